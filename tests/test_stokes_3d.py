"""Stokes flow on Delaunay tetrahedra: the 3D spaces, walls, exactness, rates, solvers."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from skfem_nem import delaunay_mesh
from helpers import qhull_mesh
from skfem_nem.geometry import box_nodes_3d
from skfem_nem.models.analytic3d import (Manufactured3D, Sinker, haberman_sayre, relative_errors,
                                         settling_velocity)
from skfem_nem.models.stokes import (assemble_stokes, inf_sup_constant, outline_flux,
                                     solve_stokes, stokes_spaces, wall_dofs)
from skfem_nem.models.stokes_amg import rigid_modes
from skfem_nem.models.stokes_walls import boundary_flux


@pytest.fixture(scope="module")
def mesh():
    return delaunay_mesh(box_nodes_3d(150, seed=2)).with_defaults()


@pytest.fixture(scope="module")
def spaces(mesh):
    return stokes_spaces(mesh)


def _down(rho):
    """Body force (0, 0, -rho(x))."""
    return lambda x: np.array([0 * x[0], 0 * x[0], -rho(x)])


def test_manufactured_solution_is_one():
    ms = Manufactured3D(20.0)
    x = np.random.default_rng(3).random((3, 20))
    h = 1e-5

    def sig(y):
        g = ms.velocity_gradient(y)
        return ms.viscosity(y) * (g + g.transpose(1, 0, 2)) - ms.pressure(y) * np.eye(3)[..., None]

    div_sigma = np.zeros((3, 20))
    for j in range(3):
        e = np.zeros((3, 1))
        e[j] = h
        div_sigma += (sig(x + e)[:, j] - sig(x - e)[:, j]) / (2 * h)
    assert np.abs(div_sigma + ms.force(x)).max() < 1e-5 * np.abs(ms.force(x)).max()
    # free slip is exact on the faces: no normal velocity, no shear strain rate
    face = np.random.default_rng(4).random((3, 10))
    for k in range(3):
        for side in (0.0, 1.0):
            y = face.copy()
            y[k] = side
            assert np.abs(ms.velocity(y)[k]).max() < 1e-15
            g = ms.velocity_gradient(y)
            for j in range(3):
                if j != k:
                    assert np.abs(g[k, j] + g[j, k]).max() < 1e-13
    assert ms.viscosity(np.ones((3, 1)))[0] / ms.viscosity(np.zeros((3, 1)))[0] == pytest.approx(20)


def test_spaces_on_tetrahedra(mesh, spaces):
    n = mesh.p.shape[1]
    assert spaces.dim == 3 and spaces.n_velocity == 3 * n and spaces.n_pressure == n
    assert spaces.bubbles.N == 3 * mesh.nelements
    mini = stokes_spaces(mesh, "mini")
    th = stokes_spaces(mesh, "taylor-hood")
    assert mini.n_pressure == th.n_pressure == n
    assert th.n_velocity == 3 * (n + mesh.edges.shape[1])
    for bad, match in ((dict(method="nem2"), "triangles only"), (dict(npoints=4), "npoints"),
                       (dict(method="p1"), "method must be")):
        with pytest.raises(ValueError, match=match):
            stokes_spaces(mesh, **bad)
    with pytest.raises(ValueError, match="Gauss"):
        stokes_spaces(mesh, "mini", integration="smoothed")


@pytest.mark.parametrize("method", ["nem", "mini", "taylor-hood"])
def test_hydrostatic_state_exact(mesh, method):
    """A uniform body force is balanced by a linear pressure alone, at any viscosity:
    no spurious flow (the gradient form of the divergence for natural neighbours)."""
    S = stokes_spaces(mesh, method)
    g = np.array([0.3, -0.2, -1.0])
    sol = solve_stokes(S, lambda x: 1 + 99 * x[0] * x[1],
                       lambda x: g[:, None, None] + 0 * x, solver="direct")
    assert np.abs(sol.u).max() < 1e-11
    v = sol.velocity_at_nodes()
    assert v.shape == (mesh.p.shape[1], 3)
    p = sol.pressure_at_nodes()
    ref = g @ mesh.p
    # the baselines' pressures carry their direct solve's round-off at this viscosity
    # contrast (up to 1.2e-10 measured, depending on the tetrahedra's order)
    tol = 1e-10 if method == "nem" else 1e-9
    assert np.abs((p - p.mean()) - (ref - ref.mean())).max() < tol


def test_flat_tetrahedra_carry_no_bubble():
    """Opposite faces of a box from box_nodes_3d carry the same pattern of nodes, so a node
    of the bottom face, the one above it on the top face and a neighbouring such pair can
    span a flat tetrahedron of Qhull's (here one, in a graded set of 762 nodes; delaunay_mesh
    makes none, but a user's mesh may have them). Its bubble block is singular and scikit-fem
    cannot map its P1 gradients; it carries no weight, and the hydrostatic state is exact
    with nothing NaN."""
    lo, hi = np.array([1.25, 0.5, 0.77]), np.array([2.75, 1.5, 0.87])

    def density(p):
        d = np.linalg.norm(np.maximum(np.maximum(lo - p, p - hi), 0.0), axis=1)
        return 1.0 / (1.0 + d / 0.15) ** 3

    m = qhull_mesh(box_nodes_3d(300, (4, 2, 1), density=density, seed=0,
                                boundary_spacing=0.25))
    P = m.p.T[m.t.T]
    vol = np.abs(np.einsum("kd,kd->k", P[:, 1] - P[:, 0],
                           np.cross(P[:, 2] - P[:, 0], P[:, 3] - P[:, 0]))) / 6
    assert np.count_nonzero(vol < 1e-14) > 0
    S = stokes_spaces(m)
    g = np.array([0.3, -0.2, -1.0])
    sol = solve_stokes(S, lambda x: 1 + 9 * x[2], lambda x: g[:, None, None] + 0 * x,
                       solver="direct")
    assert np.isfinite(sol.u).all() and np.abs(sol.u).max() < 1e-11
    p_ = sol.pressure_at_nodes()
    ref = g @ m.p
    # round-off of the direct solve near the flat tetrahedron: 6e-11 and 1.3e-10 for two
    # orders of summing the same load
    assert np.abs((p_ - p_.mean()) - (ref - ref.mean())).max() < 3e-10


def test_flat_tetrahedra_on_a_wall_keep_the_boundary_term_finite():
    """Nodes on a wall in a square lattice (four by four cocircular): Qhull spans flat
    tetrahedra of four wall nodes, whose faces lie on the hull (delaunay_mesh makes none; a
    user's mesh of Qhull's tetrahedra has them). The boundary term of the
    divergence takes their normals and pressure traces from the faces themselves (the
    tetrahedra's inverse mapping is NaN), and a 3D plate whose nodes slid along the bottom
    wall into such a pattern stopped with NaN in the pressure iterations; the hydrostatic
    state is exact, and the term equals the faces' exact flux of a linear field."""
    p = box_nodes_3d(150, (1, 1, 1), seed=0, boundary_spacing=0.25)
    g = np.linspace(0, 1, 6)
    X, Y = np.meshgrid(g, g)
    m = qhull_mesh(np.vstack([p[p[:, 2] > 0], np.c_[X.ravel(), Y.ravel(), 0 * X.ravel()]]))
    P = m.p.T[m.t.T]
    vol = np.abs(np.einsum("kd,kd->k", P[:, 1] - P[:, 0],
                           np.cross(P[:, 2] - P[:, 0], P[:, 3] - P[:, 0]))) / 6
    flat = np.flatnonzero((vol == 0) & (m.p[2, m.t] == 0).all(axis=0))
    assert np.isin(m.f2t[0, m.boundary_facets()], flat).any()
    S = stokes_spaces(m)
    F = boundary_flux(S)
    assert np.isfinite(F.data).all()
    # oint (u . n) ds = 0 for u = (x, y, -2 z); oint q (u . n) ds for q = 1 and u = (0, 0, 1)
    # is the area of top minus bottom, 0; for u = (x, 0, 0), q = 1: the volume, 1
    ones = np.ones(S.pbasis.N)
    u = np.zeros(S.ubasis.N)
    u[S.ubasis.dofs.nodal_dofs[0]] = m.p[0]
    assert abs(ones @ F @ u - 1.0) < 1e-12
    gv = np.array([0.3, -0.2, -1.0])
    sol = solve_stokes(S, lambda x: 1 + 9 * x[2], lambda x: gv[:, None, None] + 0 * x,
                       solver="direct")
    assert np.isfinite(sol.u).all() and np.abs(sol.u).max() < 1e-11


def test_faces_without_area_carry_no_boundary_term():
    """The nodes of a 3D plate pressed onto its bottom wall: Qhull's hull there has 44
    triangles of three collinear wall nodes (no area, no normal). They carry no weight in the
    boundary term of the divergence (a run stopped at step 68 with NaN in the pressure
    iterations), and the term gives the box's volume as the flux of u = (x, 0, 0). (Today's
    delaunay_mesh makes no such faces; a user's mesh of Qhull's tetrahedra has them.)"""
    from pathlib import Path
    nodes = np.load(Path(__file__).parent / "data" / "plate3d_wall_nodes.npz")["nodes"]
    m = qhull_mesh(nodes)
    F = m.p[:, m.facets[:, m.boundary_facets()]]
    area = np.linalg.norm(np.cross(F[:, 1] - F[:, 0], F[:, 2] - F[:, 0], axis=0), axis=0)
    assert np.count_nonzero(area == 0) > 0
    S = stokes_spaces(m)
    flux = boundary_flux(S)
    assert np.isfinite(flux.data).all()
    u = np.zeros(S.ubasis.N)
    u[S.ubasis.dofs.nodal_dofs[0]] = m.p[0]
    box = np.prod(np.ptp(m.p, axis=1))
    assert abs(np.ones(S.pbasis.N) @ flux @ u - box) < 1e-10 * box


def test_walls_by_name(mesh, spaces):
    """scikit-fem's default names of a box's faces: free slip fixes the normal
    component of the face's nodes, no slip all three."""
    nd = spaces.ubasis.dofs.nodal_dofs
    for name, axis in (("left", 0), ("top", 1), ("back", 2)):
        D = wall_dofs(spaces, free_slip=[name])
        nodes = np.unique(mesh.facets[:, mesh.boundaries[name]])
        assert np.array_equal(np.sort(D), np.sort(nd[axis, nodes]))
    D = wall_dofs(spaces, free_slip=None, no_slip=["front"])
    nodes = np.unique(mesh.facets[:, mesh.boundaries["front"]])
    assert np.array_equal(np.sort(D), np.sort(nd[:, nodes].ravel()))
    with pytest.raises(ValueError, match="no boundary named 'bottomm'"):
        wall_dofs(spaces, free_slip=["bottomm"])


def test_tilted_wall_named():
    p = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1.5], [0.3, 0.3, 0.3]])
    S = stokes_spaces(delaunay_mesh(p))
    with pytest.raises(ValueError, match="tilted"):
        wall_dofs(S)
    with pytest.raises(ValueError, match="2D mesh"):
        outline_flux(S, np.arange(4))


def test_buoyant_sphere_moves_up_and_is_symmetric(spaces):
    """A light ball at the centre of a closed box: it rises, nothing moves sideways on
    average, and the no-slip walls hold."""
    c = np.array([0.5, 0.5, 0.5])[:, None, None]
    light = lambda x: -1.0 * (np.linalg.norm(x - c, axis=0) < 0.25)  # noqa: E731
    sol = solve_stokes(spaces, 1.0, _down(light), free_slip=None, no_slip="all",
                       solver="direct")
    v = sol.velocity_at_nodes()
    mesh = spaces.mesh
    inner = np.linalg.norm(mesh.p - c[:, :, 0], axis=0) < 0.25
    assert v[inner, 2].mean() > 0
    assert abs(v[:, 0].mean()) < 0.1 * v[inner, 2].mean()
    assert np.abs(v[mesh.boundary_nodes()]).max() == 0


def test_rates_of_the_manufactured_solution():
    """Velocity at rate >= 1.9 and pressure >= 0.9 in h (h ~ n^(-1/3)), viscosity ratio 20
    across the cube, free slip on all faces (exact for this flow)."""
    ms = Manufactured3D(20.0)
    errs, sizes = [], []
    for n in (150, 700):
        m = delaunay_mesh(box_nodes_3d(n, seed=0))
        S = stokes_spaces(m)
        sol = solve_stokes(S, ms.viscosity, ms.force, solver="direct")
        errs.append(relative_errors(S, sol, ms))
        sizes.append(m.p.shape[1])
    rate = -3 * np.log(np.array(errs[1]) / np.array(errs[0])) / np.log(sizes[1] / sizes[0])
    assert rate[0] >= 1.9, (errs, rate)
    assert rate[1] >= 0.9, (errs, rate)
    assert errs[1][0] < 0.05


def test_inf_sup_bounded_on_random_nodes():
    """The bubble-enriched pair is inf-sup stable in 3D: its constant stays bounded below
    as random node sets grow; the velocity without bubbles is not."""
    betas = []
    for n in (30, 90, 250):
        S = stokes_spaces(delaunay_mesh(box_nodes_3d(n, seed=5)))
        betas.append(inf_sup_constant(S))
    assert min(betas) > 0.15, betas
    assert betas[-1] > 0.6 * betas[0], betas
    plain = stokes_spaces(delaunay_mesh(box_nodes_3d(90, seed=5)), "nem-projection")
    assert inf_sup_constant(plain, stabilised=False) < 0.5 * betas[1]


@pytest.mark.parametrize("solver", ["schur", "fgmres", "minres"])
def test_iterative_solvers_agree_with_direct(spaces, solver):
    ms = Manufactured3D(20.0)
    ref = solve_stokes(spaces, ms.viscosity, ms.force, solver="direct")
    sol = solve_stokes(spaces, ms.viscosity, ms.force, solver=solver, tol=1e-10)
    assert np.abs(sol.u - ref.u).max() < 1e-7 * np.abs(ref.u).max()


def test_rigid_modes_span_the_viscous_null_space(spaces):
    """The six rigid-body motions of the 3D velocity are exactly the null space of the
    condensed viscous block without walls (AMG's near null space)."""
    sys_ = assemble_stokes(spaces, 1.0, 0.0)
    R = rigid_modes(spaces.ubasis, np.arange(spaces.n_velocity))
    assert R.shape == (spaces.n_velocity, 6)
    assert np.abs(sys_.A @ R).max() < 1e-10 * abs(sys_.A).max()
    assert np.linalg.matrix_rank(R) == 6


@pytest.mark.parametrize("dim", [2, 3])
def test_rigid_modes_of_mini_leave_its_bubbles_at_zero(mesh, dim):
    """scikit-fem places the MINI bubbles at NaN: their rows in the modes are zero (a rigid
    motion is the linear part's alone), so the modes are finite and in the null space of
    the viscous block without walls (PETSc's GAMG refused NaN modes)."""
    m = mesh if dim == 3 else delaunay_mesh(np.random.default_rng(1).random((40, 2)))
    spaces = stokes_spaces(m, "mini")
    R = rigid_modes(spaces.ubasis, np.arange(spaces.n_velocity))
    assert np.isfinite(R).all() and np.linalg.matrix_rank(R) == (6 if dim == 3 else 3)
    A = assemble_stokes(spaces, 1.0, 0.0).A
    assert np.abs(A @ R).max() < 1e-10 * abs(A).max()


def test_settling_references():
    assert haberman_sayre(0.1) == pytest.approx(0.792, abs=1e-3)
    assert haberman_sayre(0.2) == pytest.approx(0.595, abs=1e-3)
    assert settling_velocity(0.1, 0.5, 1.0, 1.0, 1.0, viscosity_ratio=1.0) == pytest.approx(
        2 / 9 * 0.01 * 6 / 5 * haberman_sayre(0.2))


@settings(max_examples=15, deadline=None)
@given(st.integers(1, 400), st.integers(0, 10 ** 6),
       st.tuples(*[st.floats(0.2, 5.0)] * 3))
def test_box_nodes_3d_hull_is_the_box(n, seed, size):
    p = box_nodes_3d(n, size=size, seed=seed)
    assert np.unique(p, axis=0).shape[0] == p.shape[0]
    assert np.allclose(p.min(axis=0), 0) and np.allclose(p.max(axis=0), size)
    on_face = np.isclose(p, 0).any(1) | np.isclose(p, size).any(1)
    assert (~on_face).sum() <= n
    for k in range(3):          # every face carries its four corners and more
        assert np.isclose(p[:, k], 0).sum() >= 4 and np.isclose(p[:, k], size[k]).sum() >= 4


def test_box_nodes_3d_bad_input():
    for kw, match in ((dict(n=0), "n must"), (dict(n=10, size=(1, 0, 1)), "size"),
                      (dict(n=10, origin=(0, np.nan, 0)), "origin"),
                      (dict(n=10, boundary_spacing=-1.0), "boundary_spacing"),
                      (dict(n=10, density=lambda x: 2 + 0 * x[:, 0]), "density")):
        with pytest.raises(ValueError, match=match):
            box_nodes_3d(**kw)


def test_sinker_coefficients():
    s = Sinker(8, contrast=1e4, seed=1)
    inside = s.centres[:, :1]
    assert s.viscosity(inside)[0] == pytest.approx(100.0)
    assert s.force(inside)[2, 0] == pytest.approx(-1.0)
    far = np.array([[5.0], [5.0], [5.0]])
    assert s.viscosity(far)[0] == pytest.approx(0.01) and s.force(far)[2, 0] == 0
    with pytest.raises(ValueError, match="count"):
        Sinker(0)


def test_auto_takes_fgmres_in_3d_from_its_size(spaces, monkeypatch):
    from skfem_nem.models import stokes_solvers as solvers
    ms = Manufactured3D(20.0)
    small = solve_stokes(spaces, ms.viscosity, ms.force)
    assert small.info["solver"] == "schur"
    monkeypatch.setattr(solvers, "AUTO_FGMRES_UNKNOWNS_3D", 10)
    big = solve_stokes(spaces, ms.viscosity, ms.force)
    assert big.info["solver"] == "fgmres"
    assert np.abs(big.u - small.u).max() < 1e-7 * np.abs(small.u).max()


def test_condensation_kernels_match_scikit_fem_assembly(spaces):
    """The tetrahedra's condensation kernels against scikit-fem's assembly of the same
    forms and sparse products, at a viscosity varying inside the tetrahedra: the
    condensed viscous block (exactly symmetric), A_bb^-1 A_bn and the divergence."""
    import scipy.sparse as sp
    from skfem import BilinearForm
    from skfem.helpers import ddot, sym_grad

    from skfem_nem.models.condensation_tet import condensed_viscous_tet
    from skfem_nem.models.stokes import quadrature_values

    @BilinearForm
    def visc(u, v, w):
        return 2.0 * w["eta"] * ddot(sym_grad(u), sym_grad(v))

    ub, bb = spaces.ubasis, spaces.bubbles
    eta = quadrature_values(spaces, lambda x: np.exp(3 * x[0] * x[1] + x[2]), "eta")
    cv = condensed_viscous_tet(ub, bb, eta)
    Ann = visc.assemble(ub, eta=eta).toarray()
    vb = bb.vector_basis()
    Abn = visc.assemble(ub, vb, eta=eta).toarray()
    Abb = visc.assemble(vb, eta=eta).toarray()
    AiAbn = np.linalg.solve(Abb, Abn)
    A = Ann - Abn.T @ AiAbn
    assert np.abs(cv.A.toarray() - A).max() < 1e-11 * np.abs(A).max()
    assert np.abs(cv.AiAbn.tocsr().toarray() - AiAbn).max() < 1e-11 * np.abs(AiAbn).max()
    assert (cv.A - cv.A.T).count_nonzero() == 0 or abs(cv.A - cv.A.T).max() == 0
    assert np.abs(sp.csr_matrix(cv.Ainv).toarray() - np.linalg.inv(Abb)).max() < 1e-9 * np.abs(
        np.linalg.inv(Abb)).max()


def test_loads_match_scikit_fem(spaces):
    """The 3D load by sparse products is scikit-fem's assembly of ``(f, v) - (tau,
    eps(v))``, also for a stress that is not symmetric (its symmetric part acts)."""
    from skfem_nem.models.condensation_tet import loads_tet
    from skfem_nem.models.stokes import body_force, stress_load
    ub = spaces.ubasis
    rng = np.random.default_rng(3)
    f = rng.normal(size=(3,) + ub.dx.shape)
    tau = rng.normal(size=(3, 3) + ub.dx.shape)
    ref = body_force.assemble(ub, f=f) + stress_load.assemble(ub, tau=tau)
    b = loads_tet(ub, f, tau)
    assert np.abs(b - ref).max() < 1e-13 * np.abs(ref).max()
    assert np.abs(loads_tet(ub, f) - body_force.assemble(ub, f=f)).max() < 1e-13 * np.abs(
        ref).max()


def test_viscous_amg_in_3d_is_plain_aggregation(spaces):
    """The 3D block's hierarchy does not smooth its prolongator (its rows would be as
    dense as the block's): each fine dof maps to one aggregate's six rigid-body modes."""
    from skfem_nem.models.stokes_solvers import StokesCache
    ms = Manufactured3D(20.0)
    cache = StokesCache()
    sol = solve_stokes(spaces, ms.viscosity, ms.force, solver="fgmres", cache=cache)
    P = cache.hierarchy.ml.levels[0].P.tocsr()
    assert np.diff(P.indptr).max() <= 6
    assert sol.iterations < 60


@pytest.mark.parametrize("method", ["nem", "nem-projection"])
def test_divergence_block_matches_scikit_fem(spaces, mesh, method):
    """The divergence block of the natural neighbours on tetrahedra by sparse products is
    scikit-fem's assembly of ``(u, grad q)``."""
    from skfem_nem.models.condensation_tet import divergence_tet
    from skfem_nem.models.stokes import weak_divergence
    S = spaces if method == "nem" else stokes_spaces(mesh, method)
    B = divergence_tet(S.ubasis, S.pbasis)
    ref = weak_divergence.assemble(S.ubasis, S.pbasis)
    assert abs(B - ref).max() < 1e-14 * abs(ref).max()


def test_the_solve_lets_the_whole_viscous_block_go(spaces, monkeypatch):
    """Once the block on the free dofs is made, the whole viscous block is let go before
    the solver starts (a 3D plate step at 10,000 nodes: 165 MB); the reactions, from its
    fixed rows alone, are the whole block's."""
    import gc
    import weakref

    import skfem_nem.models.stokes as stokes
    seen = {}
    assemble, solver = stokes.assemble_stokes, stokes.SOLVERS["fgmres"]

    def spy_assemble(*args, **kwargs):
        system = assemble(*args, **kwargs)
        seen["A"] = weakref.ref(system.A)
        return system

    def spy_solver(problem, *args, **kwargs):
        gc.collect()
        seen["alive"] = seen["A"]() is not None
        return solver(problem, *args, **kwargs)

    monkeypatch.setattr(stokes, "assemble_stokes", spy_assemble)
    monkeypatch.setitem(stokes.SOLVERS, "fgmres", spy_solver)
    ms = Manufactured3D(20.0)
    sol = solve_stokes(spaces, ms.viscosity, ms.force, no_slip=["left"], solver="fgmres",
                       tol=1e-10)
    assert seen["alive"] is False
    s = assemble(spaces, ms.viscosity, ms.force)
    fixed = sol.info["fixed"]
    whole = (s.A @ sol.u + s.B.T @ sol.p) - s.f
    assert np.array_equal(sol.info["reaction"][fixed], whole[fixed])
    assert np.abs(sol.info["reaction"][fixed]).max() > 0
    assert not sol.info["reaction"][np.setdiff1d(np.arange(spaces.ubasis.N), fixed)].any()


def test_an_assembled_block_is_reduced_and_scaled_over_its_own_arrays(spaces, monkeypatch):
    """The block ``solve_stokes`` assembles itself is taken to the free dofs and scaled
    for the AMG over its own arrays (no second copy of its entries: 3.6 GB at 100,000
    nodes); a ``system`` the caller gives is read only, and both solve alike."""
    import skfem_nem.models.stokes as stokes
    seen = {}
    assemble, solver = stokes.assemble_stokes, stokes.SOLVERS["fgmres"]

    def spy_assemble(*args, **kwargs):
        system = assemble(*args, **kwargs)
        seen["data"] = system.A.data
        return system

    def spy_solver(problem, *args, **kwargs):
        seen["owned"] = problem.owned
        seen["shared"] = np.shares_memory(problem.A.data, seen["data"])
        A = problem.A
        out = solver(problem, *args, **kwargs)
        seen["unit diagonal"] = np.allclose(A.diagonal(), 1.0)
        # an own block is let go once the hierarchy holds it (it is the scaled block then)
        seen["let go"] = problem.A is None
        return out

    monkeypatch.setattr(stokes, "assemble_stokes", spy_assemble)
    monkeypatch.setitem(stokes.SOLVERS, "fgmres", spy_solver)
    ms = Manufactured3D(20.0)
    own = solve_stokes(spaces, ms.viscosity, ms.force, no_slip=["left"], solver="fgmres",
                       tol=1e-10)
    assert seen == {"data": seen["data"], "owned": True, "shared": True, "let go": True,
                    "unit diagonal": True}
    given = assemble(spaces, ms.viscosity, ms.force)
    before = given.A.copy()
    theirs = solve_stokes(spaces, None, system=given, no_slip=["left"], solver="fgmres",
                          tol=1e-10)
    assert not (seen["owned"] or seen["let go"] or seen["unit diagonal"])
    assert (given.A != before).nnz == 0
    assert np.abs(own.u - theirs.u).max() < 1e-8 * np.abs(theirs.u).max()
    assert own.residual < 1e-10 and abs(own.residual - theirs.residual) < 1e-12


def test_the_viscous_block_as_blocks_solves_as_the_csr_block(spaces, monkeypatch):
    """``solve_stokes`` assembles the 3D viscous block as its nodes' upper blocks for
    ``"fgmres"`` and ``"auto"`` (``"auto"`` converts it where it factorises): the same
    velocity, pressure and reactions as from the CSR block, to rounding; other spaces
    refuse ``viscous_blocks=True`` by name."""
    import skfem_nem.models.stokes as stokes
    from skfem_nem.models.block_rows import BlockSymmetricRows
    assert isinstance(assemble_stokes(spaces, 1.0, viscous_blocks=True).A, BlockSymmetricRows)
    f = _down(lambda x: 1.0 + x[0])
    runs = {}
    for blocks in (True, False):
        monkeypatch.setattr(stokes, "takes_viscous_blocks", lambda s, b=blocks: b)
        runs[blocks] = [solve_stokes(spaces, 1.0, f, solver=name, tol=1e-9)
                        for name in ("fgmres", "auto")]
    for with_blocks, with_csr in zip(runs[True], runs[False]):
        for a, b in ((with_blocks.u, with_csr.u), (with_blocks.p, with_csr.p),
                     (with_blocks.info["reaction"], with_csr.info["reaction"])):
            assert np.abs(a - b).max() <= 1e-7 * np.abs(b).max()
    assert runs[True][1].info["solver"] == "schur"     # (converted to CSR)
    monkeypatch.undo()
    from skfem import MeshTri
    with pytest.raises(ValueError, match="viscous_blocks=True needs the natural-neighbour "
                                         "velocity on tetrahedra, got method 'nem' in 2D"):
        assemble_stokes(stokes_spaces(delaunay_mesh(MeshTri().refined(2).p.T)), 1.0,
                        viscous_blocks=True)
