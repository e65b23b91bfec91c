"""Box 1 (Lasserre) coordinates: agreement with the 2D area method and the
defining properties in 3D and 4D."""
import numpy as np

from skfem_nem import sibson_coordinates
from skfem_nem.coordinates.lasserre import sibson_coordinates_nd


def test_2d_agrees_with_area_method():
    rng = np.random.default_rng(0)
    p = np.r_[[[0, 0], [1, 0], [1, 1], [0, 1]], rng.random((150, 2))]
    q = 0.1 + 0.8 * rng.random((150, 2))
    A, (ax, ay) = sibson_coordinates_nd(p, q, gradient=True)
    B, (bx, by) = sibson_coordinates(p, q, gradient=True)
    assert abs(A - B).max() < 1e-12
    assert max(abs(ax - bx).max(), abs(ay - by).max()) < 1e-9


def test_3d_4d_properties_and_finite_differences():
    rng = np.random.default_rng(1)
    for d, n, m in ((3, 220, 40), (4, 120, 8)):
        p = rng.random((n, d))
        q = 0.3 + 0.4 * rng.random((m, d))
        F, G = sibson_coordinates_nd(p, q, gradient=True)
        F = F.toarray()
        np.testing.assert_allclose(F.sum(1), 1, atol=1e-12)
        np.testing.assert_allclose(F @ p, q, atol=1e-12)
        assert F.min() > -1e-14
        Gd = [g.toarray() for g in G]
        for k in range(d):
            np.testing.assert_allclose(Gd[k].sum(1), 0, atol=1e-9)
            np.testing.assert_allclose(Gd[k] @ p[:, k], 1, atol=1e-9)
            h = np.zeros(d)
            h[k] = 1e-6
            fd = (sibson_coordinates_nd(p, q + h).toarray()
                  - sibson_coordinates_nd(p, q - h).toarray()) / 2e-6
            assert np.abs(fd - Gd[k]).max() < 1e-4 * max(1, np.abs(Gd[k]).max())
        np.testing.assert_allclose(sibson_coordinates_nd(p, p[:5]).toarray(), np.eye(n)[:5],
                                   atol=1e-12)
