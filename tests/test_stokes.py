"""Stokes flow: analytic SolCx, inf-sup stability, rates, solvers, bad input."""
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from skfem_nem import delaunay_mesh
from skfem_nem.models.analytic import SolCx
from skfem_nem.geometry.nodesets import box_nodes
from skfem_nem.models.stokes import inf_sup_constant, solve_stokes, stokes_spaces

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "examples"))
import ex07_solcx  # noqa: E402
import ex08_sinking_block  # noqa: E402


def _stress(sol, x):
    G = sol.velocity_gradient(x)
    E = 0.5 * (G + G.transpose(1, 0, 2))
    return 2 * sol.viscosity(x) * E - sol.pressure(x) * np.eye(2)[:, :, None]


@pytest.mark.parametrize("contrast", [1.0, 1e6])
def test_solcx_analytic_solves_stokes(contrast):
    sol = SolCx(1.0, contrast)
    rng = np.random.default_rng(0)
    h = 1e-4
    for lo, hi in ((0.05, 0.45), (0.55, 0.95)):
        x = np.stack([rng.uniform(lo, hi, 30), rng.uniform(0.05, 0.95, 30)])
        ds = np.zeros((2, 30))
        for j in range(2):
            e = np.zeros((2, 1))
            e[j] = h
            ds += (_stress(sol, x + e)[:, j] - _stress(sol, x - e)[:, j]) / (2 * h)
        assert np.abs(ds + sol.force(x)).max() < 1e-6          # momentum
        G = sol.velocity_gradient(x)
        assert np.abs(G[0, 0] + G[1, 1]).max() < 1e-14         # incompressible
    z = np.linspace(0.05, 0.95, 9)
    xl, xr = np.stack([0.5 - 1e-13 + 0 * z, z]), np.stack([0.5 + 1e-13 + 0 * z, z])
    assert np.abs(sol.velocity(xl) - sol.velocity(xr)).max() < 1e-12
    assert np.abs(_stress(sol, xl)[:, 0] - _stress(sol, xr)[:, 0]).max() < 1e-10  # traction
    w = np.stack([0 * z, z])
    assert np.abs(sol.velocity(w)[0]).max() < 1e-15            # free slip wall
    assert abs(_stress(sol, w)[0, 1]).max() < 1e-12


def test_inf_sup_bubble_stable_plain_pair_not():
    plain, bubble, th = [], [], []
    for n in (100, 200, 400):
        mesh = delaunay_mesh(box_nodes(n, seed=3))
        plain.append(inf_sup_constant(stokes_spaces(mesh, "nem-projection"), stabilised=False))
        bubble.append(inf_sup_constant(stokes_spaces(mesh, "nem")))
        th.append(inf_sup_constant(stokes_spaces(mesh, "taylor-hood")))
    assert min(bubble) > 0.25 and min(th) > 0.3
    assert max(plain) < 0.05   # NEM-P1 without enrichment: spurious pressure modes


def test_stabilised_projection_inf_sup_bounded():
    vals = [inf_sup_constant(stokes_spaces(delaunay_mesh(box_nodes(n, seed=3)),
                                           "nem-projection")) for n in (100, 400)]
    assert min(vals) > 0.35


def test_hydrostatic_state_exact():
    mesh = delaunay_mesh(box_nodes(400, seed=5))
    s = solve_stokes(stokes_spaces(mesh, "nem"), 1.0, np.array([0.0, -2.0])[:, None, None],
                     tol=1e-13)
    assert np.abs(s.u).max() < 1e-10
    p, z = s.pressure_at_nodes(), mesh.p[1]
    assert np.abs(p - (-2.0 * (z - 0.5))).max() < 1e-9


def test_solcx_nem_rates_smooth_viscosity():
    rows = ex07_solcx.run(sizes=(250, 1000, 4000), contrast=1.0, methods=("nem",),
                          verbose=False)
    ru = ex07_solcx.rates(rows, "nem", "u_l2")
    rp = ex07_solcx.rates(rows, "nem", "p_l2")
    # the interface x = 0.5 is a set of segments here too (constant viscosity: the
    # constrained functions cost nothing); measured 2.30, 2.01 and 1.17, 0.91
    assert ru.mean() > 1.9
    assert rp.mean() > 0.6
    assert rows[-1]["u_l2"] < 2e-5


def test_solcx_jump_nem_and_taylor_hood():
    rows = ex07_solcx.run(sizes=(250, 1000), contrast=1e6, verbose=False)
    nem = [r for r in rows if r["method"] == "nem"]
    th = [r for r in rows if r["method"] == "taylor-hood"]
    # the interface as segments (constrained natural neighbours): u L2 1.44e-5 at 1107
    # nodes (without segments 3.9e-4), Taylor-Hood 8.8e-7
    assert nem[-1]["u_l2"] < 2e-5 and th[-1]["u_l2"] < 2e-6
    # both continuous pressures are limited by the jump alike (6.8e-3 and 6.6e-3; without
    # segments the NEM pressure spikes at the interface nodes: 0.30)
    assert th[-1]["p_l2"] < 1e-2 and nem[-1]["p_l2"] < 1e-2
    assert ex07_solcx.rates(rows, "nem", "u_l2")[0] > 1.8      # 2.92 (without segments 1.07)
    assert ex07_solcx.rates(rows, "taylor-hood", "u_l2")[0] > 2.5
    # the quadratic natural-neighbour velocity: Taylor-Hood's unknowns and rate (3.47
    # against 3.58), 1.09 and 1.17 times its error
    nem2 = [r for r in rows if r["method"] == "nem2"]
    assert ex07_solcx.rates(rows, "nem2", "u_l2")[0] > 2.8
    assert all(q["u_l2"] < 1.5 * t["u_l2"] and q["dofs"] == t["dofs"] for q, t in zip(nem2, th))


def test_sinking_block_weak_and_strong():
    rows = ex08_sinking_block.run(n=1200, ratios=(1e-2, 1.0, 1e4), reference=False,
                                  verbose=False)
    for r in rows:
        # same triangles, the outline as segments: NEM within 0.05%, 0.9% and 2.6% of
        # Taylor-Hood (without segments 2.2%, 0.9% and 12.1%: the
        # unconstrained functions cannot follow the kink at the outline)
        assert abs(r["nem"] / r["th"] - 1) < 0.04, r
    assert rows[-1]["nem"] > rows[1]["nem"] > rows[0]["nem"]   # weaker block sinks faster


def test_solvers_agree():
    sol = SolCx(1.0, 10.0)
    mesh = delaunay_mesh(box_nodes(300, seed=2))
    for method in ("nem", "nem-projection", "taylor-hood"):
        sp_ = stokes_spaces(mesh, method)
        ref = solve_stokes(sp_, sol.viscosity, sol.force, solver="direct")
        for solver in ("schur", "schur-amg", "minres", "fgmres"):
            s = solve_stokes(sp_, sol.viscosity, sol.force, solver=solver, tol=1e-12,
                             maxiter=5000)
            assert np.abs(s.u - ref.u).max() < 1e-6 * np.abs(ref.u).max(), (method, solver)
            assert s.iterations > 1


def test_schur_amg_at_high_contrast():
    """The factorisation-free solver agrees with the direct one at a 1e6 jump."""
    sol = SolCx(1.0, 1e6)
    sp_ = stokes_spaces(delaunay_mesh(ex07_solcx.nodes(400)), "nem")
    ref = solve_stokes(sp_, sol.viscosity, sol.force, solver="direct")
    s = solve_stokes(sp_, sol.viscosity, sol.force, solver="schur-amg", tol=1e-9)
    assert np.abs(s.u - ref.u).max() < 1e-6 * np.abs(ref.u).max()
    assert s.info["inner_iterations"]["its"] > s.iterations


def test_bad_input():
    mesh = delaunay_mesh(box_nodes(200, seed=2))
    sp_ = stokes_spaces(mesh, "nem")
    with pytest.raises(ValueError, match="viscosity eta .* element"):
        solve_stokes(sp_, lambda x: np.where(x[0] > 0.7, -1.0, 1.0), 0.0)
    eta = np.ones(mesh.p.shape[1])
    eta[7] = np.nan
    with pytest.raises(ValueError, match="node 7"):
        solve_stokes(sp_, eta, 0.0)
    assert np.isnan(eta[7]) and np.isfinite(np.delete(eta, 7)).all()   # untouched
    with pytest.raises(ValueError, match="body force"):
        solve_stokes(sp_, 1.0, lambda x: np.stack([x[0] * np.inf, x[1]]))
    with pytest.raises(ValueError, match="method"):
        stokes_spaces(mesh, "p1p1")
    with pytest.raises(ValueError, match="solver"):
        solve_stokes(sp_, 1.0, 0.0, solver="lu")
    with pytest.raises(ValueError, match="no boundary named"):
        solve_stokes(sp_, 1.0, 0.0, free_slip=["top"])
    with pytest.raises(RuntimeError, match="did not converge: 2 iterations"):
        solve_stokes(sp_, 1.0, lambda x: np.stack([0 * x[0], np.sin(3 * x[0])]),
                     solver="schur", maxiter=2)
    tilted = delaunay_mesh(np.array([[0, 0], [1, 0], [1.2, 1], [0, 1], [0.5, 0.5]]))
    with pytest.raises(ValueError, match="tilted"):
        solve_stokes(stokes_spaces(tilted, "nem"), 1.0, 0.0)


def test_outline_flux_constraint_keeps_region_area():
    """A dense square sinking in a box: the nodal-velocity flux through its
    outline is not zero on its own (discrete divergence is only weakly zero),
    and exactly zero with the constraint, at almost the same sinking speed."""
    from skfem_nem.geometry.nodesets import polyline_nodes
    from skfem_nem.models.stokes import outline_flux
    sq = [[0.35, 0.45], [0.65, 0.45], [0.65, 0.75], [0.35, 0.75]]
    line = polyline_nodes(sq, 0.03, closed=True)
    pts = box_nodes(800, lines=[np.r_[line, line[:1]]], seed=4)
    mesh = delaunay_mesh(pts)
    idx = np.array([int(np.argmin(np.hypot(*(mesh.p.T - q).T))) for q in line])
    sp_ = stokes_spaces(mesh, "nem", npoints=3)
    X = sp_.quadrature_points
    inside = (np.abs(X[0] - 0.5) < 0.15) & (np.abs(X[1] - 0.6) < 0.15)
    eta = np.where(inside, 30.0, 1.0)
    f = np.stack([0 * X[0], -1.0 * inside])
    C = outline_flux(sp_, idx)
    free = solve_stokes(sp_, eta, f)
    held = solve_stokes(sp_, eta, f, constraints=C)
    vz = free.velocity_at_nodes()[idx, 1].mean()
    assert abs((C @ free.u)[0]) > 1e-5 * abs(vz)          # area drifts unconstrained
    assert abs((C @ held.u)[0]) < 1e-12 * abs(vz)         # and is held with it
    assert held.velocity_at_nodes()[idx, 1].mean() == pytest.approx(vz, rel=0.05)
    assert held.info["multipliers"].shape == (1,)


@pytest.mark.parametrize("solver", ["schur", "direct", "minres", "schur-amg", "fgmres"])
def test_constraint_with_a_right_side(solver):
    """``constraints=(C, c)`` imposes ``C u = c`` (a prescribed flux through an
    outline, here the region growing at a given rate) with every solver; a
    malformed pair is refused naming what is wrong."""
    from skfem_nem.geometry.nodesets import polyline_nodes
    from skfem_nem.models.stokes import outline_flux
    sq = [[0.35, 0.45], [0.65, 0.45], [0.65, 0.75], [0.35, 0.75]]
    line = polyline_nodes(sq, 0.05, closed=True)
    mesh = delaunay_mesh(box_nodes(300, lines=[np.r_[line, line[:1]]], seed=2))
    idx = np.array([int(np.argmin(np.hypot(*(mesh.p.T - q).T))) for q in line])
    sp_ = stokes_spaces(mesh, "nem")
    X = sp_.quadrature_points
    f = np.stack([0 * X[0], -1.0 * (np.abs(X[0] - 0.5) < 0.15)])
    C = outline_flux(sp_, idx)
    rate = 2e-3
    s = solve_stokes(sp_, 1.0, f, constraints=(C, [rate]), solver=solver, tol=1e-12)
    assert (C @ s.u)[0] == pytest.approx(rate, rel=1e-6)
    s0 = solve_stokes(sp_, 1.0, f, constraints=C, solver=solver, tol=1e-12)
    assert abs((C @ s0.u)[0]) < 1e-9 * rate
    with pytest.raises(ValueError, match="right side must be 1 finite"):
        solve_stokes(sp_, 1.0, f, constraints=(C, [1.0, 2.0]))
    with pytest.raises(ValueError, match="right side must be 1 finite"):
        solve_stokes(sp_, 1.0, f, constraints=(C, np.nan))
    with pytest.raises(ValueError, match="pair"):
        solve_stokes(sp_, 1.0, f, constraints=(C, [0.0], 1))


@pytest.mark.parametrize("method", ["nem", "nem-projection", "taylor-hood"])
def test_restricted_spaces_add_up_to_the_whole_system(method):
    """Distributed assembly's premise: the systems assembled on the triangles of each
    part of a partition add up to the whole system (viscosity given at the quadrature
    points of all triangles, as the Picard iterations give it)."""
    from skfem_nem.models.stokes import assemble_stokes
    mesh = delaunay_mesh(box_nodes(200, seed=2))
    spaces = stokes_spaces(mesh, method)
    ex = SolCx(1.0, 1e3)
    eta = ex.viscosity(spaces.quadrature_points)
    whole = assemble_stokes(spaces, eta, ex.force)
    parts = np.array_split(np.random.default_rng(0).permutation(mesh.nelements), 3)
    shares = [assemble_stokes(spaces.restricted(p), eta, ex.force) for p in parts]
    for name in ("A", "B", "S", "Mp", "m", "f", "g"):
        total = sum(getattr(s, name) for s in shares)
        ref = getattr(whole, name)
        diff = total - ref
        diff = abs(diff).max() if hasattr(diff, "nnz") else np.abs(diff).max()
        scale = abs(ref).max() if hasattr(ref, "nnz") else np.abs(ref).max()
        assert diff <= 1e-13 * max(scale, 1.0), (name, diff)
    sub = spaces.restricted(parts[0])
    assert np.array_equal(sub.elements, np.sort(parts[0]))
    assert sub.quadrature_points.shape[1] == parts[0].size
    assert sub.n_velocity == spaces.n_velocity and sub.n_pressure == spaces.n_pressure


@pytest.mark.parametrize("method", ["nem", "nem-projection", "nem2", "taylor-hood", "mini"])
def test_spaces_built_on_some_triangles_are_the_restricted_whole_ones(method):
    """``stokes_spaces(mesh, elements=...)`` computes nothing for the other triangles
    (its bases hold the given triangles alone) and assembles, bit for bit, what the
    whole spaces restricted to those triangles assemble."""
    from skfem_nem.models.stokes import assemble_stokes
    mesh = delaunay_mesh(box_nodes(150, seed=4))
    part = np.random.default_rng(1).permutation(mesh.nelements)[: mesh.nelements // 3]
    ex = SolCx(1.0, 1e3)
    whole = stokes_spaces(mesh, method)
    eta = ex.viscosity(whole.quadrature_points)   # given on all triangles: taken at theirs
    divided = stokes_spaces(mesh, method, elements=part)
    assert np.array_equal(divided.elements, np.sort(part))
    assert divided.quadrature_points.shape[1] == part.size == divided.ubasis.nelems
    a = assemble_stokes(whole.restricted(part), eta, ex.force)
    b = assemble_stokes(divided, eta, ex.force)
    for name in ("A", "B", "S", "Mp", "m", "f", "g"):
        x, y = getattr(a, name), getattr(b, name)
        if x is None:
            assert y is None
            continue
        assert (abs(x - y).max() if hasattr(x, "nnz") else np.abs(x - y).max()) == 0.0, name


def _cube_mesh(n, seed):
    rng = np.random.default_rng(seed)
    corners = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], float)
    return delaunay_mesh(np.r_[corners, rng.random((n, 3))])


def _tet_load(x):
    return np.stack([0 * x[0], x[2] - 0.5, -1.0 - x[0]])


@pytest.mark.parametrize("method", ["taylor-hood", "mini", "nem"])
def test_spaces_built_on_some_tetrahedra_are_the_restricted_whole_ones(method):
    """The same on tetrahedra: the scikit-fem velocities, and the natural-neighbour one
    whose condensed bubbles keep the mesh's numbering (``3 cell + c``) on some cells."""
    from skfem_nem.models.stokes import assemble_stokes
    mesh = _cube_mesh(60, 3)
    part = np.arange(0, mesh.nelements, 4)
    whole = stokes_spaces(mesh, method)
    divided = stokes_spaces(mesh, method, elements=part)
    assert divided.ubasis.nelems == part.size
    eta = 2.0 + whole.quadrature_points[0]           # given on all cells: taken at theirs
    a = assemble_stokes(whole.restricted(part), eta, _tet_load)
    b = assemble_stokes(divided, eta, _tet_load)
    for name in ("A", "B", "S", "Mp", "m", "f", "g"):
        x, y = getattr(a, name), getattr(b, name)
        assert (abs(x - y).max() if hasattr(x, "nnz") else np.abs(x - y).max()) == 0.0, name


@pytest.mark.parametrize("blocks", [False, True])
def test_natural_neighbour_tetrahedra_add_up_to_the_whole_system(blocks):
    """Each tetrahedron's bubbles are condensed where it is integrated, so the condensed
    systems of the parts of a partition add up to the whole mesh's (also the viscous block
    as its nodes' 3 x 3 blocks), and their bubbles' coupling keeps the mesh's rows."""
    from skfem_nem.models.stokes import assemble_stokes
    mesh = _cube_mesh(80, 5)
    spaces = stokes_spaces(mesh)
    eta = 1.0 + 10.0 * (spaces.quadrature_points[2] > 0.5)
    whole = assemble_stokes(spaces, eta, _tet_load, viscous_blocks=blocks)
    parts = np.array_split(np.random.default_rng(2).permutation(mesh.nelements), 3)
    shares = [assemble_stokes(spaces.restricted(p), eta, _tet_load, viscous_blocks=blocks)
              for p in parts]

    def matrix(A):
        return A.tocsr() if hasattr(A, "tocsr") else A

    for name in ("A", "B", "S", "Mp", "m", "f", "g"):
        total = sum(matrix(getattr(s, name)) for s in shares)
        ref = matrix(getattr(whole, name))
        diff = total - ref
        diff = abs(diff).max() if hasattr(diff, "nnz") else np.abs(diff).max()
        scale = abs(ref).max() if hasattr(ref, "nnz") else np.abs(ref).max()
        assert diff <= 1e-13 * scale, (name, diff)
    u = np.random.default_rng(0).standard_normal(spaces.n_velocity)
    coupling = whole.bubble[1]
    bubbles = sum(s.bubble[1] @ u for s in shares)
    assert np.abs(bubbles - coupling @ u).max() <= 1e-13 * np.abs(coupling @ u).max()
    y = np.random.default_rng(1).standard_normal(coupling.shape[0])
    back = sum(s.bubble[1].T @ y for s in shares)
    assert np.abs(back - coupling.T @ y).max() <= 1e-12 * np.abs(coupling.T @ y).max()
    first, ref = shares[0].bubble[1].tocsr(), coupling.tocsr()
    rows = np.zeros(ref.shape[0], bool)
    rows[(3 * parts[0][:, None] + np.arange(3)).ravel()] = True
    assert first[~rows].nnz == 0                  # (the other parts' bubbles: not here)
    assert abs(first[rows] - ref[rows]).max() <= 1e-13 * abs(ref).max()


def test_spaces_of_some_triangles_solve_only_over_mpi():
    """One rank's share solves with solver "petsc" alone (with the others' shares);
    serial solvers and the visco-elasto-plastic step refuse it, naming the solver."""
    from skfem_nem.models.rheology import Material, vep_step
    mesh = delaunay_mesh(box_nodes(100, seed=4))
    divided = stokes_spaces(mesh, elements=np.arange(mesh.nelements // 2))
    for solver in ("auto", "schur", "fgmres"):
        with pytest.raises(ValueError, match=f"solve them with solver='petsc', got "
                                             f"solver='{solver}'"):
            solve_stokes(divided, 1.0, solver=solver)
    ne, nq = divided.quadrature_points.shape[1:]
    with pytest.raises(ValueError, match="one MPI rank's share"):
        vep_step(divided, Material(viscosity=1.0, shear_modulus=1.0), np.zeros((2, 2, ne, nq)),
                 0.1, solver="schur")
    with pytest.raises(ValueError, match=f"non-empty subset of the {mesh.nelements} triangles"):
        stokes_spaces(mesh, elements=[mesh.nelements])
    with pytest.raises(ValueError, match="cell indices or 'owned', got 'mine'"):
        stokes_spaces(mesh, elements="mine")


def test_owned_triangles_name_the_mpi_installation_without_petsc4py():
    from skfem_nem.parallel import PetscUnavailableError, import_petsc
    mesh = delaunay_mesh(box_nodes(60, seed=4))
    try:
        import_petsc()
    except PetscUnavailableError:
        with pytest.raises(PetscUnavailableError, match="petsc4py and mpi4py"):
            stokes_spaces(mesh, elements="owned")
    else:  # (one process: every triangle is its own)
        assert stokes_spaces(mesh, elements="owned").elements is None


def test_restricted_spaces_check_their_elements():
    spaces = stokes_spaces(delaunay_mesh(box_nodes(60, seed=2)))
    ne = spaces.mesh.nelements
    for bad in ([], [0, ne], [-1, 2]):
        with pytest.raises(ValueError, match=f"non-empty subset of the {ne} triangles"):
            spaces.restricted(bad)
    with pytest.raises(ValueError, match="already restricted"):
        spaces.restricted([0, 1]).restricted([0])


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 10**6), st.booleans())
def test_free_columns_is_scipys_fancy_indexing(seed, rows):
    import scipy.sparse as sp
    from skfem_nem.models.stokes_walls import free_columns
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 60))
    A = sp.random(n + int(rng.integers(0, 5)), n, density=0.2, random_state=seed,
                  format="csr") if not rows else sp.random(n, n, density=0.2,
                                                            random_state=seed, format="csr")
    free = np.flatnonzero(rng.random(n) < 0.7)
    ref = (A[free][:, free] if rows else A[:, free]).toarray()
    got = free_columns(A, free, rows=rows)
    assert got.shape == ref.shape and np.array_equal(got.toarray(), ref)
    assert got.has_sorted_indices
    # written over A's own arrays: the same matrix; no new index or value array where
    # at least half the entries stay (scipy copies a view of less than half its base)
    data, indices, nnz = A.data, A.indices, A.nnz
    over = free_columns(A, free, rows=rows, overwrite=True)
    assert over.shape == ref.shape and np.array_equal(over.toarray(), ref)
    if 2 * over.nnz >= nnz > 0:
        assert np.shares_memory(over.data, data) and np.shares_memory(over.indices, indices)


def test_free_columns_over_its_input_needs_csr():
    import scipy.sparse as sp
    from skfem_nem.models.stokes_walls import free_columns
    A = sp.random(6, 6, density=0.5, random_state=1, format="coo")
    with pytest.raises(ValueError, match="overwrite=True.*CSR.*coo_matrix"):
        free_columns(A, np.arange(3), rows=True, overwrite=True)
    assert np.array_equal(free_columns(A, np.arange(3), rows=True).toarray(),
                          A.toarray()[:3, :3])
