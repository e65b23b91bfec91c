"""Walls in 3D: natural neighbours that do not see through an interface's triangles.

Checked: the faces become walls only where they are Delaunay faces (a missing one is named
and leaves the walls as they were); coordinates keep their partition of unity and linear
precision, see nothing across a wall, are the face's barycentric coordinates on it and
tend to them from both sides; Watson's values agree with the Box 1 cells of the same cut
regions; and the settling sphere moves at the Haberman-Sayre velocity to its polyhedron's
volume.
"""
import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import given, settings, strategies as st
from scipy.spatial import ConvexHull

from skfem_nem import delaunay_mesh
from skfem_nem.coordinates.lasserre import sibson_coordinates_nd
from skfem_nem.coordinates.watson3d import coordinates_3d
from skfem_nem.geometry.delaunay3d import Delaunay3D
from skfem_nem.geometry.walls3d import WALL, MissingFace, face_keys

A = 0.5


def fibonacci(m, r):
    k = np.arange(m) + 0.5
    phi, th = np.arccos(1 - 2 * k / m), np.pi * (1 + 5 ** 0.5) * k
    return r * np.c_[np.cos(th) * np.sin(phi), np.sin(th) * np.sin(phi), np.cos(phi)]


def sphere_nodes(seed, m=200, n=4000, gap=0.1):
    """A sphere's surface nodes (its hull triangles the walls) and random nodes of the cube
    [-1, 1]^3 kept ``gap`` away from it."""
    rng = np.random.default_rng(seed)
    S = fibonacci(m, A)
    box = rng.uniform(-1, 1, (n, 3))
    box = box[np.abs(np.linalg.norm(box, axis=1) - A) > gap]
    return np.vstack([S, box]), ConvexHull(S).simplices


@pytest.fixture(scope="module")
def walled():
    P, F = sphere_nodes(1)
    tri = Delaunay3D(P)
    slots = tri.wall_off({"sphere": F})
    return P, F, tri, slots


def watson(tri, q):
    """Watson's rows and the indices of the queries it flags."""
    flagged = []

    def fallback(x):
        flagged.append(x.shape[0])
        return sp.csr_matrix((x.shape[0], tri.npoints))
    W = coordinates_3d(tri, q, fallback)
    return W, np.asarray(W.sum(axis=1)).ravel() > 0.5


def test_the_sphere_walls_off_its_inside(walled):
    """Every wall face joins a tetrahedron inside the sphere to one outside, every other
    face two on one side; the walls are encoded as ``WALL - t``."""
    P, F, tri, slots = walled
    assert slots.sum() == 2 * len(F)                 # each triangle: a face of two tets
    inside = np.linalg.norm(P[tri.simplices].mean(axis=1), axis=1) < A
    t, k = np.nonzero(tri.neighbors >= 0)
    across = inside[t] != inside[tri.neighbors[t, k]]
    assert np.array_equal(across, slots[t, k])
    t, k = np.nonzero(slots)
    assert (tri.walled_neighbors[t, k] == WALL - tri.neighbors[t, k]).all()
    assert (tri.walled_neighbors[~slots] == tri.neighbors[~slots]).all()
    with pytest.raises(ValueError, match="walls need at most 2,097,151 nodes"):
        face_keys(F, 3_000_000)


def test_a_missing_face_is_named_and_the_walls_stay():
    P, F = sphere_nodes(2)
    tri = Delaunay3D(P)
    bad = F.copy()
    bad[7] = [0, 1, len(P) - 1]                      # two surface nodes and a far one
    with pytest.raises(MissingFace, match=r"sphere\[7\] = \[0, 1, "):
        tri.wall_off({"sphere": bad})
    assert tri.walled_neighbors is None
    tri.wall_off({"sphere": F})
    before = tri.walled_neighbors.copy()
    with pytest.raises(ValueError, match=r"faces\['x'\]\[0\] = \[0, 0, 1\] repeats a node"):
        tri.wall_off({"x": [[0, 0, 1]]})
    with pytest.raises(ValueError, match="outside 0.."):
        tri.wall_off({"x": [[0, 1, len(P)]]})
    assert np.array_equal(tri.walled_neighbors, before)


@settings(max_examples=6, deadline=None)
@given(st.integers(0, 10 ** 6))
def test_coordinates_see_nothing_through_a_wall(seed):
    P, F = sphere_nodes(seed, n=2500)
    tri = Delaunay3D(P)
    tri.wall_off({"sphere": F})
    rng = np.random.default_rng(seed)
    q = rng.uniform(-0.8, 0.8, (3000, 3))
    Phi = sibson_coordinates_nd(P, q, delaunay=tri)
    assert np.abs(np.asarray(Phi.sum(axis=1)).ravel() - 1).max() < 1e-12
    assert np.abs(Phi @ P - q).max() < 1e-12
    # which side of the polyhedron: the tetrahedron holding the query
    inside_tet = np.linalg.norm(P[tri.simplices].mean(axis=1), axis=1) < A
    side = inside_tet[tri.find_simplex(q)]
    C = Phi.tocoo()
    interior = np.linalg.norm(P, axis=1) < A - 1e-9
    exterior = np.linalg.norm(P, axis=1) > A + 1e-9
    assert not interior[C.col[~side[C.row]]].any()
    assert not exterior[C.col[side[C.row]]].any()


def test_box1_fallback_agrees_with_watson_off_the_folds(walled):
    """Watson's flagged queries take the Box 1 cells of the same cut region: the same
    values, except beside the folds of a curved wall on its concave side, where Watson's
    terms leave [0, 1] (and stay continuous up to the wall) and the cells do not."""
    from skfem_nem.coordinates.lasserre import _coordinates
    P, F, tri, _ = walled
    q = np.random.default_rng(3).uniform(-0.7, 0.7, (5000, 3))
    B = _coordinates(P, q, False, tri, "raise", 0)
    W, done = watson(tri, q)
    assert done.mean() > 0.85
    away = done & (np.abs(np.linalg.norm(q, axis=1) - A) > 0.02)
    assert abs(B[away] - W[away]).max() < 1e-11
    plain = sibson_coordinates_nd(P, q, delaunay=Delaunay3D(P))
    assert abs(plain - W).max() > 0.1          # (the walls change the values near them)
    with pytest.raises(ValueError, match="has walls"):
        sibson_coordinates_nd(P, q[:5], gradient=True, delaunay=tri)


def test_on_a_wall_the_face_interpolates_linearly_from_both_sides(walled):
    P, F, tri, _ = walled
    rng = np.random.default_rng(4)
    w = rng.dirichlet([1, 1, 1], 40)
    on = np.einsum("fk,fkd->fd", w, P[F[:40]])
    bary = sp.csr_matrix((w.ravel(), (np.repeat(np.arange(40), 3), F[:40].ravel())),
                         shape=(40, len(P))).toarray()
    assert np.abs(sibson_coordinates_nd(P, on, delaunay=tri).toarray() - bary).max() < 1e-12
    normal = on / np.linalg.norm(on, axis=1, keepdims=True)
    for eps in (1e-7, -1e-7):
        near = sibson_coordinates_nd(P, on + eps * normal, delaunay=tri).toarray()
        assert np.abs(near - bary).max() < 1e-3


def test_delaunay_mesh_names_the_walls_and_refuses_them_in_2d():
    P, F = sphere_nodes(5, n=1500)
    mesh = delaunay_mesh(P, faces={"sphere": F})
    facets = mesh.boundaries["sphere"]
    assert facets.size == len(F)
    got = np.sort(mesh.facets[:, facets].T, axis=1)
    assert np.array_equal(np.unique(got, axis=0), np.unique(np.sort(F, axis=1), axis=0))
    derived = mesh.with_subdomains({"all": np.arange(mesh.t.shape[1])})
    from skfem_nem.geometry.meshes import triangulation_of
    assert triangulation_of(derived).walled_neighbors is not None
    with pytest.raises(ValueError, match="faces are supported for 3D points only"):
        delaunay_mesh(np.random.default_rng(0).random((10, 2)), faces=[[0, 1, 2]])
    with pytest.raises(MissingFace):
        delaunay_mesh(P, faces=np.array([[0, 1, len(P) - 1]]))


def test_the_interpolator_keeps_the_walls(walled):
    """Sibson's values on a walled tetrahedralisation are the walled coordinates times the
    values, for a large batch (Watson's interpolant) and a small one (the coordinates); the
    methods that cannot keep walls refuse them."""
    from skfem_nem.coordinates.interpolator import NaturalNeighbourInterpolator
    P, F, tri, _ = walled
    values = np.c_[np.sin(3 * P[:, 0]) * P[:, 1], np.linalg.norm(P, axis=1)]
    itp = NaturalNeighbourInterpolator(tri, values)
    q = np.random.default_rng(6).uniform(-0.7, 0.7, (4000, 3))
    Phi = sibson_coordinates_nd(P, q, delaunay=tri)
    assert np.abs(itp(q) - Phi @ values).max() < 1e-11
    assert np.abs(itp(q[:7]) - Phi[:7] @ values).max() < 1e-11
    # one outside the sphere, zero on and inside it: zero inside with the walls, not without
    kinked = (np.linalg.norm(P, axis=1) > A + 1e-9).astype(float)
    inside = np.linalg.norm(q, axis=1) < 0.95 * A
    assert np.abs(NaturalNeighbourInterpolator(tri, kinked)(q)[inside]).max() < 1e-12
    plain = NaturalNeighbourInterpolator(Delaunay3D(P), kinked)
    assert np.abs(plain(q)[inside]).max() > 0.01
    lin = NaturalNeighbourInterpolator(tri, values, method="linear")
    assert np.isfinite(lin(q)).all()
    for method in ("nearest", "sibson1", "farin"):
        with pytest.raises(ValueError, match=f"method '{method}' does not keep them"):
            NaturalNeighbourInterpolator(tri, values, method=method)
    with pytest.raises(ValueError, match="has walls"):
        itp.gradient(q[:3])


def test_a_basis_on_walls_passes_the_patch_test_and_sees_nothing_through():
    """The smoothed basis of a walled mesh: a linear field exact in every gradient; a field
    zero on the sphere and inside it (x outside) has a zero gradient in every tetrahedron
    inside, where without walls the outside's values leak in."""
    from skfem_nem import NaturalNeighbourBasis
    P, F = sphere_nodes(7, n=2500)
    mesh = delaunay_mesh(P, faces={"sphere": F})
    basis = NaturalNeighbourBasis(mesh)
    g = np.array([0.3, -1.2, 0.7])
    G = basis.interpolate(P @ g).grad
    # (7.5e-11 at worst, in small tetrahedra at the cube's corners, with or without walls)
    assert np.abs(G - g[:, None, None]).max() < 1e-9
    u = np.where(np.linalg.norm(P, axis=1) > A + 1e-9, P[:, 0], 0.0)
    inside = np.linalg.norm(P[mesh.t.T].mean(axis=1), axis=1) < A
    assert np.abs(basis.interpolate(u).grad[:, inside]).max() < 1e-11
    plain = NaturalNeighbourBasis(delaunay_mesh(P))
    assert np.abs(plain.interpolate(u).grad[:, inside]).max() > 0.1
    with pytest.raises(ValueError, match="has walls"):
        NaturalNeighbourBasis(mesh, integration="gauss")


def test_box1_on_walls_and_on_the_hull_at_once(walled):
    """The Box 1 coordinates (the fallback of Watson's flagged queries) of points on wall
    faces are the faces' barycentric coordinates, beside points on the hull, which keep
    the hull's rule."""
    from skfem_nem.coordinates.lasserre import _coordinates
    P, F, tri, _ = walled
    w = np.random.default_rng(8).dirichlet([1, 1, 1], 30)
    on = np.einsum("fk,fkd->fd", w, P[F[:30]])
    bary = sp.csr_matrix((w.ravel(), (np.repeat(np.arange(30), 3), F[:30].ravel())),
                         shape=(30, len(P))).toarray()
    H = np.asarray(tri.convex_hull)[:5]
    hull = P[H].mean(axis=1)                      # centroids of hull triangles
    got = _coordinates(P, np.vstack([on, hull]), False, tri, "raise", 0).toarray()
    assert np.abs(got[:30] - bary).max() < 1e-12
    plain = Delaunay3D(P)
    expect = _coordinates(P, hull, False, plain, "raise", 0).toarray()
    assert np.abs(got[30:] - expect).max() < 1e-12
