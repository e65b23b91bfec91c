"""Facets and edges by integer keys (skfem_nem.geometry.entities) give scikit-fem's own
arrays, and the 3D meshes the package builds carry them from the start."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from skfem import MeshTet, MeshTri

from skfem_nem.geometry.entities import build_entities, build_inverse, prime_facets, unique_ints
from skfem_nem.geometry.meshes import delaunay_mesh


@settings(max_examples=40, deadline=None)
@given(st.lists(st.integers(-5, 40), max_size=200))
def test_unique_ints_is_numpys(values):
    a = np.array(values, dtype=np.int64)
    u = unique_ints(a)
    ref, inv = np.unique(a, return_inverse=True)
    assert u.dtype == ref.dtype and np.array_equal(u, ref)
    got, ginv = unique_ints(a, return_inverse=True)
    assert np.array_equal(got, ref) and np.array_equal(ginv, inv.ravel())


def _fresh(mesh):
    """A scikit-fem mesh of the same nodes and cells that builds its own facets."""
    return type(mesh)(mesh.p, mesh.t)


@settings(max_examples=15, deadline=None)
@given(st.integers(0, 2 ** 31), st.integers(5, 300), st.sampled_from([2, 3]))
def test_keyed_entities_are_scikit_fems(seed, n, dim):
    rng = np.random.default_rng(seed)
    p = rng.random((n, dim))
    if seed % 3 == 0:                   # lattice points: co-spherical, repeated keys
        p = np.round(p * 3) / 3 + 1e-3 * rng.random((n, dim))
    mesh = _fresh(delaunay_mesh(np.unique(p, axis=0)))
    refdom = mesh.elem.refdom
    facets, t2f = build_entities(mesh.t, refdom.facets)
    ref_facets, ref_t2f = mesh.build_entities(mesh.t, refdom.facets)
    assert np.array_equal(facets, ref_facets) and facets.dtype == ref_facets.dtype
    assert np.array_equal(t2f, ref_t2f) and t2f.dtype == ref_t2f.dtype
    f2t = build_inverse(mesh.t, t2f)
    ref_f2t = mesh.build_inverse(mesh.t, ref_t2f)
    assert np.array_equal(f2t, ref_f2t) and f2t.dtype == ref_f2t.dtype


def test_primed_mesh_matches_scikit_fem():
    p = np.random.default_rng(7).random((400, 3))
    mesh = delaunay_mesh(p)
    assert isinstance(mesh, MeshTet)
    assert {"_facets", "_t2f", "_f2t", "_f2e"} <= set(vars(mesh))   # built by keys
    ref = _fresh(mesh)
    for name in ("facets", "t2f", "f2t", "f2e"):
        got, want = getattr(mesh, name), getattr(ref, name)
        assert got.dtype == want.dtype and np.array_equal(got, want), name
    assert np.array_equal(mesh.boundary_facets(), ref.boundary_facets())


def test_prime_keeps_what_a_mesh_has():
    mesh = MeshTri.init_symmetric().refined(2)
    t2f = mesh.t2f                                  # scikit-fem's own
    prime_facets(mesh)
    assert mesh.t2f is t2f


@pytest.mark.parametrize("limit, primed", [(10 ** 6, True), (3, False)])
def test_prime_past_the_key_range_leaves_the_mesh(monkeypatch, limit, primed):
    monkeypatch.setattr("skfem_nem.geometry.entities.MAX_KEYED_NODES", limit)
    mesh = _fresh(delaunay_mesh(np.random.default_rng(1).random((30, 3))))
    prime_facets(mesh)
    assert ("_t2f" in vars(mesh)) == primed
    assert np.array_equal(mesh.t2f, _fresh(mesh).t2f)
