"""Node sets, forms and checks shared by several test files."""
import numpy as np
from skfem import BilinearForm
from skfem.helpers import dot, grad

from skfem_nem import Triangulation, sibson_coordinates

# ---------------------------------------------------------------------------
# problems
# ---------------------------------------------------------------------------


def plastic_inclusion():
    """A visco-elasto-plastic step's input on 300 random nodes of the unit square: a
    stiff (viscosity 1e3), elastic (shear modulus 10), yielding (0.05) heavy inclusion
    0.4 x 0.2 in a fluid of viscosity 1. Returns the spaces, the material, the force
    and the zero initial stress."""
    from skfem_nem import delaunay_mesh
    from skfem_nem.geometry.nodesets import box_nodes
    from skfem_nem.models.rheology import Material
    from skfem_nem.models.stokes import stokes_spaces
    S = stokes_spaces(delaunay_mesh(box_nodes(300, seed=1)), "nem")
    X = S.quadrature_points
    ne, nq = X.shape[1:]
    inside = (np.abs(X[0] - 0.5) < 0.2) & (np.abs(X[1] - 0.5) < 0.1)
    mat = Material(np.where(inside, 1e3, 1.0), np.where(inside, 10.0, np.inf),
                   np.where(inside, 0.05, np.inf))
    return S, mat, np.stack([0 * X[0], -1.0 * inside]), np.zeros((2, 2, ne, nq))


# ---------------------------------------------------------------------------
# node sets
# ---------------------------------------------------------------------------


def square_nodes(n=300, k=12, seed=0, jitter=0.0, margin=0.0):
    """The unit square's corners, k - 1 nodes on each side (evenly spaced, or
    shifted by up to ``jitter`` of a spacing) and n random interior nodes at
    least ``margin`` from the walls."""
    rng = np.random.default_rng(seed)
    if jitter:
        s = (np.arange(1, k) + jitter * rng.random(k - 1)) / k
    else:
        s = np.linspace(0, 1, k + 1)[1:-1]
    return np.r_[[[0, 0], [1, 0], [1, 1], [0, 1]], np.c_[s, 0 * s], np.c_[s, 1 + 0 * s],
                 np.c_[0 * s, s], np.c_[1 + 0 * s, s],
                 margin + (1 - 2 * margin) * rng.random((n, 2))]


def cube_nodes(n=250, seed=0, per_face=None, margin=(0.0, 0.0)):
    """The unit cube's corners, ``per_face`` random nodes on each of its six
    faces (default n^(2/3)) and n random interior nodes; ``margin`` keeps the
    face nodes and the interior nodes that far from the edges and the walls."""
    rng = np.random.default_rng(seed)
    per_face = int(n ** (2 / 3)) if per_face is None else per_face
    corners = np.array(np.meshgrid([0, 1], [0, 1], [0, 1], indexing="ij")).reshape(3, -1).T
    faces = []
    for ax in range(3):
        for v in (0.0, 1.0):
            f = margin[0] + (1 - 2 * margin[0]) * rng.random((per_face, 3))
            f[:, ax] = v
            faces.append(f)
    return np.concatenate([corners, *faces, margin[1] + (1 - 2 * margin[1]) * rng.random((n, 3))])


def edge_set(T):
    """The edges of the triangles T as a set of sorted node pairs."""
    e = np.concatenate([T[:, [0, 1]], T[:, [1, 2]], T[:, [2, 0]]])
    e.sort(axis=1)
    return {tuple(r) for r in e}


def vortex(x):
    """A divergence-free cellular flow in the unit square (2D) or cube (3D),
    tangential on the walls (free slip). In 3D it turns about the vertical
    axis through the centre, the other way round, and fades towards the top
    and bottom as sin(pi z)."""
    X, Y = x[:, 0], x[:, 1]
    u = np.sin(np.pi * X) ** 2 * np.sin(2 * np.pi * Y)
    v = -np.sin(np.pi * Y) ** 2 * np.sin(2 * np.pi * X)
    if x.shape[1] == 2:
        return np.c_[u, v]
    s = np.sin(np.pi * x[:, 2])
    return np.c_[-u * s, -v * s, 0 * s]


# ---------------------------------------------------------------------------
# forms
# ---------------------------------------------------------------------------

@BilinearForm
def laplace(u, v, w):
    return dot(grad(u), grad(v))


@BilinearForm
def mass(u, v, w):
    return u * v


# ---------------------------------------------------------------------------
# checks of coordinate matrices
# ---------------------------------------------------------------------------

def dense(A):
    return np.asarray(A.todense())


def check_properties(p, q, coords, tol=1e-12, grad=True, grad_tol=1e-10, neg_tol=1e-14, **kw):
    """Check natural neighbour coordinates ``coords(p, q, gradient=grad, **kw)``
    (a function, or its result): non-negative (to ``neg_tol``), partition of unity and linear
    precision to ``tol``; with gradients, the sparsity of the values,
    sum_i grad phi_i = 0 and sum_i x_i (x) grad phi_i = identity, to
    ``grad_tol`` times (1 + L g), g a row's largest gradient entry and L the
    nodes' extent. Returns the dense values and gradients."""
    out = coords(p, q, gradient=grad, **kw) if callable(coords) else coords
    Phi, dPhi = out if grad else (out, [])
    p = p.nodes if isinstance(p, Triangulation) else np.asarray(getattr(p, "points", p))
    F, G = dense(Phi), [dense(D) for D in dPhi]
    assert Phi.shape == (q.shape[0], p.shape[0])
    assert F.min() >= -neg_tol, "coordinates must be non-negative"
    np.testing.assert_allclose(F.sum(1), 1.0, rtol=0, atol=tol)
    np.testing.assert_allclose(F @ p, q, rtol=0, atol=tol * max(1.0, np.abs(p).max()))
    if grad:
        d, L = p.shape[1], np.ptp(p, axis=0).max()
        assert len(dPhi) == d
        assert all(np.array_equal(D.indices, Phi.indices) for D in dPhi)
        atol = grad_tol * (1.0 + L * np.max([np.abs(g).max(1) for g in G], axis=0))
        for k in range(d):
            assert np.all(L * np.abs(G[k].sum(1)) <= atol), "sum of gradients"
            for j in range(d):
                err = np.abs(G[k] @ p[:, j] - float(k == j))
                assert np.all(err <= atol), (k, j, err.max())
    return F, G


def compare_2d(p, q, gtol=1e-10, lasserre=None):
    """Lasserre's recursion (``lasserre(p, q, gradient=True)``, default the
    public function's method="lasserre") against the area method in 2D: values
    to 1e-12, gradients to gtol times the largest (at least 1)."""
    if lasserre is None:
        B, dB = sibson_coordinates(p, q, gradient=True, method="lasserre")
    else:
        B, dB = lasserre(p, q, gradient=True)
    A, dA = sibson_coordinates(p, q, gradient=True)
    np.testing.assert_allclose(dense(B), dense(A), rtol=0, atol=1e-12)
    scale = max(1.0, max(np.abs(dense(D)).max() for D in dA))
    for Da, Db in zip(dA, dB):
        np.testing.assert_allclose(dense(Db), dense(Da), rtol=0, atol=gtol * scale)


def qhull_mesh(nodes):
    """The ``MeshTet`` of Qhull's tetrahedra of the (n, 3) nodes, flat ones included, as a
    user may build it (delaunay_mesh uses the package's own tetrahedralisation, which has
    no flat tetrahedra)."""
    from scipy.spatial import Delaunay
    from skfem import MeshTet
    p = np.ascontiguousarray(nodes, dtype=float)
    return MeshTet(np.ascontiguousarray(p.T), Delaunay(p).simplices.T.astype(np.int64))
