"""solver_petsc with scikit-fem's solve on 1 and 2 ranks: Poisson on a natural-neighbour
basis and linear elasticity with the rigid-body modes as near null space, against
scipy's direct solve; the row split, the replication check and bad arguments."""
import numpy as np
import pytest
from skfem import Basis, BilinearForm, ElementTriP1, ElementVector, LinearForm, condense, solve
from skfem.helpers import ddot, dot, grad, sym_grad, trace

from skfem_nem import NaturalNeighbourBasis, delaunay_mesh
from skfem_nem.geometry.nodesets import box_nodes
from skfem_nem.parallel import solver_petsc
from skfem_nem.parallel.petsc import (check_replicated, csr_to_petsc, first_block_first,
                                      gather, nest_from_rows, row_range, split_bounds,
                                      summed_rows, vector)
from agreement import rel

# agreement asked of the PETSc solution with scipy's direct one (relative, 2-norm),
# PETSc converged to RTOL
AGREEMENT = 1e-8
RTOL = 1e-12
# a product with the distributed matrix against scipy's: round-off only
PRODUCT_RTOL = 1e-14


@pytest.fixture(scope="module")
def mesh():
    return delaunay_mesh(box_nodes(300, seed=5))


@BilinearForm
def laplace(u, v, w):
    return dot(grad(u), grad(v))


@LinearForm
def unit_load(v, w):
    return np.sin(3 * w.x[0]) * v


def test_poisson_on_natural_neighbours(mesh, agree):
    basis = NaturalNeighbourBasis(mesh)
    A, b = laplace.assemble(basis), unit_load.assemble(basis)
    D = basis.get_dofs().all()
    ref = solve(*condense(A, b, D=D))
    s = solver_petsc(rtol=RTOL)
    x = solve(*condense(A, b, D=D), solver=s)
    got = agree((rel(x, ref), s.iterations, float(x @ x)))
    assert all(d < AGREEMENT and its > 1 and xx == got[0][2] for d, its, xx in got), got


@BilinearForm
def elasticity(u, v, w):
    eps_u = sym_grad(u)
    return 2 * ddot(eps_u, sym_grad(v)) + trace(eps_u) * trace(sym_grad(v))


@LinearForm
def gravity(v, w):
    return -v[1]


def rigid_modes(basis, free):
    x, y = basis.doflocs
    comp = np.zeros(basis.N, dtype=int)
    comp[basis.nodal_dofs[1]] = 1
    modes = np.zeros((basis.N, 3))
    modes[comp == 0, 0] = 1
    modes[comp == 1, 1] = 1
    modes[comp == 0, 2] = -y[comp == 0]
    modes[comp == 1, 2] = x[comp == 1]
    return modes[free]


@pytest.mark.parametrize("pc", ["gamg", "hypre"])
def test_elasticity_with_rigid_modes(mesh, agree, pc):
    basis = Basis(mesh, ElementVector(ElementTriP1()))
    A, b = elasticity.assemble(basis), gravity.assemble(basis)
    D = basis.get_dofs(lambda x: x[0] < 1e-12).all()   # clamped on the left
    free = np.setdiff1d(np.arange(basis.N), D)
    ref = solve(*condense(A, b, D=D))
    s = solver_petsc(pc_type=pc, rtol=RTOL, near_nullspace=rigid_modes(basis, free))
    x = solve(*condense(A, b, D=D), solver=s)
    got = agree((rel(x, ref), s.iterations))
    assert all(d < AGREEMENT and its > 1 for d, its in got), got


def test_solver_names_bad_arguments():
    with pytest.raises(ValueError, match="rtol must be a positive number, got -1"):
        solver_petsc(rtol=-1)
    with pytest.raises(ValueError, match="without the leading '-'"):
        solver_petsc(options={"-pc_type": "lu"})
    A = laplace.assemble(Basis(delaunay_mesh(box_nodes(30, seed=1)), ElementTriP1()))
    with pytest.raises(TypeError, match=r"no keyword argument, got \['x0'\]"):
        solver_petsc()(A, np.ones(A.shape[0]), x0=None)


def test_rows_are_split_in_blocks_and_gathered(mesh, comm, agree):
    """Each rank holds its own block of rows; the matrix-vector product of the
    distributed matrix is the serial one on every rank."""
    A = laplace.assemble(NaturalNeighbourBasis(mesh)).tocsr()
    n = A.shape[0]
    r0, r1 = row_range(n, comm)
    blocks = agree((r0, r1))
    assert blocks[0][0] == 0 and blocks[-1][1] == n
    assert all(a[1] == b[0] for a, b in zip(blocks[:-1], blocks[1:]))
    x = np.cos(np.arange(n))
    M, v = csr_to_petsc(A, comm), vector(x, comm)
    y = v.duplicate()
    try:
        assert M.getOwnershipRange() == (r0, r1)
        M.mult(v, y)
        got = agree(rel(gather(y), A @ x))
    finally:
        for obj in (y, v, M):
            obj.destroy()
    assert max(got) < PRODUCT_RTOL, got


@pytest.mark.parametrize("renumber", [False, True])
@pytest.mark.parametrize("owned", [None, "uneven"])
def test_summed_rows_sum_every_ranks_share(comm, agree, renumber, owned):
    """Each rank holds a different random share (some rows empty, one rank may own no
    rows): its rows of the sum, renumbered or not and under an uneven split, are those of
    the whole sum taken in one process."""
    import scipy.sparse as sp
    rank, size = comm.getRank(), comm.getSize()
    n = 57
    share = sp.random(n, n, density=0.15, format="csr", random_state=rank + 1)
    share[rank::3] = 0.0
    share.eliminate_zeros()
    shares = agree(share)
    order = np.random.default_rng(9).permutation(n) if renumber else None
    split = None if owned is None else [n - 3 * (size - 1)] + [3] * (size - 1)
    if split is not None and size > 1:
        split[-1], split[0] = 0, split[0] + 3        # a rank without rows
    whole = sum(shares[1:], shares[0]).tocsr()
    if order is not None:
        whole = whole[order][:, order]
    a, b = split_bounds(n, size, split)[rank]
    got = summed_rows(share, comm, owned=split, order=order)
    assert got.shape == (b - a, n)
    assert max(agree(abs(got - whole[a:b]).max() if got.nnz or whole[a:b].nnz else 0.0)) \
        < 1e-15


def test_ranks_holding_different_matrices_are_caught(comm, agree):
    """A matrix assembled differently on one rank (an unseeded random node set, say)."""
    if comm.getSize() == 1:
        pytest.skip("needs two ranks: one rank always agrees with itself")
    import scipy.sparse as sp
    A = sp.eye(4).tocsr() * (1.0 + (comm.getRank() == 1))   # rank 1 alone differs
    with pytest.raises(ValueError, match=r"differs between rank 0 and rank\(s\) \[1\]"):
        check_replicated(A, comm)


@pytest.mark.parametrize("uneven", [False, True])
def test_a_nest_from_rows_is_the_matrix(PETSc, comm, agree, uneven):
    """A matrix renumbered first-block first on every rank (first_block_first; with
    ``uneven`` one rank holds none of the first block) is, as a nest of four blocks, the
    same operator as the whole matrix: its products and its blocks are scipy's."""
    import scipy.sparse as sp
    rank, size = comm.getRank(), comm.getSize()
    n, n1 = 40, 26
    K = sp.random(n, n, density=0.2, format="csr", random_state=3) + sp.eye(n)
    order = np.random.default_rng(4).permutation(n)
    if uneven and size > 1:   # rank 0's rows all of the second block
        order = np.r_[np.arange(n1, n), np.arange(n1)]
    bounds = split_bounds(n, size)
    order = first_block_first(order, np.arange(n) < n1, bounds)
    first = order < n1
    assert all(not (first[b:e][:-1] < first[b:e][1:]).any() for b, e in bounds)
    Kp = K[order][:, order].tocsr()
    a, b = bounds[rank]
    M, sets = nest_from_rows(Kp[a:b], first, a, comm)
    x = np.random.default_rng(5).standard_normal(n)
    xv, yv = vector(x, comm), vector(np.zeros(n), comm)
    try:
        M.mult(xv, yv)
        y = gather(yv)
        A00 = M.getNestSubMatrix(0, 0)
        ia = sets[0].getIndices()
        local = A00.getValuesCSR()
        rows00 = sp.csr_matrix((local[2], local[1], local[0]),
                               shape=(ia.size, int(first.sum())))
        want00 = Kp[ia][:, np.flatnonzero(first)]
    finally:
        for obj in (xv, yv, M, *sets):
            obj.destroy()
    assert max(agree(rel(y, Kp @ x))) < 1e-14
    assert max(agree(abs(rows00 - want00).max() if want00.nnz else 0.0)) < 1e-15
    # every rank holds at least three rows: alternating blocks are refused on each
    with pytest.raises(ValueError, match="first block's unknowns must come first"):
        nest_from_rows(Kp[a:b], np.arange(n) % 2 == 1, a, comm)
