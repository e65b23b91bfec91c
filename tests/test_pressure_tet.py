"""The 3D pressure blocks from 4 x 4 blocks a tetrahedron equal scikit-fem's assembly."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from helpers import cube_nodes
from skfem_nem import delaunay_mesh
from skfem_nem.models.condensation_tet import condensed_viscous_tet
from skfem_nem.models.pressure_tet import (bubble_stabilisation_tet, tet_blocks_summed,
                                           weighted_mass_tet)
from skfem_nem.models.stokes import _blocks_once, weighted_mass
from skfem_nem.models.stokes_bases import stokes_spaces


def _relative(A, B):
    return abs(A - B).max() / abs(B).max()


@settings(max_examples=4, deadline=None)
@given(seed=st.integers(0, 10_000), method=st.sampled_from(["nem", "taylor-hood"]))
def test_the_weighted_pressure_mass_is_scikit_fems(seed, method):
    spaces = stokes_spaces(delaunay_mesh(cube_nodes(40, seed=seed)), method)
    pb = spaces.pbasis
    c = np.exp(np.random.default_rng(seed).normal(size=pb.dx.shape))
    M = weighted_mass_tet(pb, c)
    assert _relative(M, weighted_mass.assemble(pb, c=c).tocsr()) < 1e-14
    assert _relative(M, M.T) < 1e-15


def test_the_bubbles_stabilisation_is_the_triple_product():
    spaces = stokes_spaces(delaunay_mesh(cube_nodes(60, seed=4)))
    eta = np.exp(np.random.default_rng(4).normal(size=spaces.pbasis.dx.shape))
    cv = condensed_viscous_tet(spaces.ubasis, spaces.bubbles, eta)
    cache = _blocks_once(spaces)
    Bb = cache["Bb"]
    S = bubble_stabilisation_tet(spaces.pbasis, cache["tet_divergence"].local, cv.AiAbn.Q)
    assert _relative(S, (Bb @ cv.Ainv @ Bb.T).tocsr()) < 1e-13


def test_blocks_of_another_shape_are_named():
    spaces = stokes_spaces(delaunay_mesh(cube_nodes(40, seed=5)))
    ne = spaces.mesh.nelements
    with pytest.raises(ValueError, match=rf"local must have shape \({ne}, 4, 4\), got "
                                         rf"\({ne}, 3, 3\)"):
        tet_blocks_summed(spaces.pbasis, np.zeros((ne, 3, 3)))


def test_the_kept_pattern_sums_each_new_set_of_blocks():
    """The second and later calls on one basis read the kept pattern: each must still be
    scipy's sum of the blocks, in canonical CSR form."""
    import scipy.sparse as sp
    spaces = stokes_spaces(delaunay_mesh(cube_nodes(50, seed=6)))
    pb = spaces.pbasis
    dofs = np.asarray(pb.element_dofs).T
    rows, cols = np.repeat(dofs, 4, axis=1).ravel(), np.tile(dofs, (1, 4)).ravel()
    rng = np.random.default_rng(6)
    for _ in range(3):
        local = rng.normal(size=(dofs.shape[0], 4, 4))
        S = tet_blocks_summed(pb, local)
        ref = sp.csr_matrix((local.ravel(), (rows, cols)), shape=(pb.N, pb.N))
        assert S.has_canonical_format and S.nnz == ref.nnz
        assert np.array_equal(S.indptr, ref.indptr) and np.array_equal(S.indices, ref.indices)
        assert _relative(S, ref) < 1e-15
