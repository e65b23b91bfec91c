"""The 3D smoothed basis' values and one gradient row per cell (basis/cell_rows.py), the row
kernels taken in Z-order, and the joined gradient chunks of the row sums (basis/summation.py):
each against the joined rows and orders they replace."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from skfem import ElementVector

from helpers import cube_nodes
from skfem_nem import ElementNaturalNeighbour, NaturalNeighbourBasis, delaunay_mesh
from skfem_nem.basis import smoothing, summation
from skfem_nem.basis.cell_rows import gradient_rows, two_pass
from skfem_nem.basis.stencils import stencil_union


def _basis(n, seed, vector=False):
    e = ElementNaturalNeighbour()
    mesh = delaunay_mesh(cube_nodes(n, seed=seed, per_face=3))
    return NaturalNeighbourBasis(mesh, ElementVector(e) if vector else e)


@settings(max_examples=15, deadline=None)
@given(st.integers(12, 90), st.integers(0, 2 ** 31 - 1))
def test_stencils_and_their_gradients_are_those_of_the_joined_rows(n, seed):
    """The stencils and stencil gradients the cell rows give are, bitwise, those the joined
    rows (one gradient copy per point) give; the joined rows are made only on request."""
    b = _basis(n, seed)
    assert b.cell_rows is not None and b._values is None
    Gs = summation.stencil_gradients(b)
    Phi, G = b.values_matrix, b.gradient_entries            # joined now
    nq = b.dx.shape[1]
    ptr, sten = stencil_union(Phi.indptr, Phi.indices, nq, b.nelems)
    assert np.array_equal(ptr, b.stencil_ptr) and np.array_equal(sten, b.stencil_nodes)
    ref = np.empty_like(Gs)
    summation._stencil_gradients_serial(ptr, sten, Phi.indptr.astype(np.int64),
                                        Phi.indices.astype(np.int64), G, nq, ref)
    assert np.array_equal(Gs, ref)
    # every point of a tetrahedron carries its one gradient
    for k in range(3):
        rows = b._D[k].toarray().reshape(b.nelems, nq, -1)
        assert np.array_equal(rows, np.broadcast_to(rows[:, :1], rows.shape))


@settings(max_examples=10, deadline=None)
@given(st.integers(12, 90), st.integers(0, 2 ** 31 - 1))
def test_marked_gradient_rows_equal_the_merged_ones(n, seed):
    """The cells' gradient rows by marking equal, bit for bit, the k-way merge's."""
    mesh = delaunay_mesh(cube_nodes(n, seed=seed, per_face=3))
    cells = np.arange(mesh.nelements)
    pts, own, cp, coef, slot = smoothing.cells_3d(mesh.p.T, mesh.t, mesh.t2f, mesh.facets, cells)
    rng = np.random.default_rng(seed)
    import scipy.sparse as sp
    m, nv = pts.shape[0], mesh.nvertices
    # any sorted rows will do: random ones for the faces, the nodes' identity after them
    F = sp.random(m, nv, density=0.2, format="csr", random_state=rng)
    S = sp.vstack([F, sp.identity(nv, format="csr")], format="csr")
    S.sort_indices()
    raw = (S.indptr.astype(np.int64), S.indices.astype(np.int64), S.data)
    got = gradient_rows(cp, coef, raw, nv)
    none = (np.zeros(cp.shape[0] + 1, np.int64), np.empty(0, np.int64), np.empty(0))
    args = (np.arange(cp.shape[0]), cp, coef, *none, *raw)
    want = two_pass(smoothing._smoothed_rows, smoothing._smoothed_rows_serial, cp.shape[0],
                    args, 3)
    assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])
    assert np.array_equal(got[2], want[3])


def test_row_order_changes_no_pattern_and_no_sum():
    """Rows taken in Z-order give the node pattern and the matrix of rows taken in order."""
    from skfem.models.elasticity import lame_parameters, linear_elasticity
    b = _basis(400, 3, vector=True)
    inc_ptr, inc_e, inc_l, cptr, cols = summation.node_pattern(b)
    order = summation.basis_row_order(b)
    n = cptr.size - 1
    assert np.array_equal(np.sort(order), np.arange(n)) and not np.array_equal(order,
                                                                              np.arange(n))
    want = summation.stencil_union(b.stencil_ptr, b.stencil_nodes, inc_ptr, inc_e, n)
    assert np.array_equal(want[0], cptr) and np.array_equal(want[1], cols)
    form = linear_elasticity(*lame_parameters(1e3, 0.3))
    K = form.assemble(b)
    b.__dict__["_row_order"] = np.arange(n)                # the same sums in node order
    assert (form.assemble(b) != K).nnz == 0


def _chunk(e0, e1, pairs=(0, 1), kind="gradients"):
    if kind == "matrices":
        return e0, e1, kind, ("off", "K")
    pa = np.array(pairs)
    return e0, e1, kind, (np.full((pa.size, e1 - e0), float(e0)), pa, pa.copy())


def test_consecutive_gradient_chunks_are_joined(monkeypatch):
    """Runs of gradient chunks of the same pairs become one chunk (ranges joined, the
    coefficients side by side); a matrices chunk, other pairs or the budget end a run."""
    chunks = [_chunk(0, 4), _chunk(4, 6), _chunk(6, 7, kind="matrices"), _chunk(6, 9),
              _chunk(9, 10, pairs=(0, 2)), _chunk(10, 12, pairs=(0, 2))]
    out = list(summation._merged_gradient_chunks(iter(chunks)))
    assert [(o[0], o[1], o[2]) for o in out] == [
        (0, 6, "gradients"), (6, 7, "matrices"), (6, 9, "gradients"), (9, 12, "gradients")]
    Ce, pa, pb = out[0][3]
    assert np.array_equal(Ce, np.hstack([np.zeros((2, 4)), np.full((2, 2), 4.0)]))
    assert np.array_equal(out[3][3][1], [0, 2])
    monkeypatch.setattr(summation, "GRADIENT_COEFFICIENT_BUDGET", 10)   # 8 + 8 > 10 >= 8 + 2
    out = list(summation._merged_gradient_chunks(iter([_chunk(0, 4), _chunk(4, 8),
                                                       _chunk(8, 9)])))
    assert [(o[0], o[1]) for o in out] == [(0, 4), (4, 9)]


@pytest.mark.parametrize("vector", [False, True])
def test_a_form_with_values_joins_the_rows_and_agrees(vector):
    """A form with value terms makes the joined rows and assembles as with them from the
    start; a pure gradient form does not make them."""
    from helpers import laplace
    from skfem import BilinearForm
    b = _basis(200, 5, vector=vector)
    if vector:
        from skfem.helpers import ddot, dot, sym_grad
        from skfem.models.elasticity import lame_parameters, linear_elasticity
        grad_form = linear_elasticity(*lame_parameters(1.0, 0.3))

        @BilinearForm
        def both(u, v, w):
            return dot(u, v) + ddot(sym_grad(u), sym_grad(v))
    else:
        from skfem.helpers import dot, grad
        grad_form = laplace

        @BilinearForm
        def both(u, v, w):
            return dot(grad(u), grad(v)) + u * v
    grad_form.assemble(b)
    assert b._values is None
    K = both.assemble(b)
    assert b._values is not None
    fresh = _basis(200, 5, vector=vector)
    _ = fresh.values_matrix                                  # joined from the start
    assert abs(both.assemble(fresh) - K).max() == 0.0


def test_stokes_loads_divergence_and_fields_need_no_joined_rows():
    """The 3D Stokes load (body force and stress), the divergence block and ``interpolate``
    read the cell rows: the numbers of the joined rows, which are never made, bitwise (the
    stress load to rounding: the cell rows sum the stress over a cell's points first)."""
    from skfem import Basis, ElementTetP1
    from skfem_nem.models.condensation_tet import divergence_tet, loads_tet
    b = _basis(150, 7, vector=True)
    ne, nq = b.dx.shape
    rng = np.random.default_rng(0)
    f, tau = rng.normal(size=(3, ne, nq)), rng.normal(size=(3, 3, ne, nq))
    u = rng.normal(size=b.N)
    pbasis = Basis(b.mesh, ElementTetP1(), quadrature=b.quadrature)
    got = (loads_tet(b, f, tau), divergence_tet(b, pbasis), b.interpolate(u))
    assert b._values is None                                 # nothing joined
    _ = b.values_matrix
    b.cell_rows = None                                       # the joined rows' road
    want = (loads_tet(b, f, tau), divergence_tet(b, pbasis), b.interpolate(u))
    assert np.abs(got[0] - want[0]).max() < 1e-13 * np.abs(want[0]).max()
    assert not np.array_equal(got[0], want[0]) or np.abs(tau).max() == 0  # (two roads)
    assert abs(got[1] - want[1]).max() == 0.0
    assert np.array_equal(got[2][0], want[2][0])
    assert np.array_equal(got[2][1], want[2][1])
