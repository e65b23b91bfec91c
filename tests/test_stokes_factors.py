"""The factors of the viscous block per velocity component
(:class:`skfem_nem.models.stokes_factors.ComponentFactors`): each component's diagonal
block solved exactly, made and applied in two threads, errors raised in the caller."""
import numpy as np
import pytest
import scipy.sparse as sps

from skfem_nem.models.stokes_factors import (DENSE_ROW_ENTRIES, ComponentFactors,
                                             ViscousFactor, in_two_threads, ordering)


def _coupled_block(n, rng):
    """A symmetric positive definite block of 2n unknowns, components interleaved
    (``2i``, ``2i + 1``), coupled across components, diagonal spanning 1e-3..1e3."""
    L = 2.5 * np.eye(n) - np.eye(n, k=1) - np.eye(n, k=-1)
    C = 0.2 * (np.eye(n, k=1) + np.eye(n, k=-1))
    K = np.block([[L, C], [C, L]])
    order = np.r_[0:2 * n:2, 1:2 * n:2]          # component blocks -> interleaved
    A = np.empty_like(K)
    A[np.ix_(order, order)] = K
    d = 10.0 ** rng.uniform(-1.5, 1.5, 2 * n)
    return sps.csr_matrix(d[:, None] * A * d[None, :])


@pytest.mark.parametrize("dtype, rtol", [(np.float64, 1e-12), (np.float32, 1e-4)])
def test_component_factors_solve_each_diagonal_block(dtype, rtol):
    rng = np.random.default_rng(0)
    A = _coupled_block(40, rng)
    comp = np.arange(A.shape[0]) % 2
    r = rng.standard_normal(A.shape[0])
    x = ComponentFactors(A, comp, dtype).solve(r)
    assert x.dtype == np.float64
    for c in (0, 1):
        rows = np.flatnonzero(comp == c)
        block = A[rows][:, rows]
        assert np.linalg.norm(block @ x[rows] - r[rows]) < rtol * np.linalg.norm(r[rows])
    # the coupling is left out: this is not A^-1
    assert np.linalg.norm(A @ x - r) > 1e-3 * np.linalg.norm(r)
    whole = ViscousFactor(A, dtype).solve(r)
    assert np.linalg.norm(A @ whole - r) < rtol * np.linalg.norm(r)


def test_a_singular_component_block_is_named_in_the_caller():
    """The component factorised in the second thread fails: its error reaches the caller."""
    A = sps.csr_matrix(np.array([[2.0, 0.0, 0.1, 0.0], [0.0, 1.0, 0.0, 1.0],
                                 [0.1, 0.0, 2.0, 0.0], [0.0, 1.0, 0.0, 1.0]]))
    with pytest.raises(RuntimeError, match="viscous block is singular"):
        ComponentFactors(A, np.array([0, 1, 0, 1]))


def test_in_two_threads_returns_both_and_raises_either():
    assert in_two_threads([lambda: 1, lambda: 2]) == [1, 2]
    for tasks in ([lambda: 1 / 0, lambda: 2], [lambda: 1, lambda: 1 / 0]):
        with pytest.raises(ZeroDivisionError):
            in_two_threads(tasks)


def test_dense_blocks_are_ordered_by_colamd_and_solved():
    """A block with more than DENSE_ROW_ENTRIES entries a row (the quadratic
    natural-neighbour velocity's) is ordered by COLAMD, a sparse one (Taylor-Hood's,
    the linear natural-neighbour one's) by minimum degree; both factors solve it."""
    rng = np.random.default_rng(1)
    n = 300
    sparse = _coupled_block(n // 2, rng)
    B = sps.random(n, n, density=1.5 * DENSE_ROW_ENTRIES / n, random_state=2)
    dense = sps.csr_matrix(B @ B.T + n * sps.eye(n))
    assert ordering(sparse) == "MMD_AT_PLUS_A" and ordering(dense) == "COLAMD"
    assert not dense.has_sorted_indices          # a product's columns: sorted on a copy
    indices = dense.indices.copy()
    for A in (sparse, dense):
        r = rng.standard_normal(n)
        x = ViscousFactor(A).solve(r)
        assert np.linalg.norm(A @ x - r) < 1e-12 * np.linalg.norm(r)
    assert np.array_equal(dense.indices, indices)
