"""Constrained natural neighbours: segments in the triangulation, the coordinates,
the meshes and the basis (interfaces with kinks, non-convex domains)."""
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from skfem import BilinearForm, Functional, MeshTri, condense, solve
from skfem.helpers import dot, grad
from conftest import load_benchmark
from helpers import check_properties, edge_set

from skfem_nem.geometry.meshes import triangulation_of
from skfem_nem import (NaturalNeighbourBasis, NaturalNeighbourFacetBasis, Triangulation,
                       delaunay_mesh, natural_neighbour_coordinates)

nonconvex = load_benchmark("nonconvex")


def _segments_of_other_triangulation(p, rng, k):
    """k edges of the Delaunay triangulation of a random subset of p: they never cross."""
    sub = rng.choice(p.shape[0], size=max(4, p.shape[0] // 2), replace=False)
    e = np.array(sorted(edge_set(Triangulation(p[sub]).triangles)))
    return sub[e[rng.choice(len(e), size=min(k, len(e)), replace=False)]]


def _crosses(p, a, b, c, d):
    """True if the open segments a-b and c-d cross properly."""
    def o(u, v, w):
        return np.sign((v[0] - u[0]) * (w[1] - u[1]) - (v[1] - u[1]) * (w[0] - u[0]))
    return (o(p[a], p[b], p[c]) * o(p[a], p[b], p[d]) < 0
            and o(p[c], p[d], p[a]) * o(p[c], p[d], p[b]) < 0)


def _check_constrained(tri, segments):
    E = edge_set(tri.triangles)
    assert all(tuple(sorted(s)) in E for s in tri.segments), "every segment is an edge"
    assert (tri.orientation() > 0).all()
    assert tri.non_delaunay_edges() == 0
    # every given segment is covered by its pieces
    for i, s in enumerate(segments):
        assert (tri.segment_source == i).any()


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(6, 80), st.integers(1, 30))
def test_hypothesis_cdt_random(seed, n, k):
    rng = np.random.default_rng(seed)
    p = rng.random((n, 2))
    seg = _segments_of_other_triangulation(p, rng, k)
    tri = Triangulation(p, segments=seg)
    _check_constrained(tri, seg)
    # the caller's array is untouched and the plain triangulation differs only by flips
    assert tri.npoints == n and tri.ntriangles == Triangulation(p).ntriangles


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(3, 9))
def test_hypothesis_cdt_grid_collinear(seed, m):
    """Co-circular grid nodes, segments along rows, columns and diagonals through
    other nodes (split there)."""
    rng = np.random.default_rng(seed)
    x, y = np.meshgrid(np.arange(m + 1.0), np.arange(m + 1.0))
    p = np.c_[x.ravel(), y.ravel()]
    idx = lambda i, j: i * (m + 1) + j  # noqa: E731
    i = int(rng.integers(0, m + 1))
    seg = [[idx(i, 0), idx(i, m)], [idx(0, 0), idx(m, m)]]
    tri = Triangulation(p, segments=np.array(seg))
    _check_constrained(tri, seg)
    assert tri.segments.shape[0] == 2 * m, "each split at the m - 1 nodes it passes"


def test_segment_errors_name_the_input():
    p = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [.5, .5]], float)
    with pytest.raises(ValueError, match=r"segments\[1\] = \[1, 3\] crosses segments\[0\] = "
                                         r"\[0, 2\]"):
        Triangulation(p + [[0, 0], [0, 0], [0, 0], [0, 0], [.1, 0]], segments=[[0, 2], [1, 3]])
    with pytest.raises(ValueError, match=r"segments\[0\] = \[0, 7\] refers to a node outside"):
        Triangulation(p, segments=[[0, 7]])
    with pytest.raises(ValueError, match=r"segments\[0\] = \[2, 2\] joins a node to itself"):
        Triangulation(p, segments=[[2, 2]])
    with pytest.raises(ValueError, match="integer node indices"):
        Triangulation(p, segments=[[0.0, 1.0]])
    with pytest.raises(ValueError, match=r"shape \(k, 2\)"):
        Triangulation(p, segments=[0, 1, 2])
    # a node on a segment splits it: (0, 2) through node 4
    tri = Triangulation(p, segments=[[0, 2]])
    assert sorted(map(tuple, tri.segments)) == [(0, 4), (2, 4)]
    assert tri.segment_source.tolist() == [0, 0]


def test_insert_on_a_segment_splits_it():
    rng = np.random.default_rng(0)
    p = np.r_[[[0, 0], [1, 0], [1, 1], [0, 1.]], rng.random((40, 2))]
    tri = Triangulation(p, segments=[[0, 2]])
    new = tri.insert([[.5, .5], [.25, .25], [.3, .6]])
    assert sorted(map(tuple, tri.segments)) == [(0, new[1]), (2, new[0]), (new[0], new[1])]
    assert tri.segment_source.tolist() == [0, 0, 0]
    _check_constrained(tri, [[0, 2]])
    # a failed insertion leaves the triangulation, segments included, as it was
    before = tri.snapshot()
    with pytest.raises(ValueError, match="coincides"):
        tri.insert([[.75, .75], [.5, .5]])
    after = tri.snapshot()
    assert all(np.array_equal(before[k], after[k]) for k in before)


def _interface_nodes(n=150, m=9, seed=3):
    """The unit square with the interface x = 1/2 carried by m nodes (segments
    0-1, 1-2, ...) and random nodes elsewhere."""
    rng = np.random.default_rng(seed)
    ys = np.linspace(0, 1, m)
    side = rng.random(6) * 0.9 + 0.05
    inner = rng.random((n, 2))
    inner = inner[(np.abs(inner[:, 0] - .5) > .01) & (inner.min(1) > .01) & (inner.max(1) < .99)]
    p = np.r_[np.c_[np.full(m, .5), ys], np.c_[np.zeros(m), ys], np.c_[np.ones(m), ys],
              np.c_[side, 0 * side], np.c_[side, 1 + 0 * side], inner]
    return p, np.c_[np.arange(m - 1), np.arange(1, m)]


def test_coordinates_see_only_visible_nodes():
    p, seg = _interface_nodes()
    tri = Triangulation(p, segments=seg)
    rng = np.random.default_rng(0)
    q = rng.random((400, 2))
    q = q[np.abs(q[:, 0] - .5) > 1e-3]
    F, _ = check_properties(tri, q, natural_neighbour_coordinates, grad_tol=1e-9)
    rows, cols = np.nonzero(F)
    # no natural neighbour across the interface (nodes on it are seen from both sides)
    side = np.sign(p[cols, 0] - .5)
    assert np.all((side == 0) | (side == np.sign(q[rows, 0] - .5)))
    # the plain coordinates do reach across, which is what the segments prevent
    F0 = natural_neighbour_coordinates(Triangulation(p), q).toarray()
    r0, c0 = np.nonzero(F0)
    assert np.any(np.sign(p[c0, 0] - .5) * np.sign(q[r0, 0] - .5) < 0)
    # exact gradients of the constrained functions (central differences, h = 1e-6)
    for kind in ("sibson", "laplace"):
        _, (Dx, Dy) = natural_neighbour_coordinates(tri, q, gradient=True, kind=kind)
        for D, e in ((Dx, [1e-6, 0]), (Dy, [0, 1e-6])):
            fd = (natural_neighbour_coordinates(tri, q + e, kind=kind)
                  - natural_neighbour_coordinates(tri, q - e, kind=kind)) / 2e-6
            assert abs(fd - D).max() < 1e-5 * max(1.0, abs(D).max())
    # on a segment: the linear 1D weights of its two nodes
    y = rng.random(50)
    on = natural_neighbour_coordinates(tri, np.c_[np.full(50, .5), y]).toarray()
    assert (np.count_nonzero(on, axis=1) <= 2).all()
    np.testing.assert_allclose(on @ p, np.c_[np.full(50, .5), y], atol=1e-14)
    with pytest.raises(ValueError, match="area method only"):
        natural_neighbour_coordinates(tri, q, method="lasserre")


def _kinked(x):
    """Piecewise linear, flux-continuous for k = 1 | 10 across x = 1/2."""
    return np.where(x[0] < .5, x[0], .5 + (x[0] - .5) / 10) + 0.3 * x[1]


@BilinearForm
def _conduction(u, v, w):
    return np.where(w.x[0] < .5, 1.0, 10.0) * dot(grad(u), grad(v))


def _interface_patch_error(mesh):
    basis = NaturalNeighbourBasis(mesh)
    A = _conduction.assemble(basis)
    u = _kinked(mesh.p)
    x = solve(*condense(A, np.zeros(basis.N), x=u.copy(), D=basis.get_dofs().all()))
    return np.abs(x - u).max()


def test_interface_patch_test():
    """-div(k grad u) = 0, k = 1 | 10 across x = 1/2, kinked linear solution: exact
    at every node with the interface as segments; the smooth functions cannot kink."""
    p, seg = _interface_nodes()
    mesh = delaunay_mesh(p, segments={"interface": seg})
    assert _interface_patch_error(mesh) < 1e-10
    # plain NEM on the same nodes: measured 3.0e-2
    assert _interface_patch_error(delaunay_mesh(p)) > 1e-3
    # the interface is a named (interior) boundary; a facet basis integrates over it
    f = mesh.boundaries["interface"]
    assert f.size == seg.shape[0] and (mesh.f2t[1, f] >= 0).all()
    fb = NaturalNeighbourFacetBasis(mesh, facets=f)
    # (each facet's normal points out of its first triangle, either side: n_x = +-1)
    along = Functional(lambda w: w["u"] * w.n[0] ** 2)
    u = _kinked(mesh.p)
    # the integral of u over the interface: int_0^1 (1/2 + 0.3 y) dy = 0.65
    assert abs(along.assemble(fb, u=fb.interpolate(u)) - 0.65) < 1e-12
    # scikit-fem's mesh operations return new meshes that keep the constraints
    again = mesh.with_boundaries({"left": lambda x: x[0] == 0})
    assert _interface_patch_error(again) < 1e-10


def test_holes_and_non_convex_meshes():
    p, seg, hole = nonconvex.domain("L-shape", 400)
    mesh = delaunay_mesh(p, segments={"outline": seg}, holes=hole)
    assert mesh.p.shape[1] == p.shape[0]
    mid = mesh.p[:, mesh.t].mean(axis=1)
    assert not ((mid[0] > .5) & (mid[1] > .5)).any(), "the notch is left out"
    assert set(mesh.boundaries["outline"]) == set(mesh.boundary_facets())
    basis = NaturalNeighbourBasis(mesh)
    with pytest.raises(ValueError, match=r"point 1 at \[0.75, 0.6\] is outside the domain"):
        basis.probes(np.array([[.25, .75], [.25, .6]]))
    # boundary data are interpolated exactly along the whole outline
    tri = basis.triangulation
    assert nonconvex.boundary_interpolation(p, seg, tri) < 1e-12
    assert nonconvex.boundary_interpolation(p, seg, Triangulation(p)) > 1e-5
    with pytest.raises(ValueError, match="area method only"):
        NaturalNeighbourBasis(mesh, method="lasserre")
    with pytest.raises(ValueError, match=r"points\[.*\] = .* lies in a hole"):
        delaunay_mesh(np.r_[p, [[.8, .8]]], segments={"outline": seg}, holes=hole)
    with pytest.raises(ValueError, match=r"holes\[0\] = \[2.0, 2.0\] is outside"):
        delaunay_mesh(p, segments=seg, holes=[[2.0, 2.0]])
    notch = (p[seg] >= .5).all(axis=(1, 2))
    with pytest.raises(ValueError, match="take every triangle"):
        delaunay_mesh(p, segments=seg[~notch], holes=hole)
    with pytest.raises(ValueError, match="2D points only"):
        delaunay_mesh(np.random.default_rng(0).random((10, 3)), segments=[[0, 1]])


def test_scikit_fem_l_shape_is_constrained():
    """A non-convex scikit-fem mesh gets the constrained coordinates of its nodes
    with its boundary facets as segments: exact along the concave boundary, probes
    anywhere inside (also at the re-entrant corner), an error in the notch."""
    m = MeshTri.init_lshaped().refined(2)
    basis = NaturalNeighbourBasis(m)
    bf = m.facets[:, m.boundary_facets()]
    s = np.random.default_rng(0).random(bf.shape[1])
    x = m.p[:, bf[0]] * (1 - s) + m.p[:, bf[1]] * s
    u = np.sin(3 * m.p[0]) * np.cos(2 * m.p[1])
    np.testing.assert_allclose(basis.probes(x) @ u, u[bf[0]] * (1 - s) + u[bf[1]] * s,
                               atol=1e-13)
    assert abs(basis.probes(np.zeros((2, 1))) @ u - u[(m.p == 0).all(0)]).max() < 1e-14
    with pytest.raises(ValueError, match="outside the domain"):
        basis.probes(np.array([[.5], [.5]]))


def test_non_convex_rates():
    """Smooth manufactured Poisson solutions on the L-shape and the slit square
    converge at the optimal rates (measured 2.1-2.3 in L2, 1.03-1.11 in H1)."""
    rows = nonconvex.study([400, 1600])
    for a, b in zip(rows[::2], rows[1::2]):
        rl2 = nonconvex.rate(a[1], b[1], a[4], b[4])
        rh1 = nonconvex.rate(a[1], b[1], a[5], b[5])
        assert rl2 >= 1.9 and rh1 >= 0.95, (a[0], rl2, rh1)
        assert b[4] < b[6] and b[5] < b[7], "NEM below P1 on the same triangles"


def test_plain_mesh_with_the_same_triangles_stays_plain():
    """Segments that are Delaunay edges already give the same triangles as the plain
    mesh; only the constrained mesh and the meshes scikit-fem derives from it (which
    keep its named boundaries) get the constrained triangulation."""
    p = np.random.default_rng(7).random((60, 2))
    seg = Triangulation(p).edges[::7]
    mc = delaunay_mesh(p, segments={"faults": seg})
    mu = delaunay_mesh(p)
    assert np.array_equal(mc.t, mu.t)
    assert triangulation_of(mc).segments.shape[0] == seg.shape[0]
    for plain in (mu, MeshTri(mc.p, mc.t), mu.with_boundaries({"left": lambda x: x[0] < .1})):
        assert triangulation_of(plain).segments.size == 0
    derived = mc.with_boundaries({"left": lambda x: x[0] < .1}).with_subdomains(
        {"half": lambda x: x[0] < .5})
    assert triangulation_of(derived) is triangulation_of(mc)


def test_line_segments_of_box_nodes():
    from skfem_nem.geometry.nodesets import box_nodes, line_segments, polyline_nodes
    ring = polyline_nodes([[.3, .3], [.7, .3], [.7, .7], [.3, .7]], 0.05, closed=True)
    p = box_nodes(300, lines=[np.r_[ring, ring[:1]]], seed=2)
    seg = line_segments(p, ring, closed=True)
    assert seg.shape == (ring.shape[0], 2) and np.allclose(p[seg[:, 0]], ring, atol=1e-12)
    mesh = delaunay_mesh(p, segments={"ring": seg})
    assert mesh.boundaries["ring"].size == ring.shape[0]
    with pytest.raises(ValueError, match=r"line point 1 at \[0.5, 0.51\] is not a node"):
        line_segments(p, [[.3, .3], [.5, .51]])
