"""Quadratically consistent smoothing: linear smoothed gradients on each triangle.

Why
---
The smoothing of :mod:`skfem_nem.basis.smoothing` gives each cell a constant gradient,
exact for linear fields: enough for the linear natural-neighbour functions, but the
quadratic ones (:mod:`skfem_nem.basis.quadratic`) would then lose their extra order (a
constant gradient of a quadratic is off by O(h)). Here each triangle gets a *linear*
smoothed gradient ``g = sum_j c_j p_j`` (``p = 1, x, y``), fixed by the divergence
theorem against each ``p_j`` (the quadratically consistent 3-point integration, QC3,
of Duan, Li, Tang and Belytschko, IJNME 92, 2012)::

    sum_q w_q g(x_q) p_j(x_q) = oint_dT phi p_j n ds - sum_q w_q phi(x_q) grad p_j,

with the 3-point rule (exact for degree 2) and a 2-point Gauss-Legendre rule on each
edge (exact for the cubic ``phi p_j`` of a quadratic phi). Two properties follow:

* quadratic exactness: for a quadratic field the right side is the integral of
  ``grad u p_j`` exactly, so ``g`` is the (linear) gradient itself;
* the integration constraint of degree one: summed over the triangles, the edge
  terms of an inner edge cancel (same points, opposite normals), leaving the
  discrete divergence theorem ``sum_q w_q grad phi p = oint_dOmega phi p n -
  sum_q w_q phi grad p`` for every linear p.

Together they make the Galerkin solution reproduce quadratic fields to round-off (the
quadratic patch test) with symmetric forms, and the rates those of P2. With three
points and three polynomials the point values of g follow in closed form: the
Gram matrix is ``P^T W P`` with P the (point, polynomial) values, so
``g(x_q) = (1 / w_q) sum_j (P^-1)[j, q] r_j``.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .quadratic import lift
from .smoothing import combine

__all__ = ["EDGE_POINTS", "quadratic_cells", "smoothed_quadratic"]

# Gauss-Legendre rule on [0, 1] with 2 points: exact for cubics along an edge
_GL_X = np.array([0.5 - np.sqrt(3.0) / 6.0, 0.5 + np.sqrt(3.0) / 6.0])
_GL_W = np.array([0.5, 0.5])
#: points per triangle edge (the 2-point rule: exact for the cubic phi p of the
#: quadratic patch test; the edges are shared, so more points only add evaluations)
EDGE_POINTS = _GL_X.size


def quadratic_cells(mesh, x, w, elems):
    """The edge points of the triangles ``elems`` and the coefficients of their
    points' smoothed gradients.

    ``x`` (2, ne, 3) the triangles' 3 integration points, ``w`` (ne, 3) their weights.
    Returns ``(points, hint, sources, coef)``: the (k, 2) edge points (each edge of the
    triangles once, with a triangle holding it as ``hint``); for integration point r =
    3 e + q, ``sources[r]`` (9,) indexes the rows of the batch ``[integration points;
    points]`` its gradient combines and ``coef[r]`` (9, 2) the weights, so that
    ``grad phi(x_r) = sum_s coef[r, s] phi(batch[sources[r, s]])``.
    """
    if x.shape[2] != 3:
        raise ValueError(f"quadratic smoothing needs the 3-point rule, got {x.shape[2]} points")
    ne = elems.size
    p, t2f, facets = mesh.p, mesh.t2f[:, elems], mesh.facets
    edges, local = np.unique(t2f, return_inverse=True)
    local = local.reshape(t2f.shape)
    a, b = p[:, facets[0, edges]], p[:, facets[1, edges]]
    points = (a[:, :, None] + (b - a)[:, :, None] * _GL_X).transpose(1, 2, 0).reshape(-1, 2)
    hint = np.repeat(mesh.f2t[0, edges], EDGE_POINTS)
    centre = x.mean(axis=2)                         # the 3-point rule's mean: the centroid
    scale = np.sqrt(w.sum(axis=1))                  # sqrt of the area: p_j of order one

    def poly(y):                                    # (2, ne, k) -> (ne, k, 3)
        u = (y - centre[:, :, None]) / scale[None, :, None]
        return np.stack([np.ones_like(u[0]), u[0], u[1]], axis=-1)

    # right-hand sides r_j per source value: (ne, source, j, dim)
    rc = np.zeros((ne, 3 + 3 * EDGE_POINTS, 3, 2))
    for k in range(2):                              # - sum_q w_q phi(x_q) d_k p_j
        rc[:, :3, k + 1, k] = -w / scale[:, None]
    sources = np.empty((ne, 3 + 3 * EDGE_POINTS), np.int64)
    sources[:, :3] = 3 * np.arange(ne)[:, None] + np.arange(3)
    for le in range(3):
        f = t2f[le]
        ea, eb = p[:, facets[0, f]], p[:, facets[1, f]]
        normal = np.stack([eb[1] - ea[1], ea[0] - eb[0]])   # times the edge's length
        normal *= np.where(np.einsum("ij,ij->j", normal, 0.5 * (ea + eb) - centre) < 0,
                           -1.0, 1.0)
        ys = ea[:, :, None] + (eb - ea)[:, :, None] * _GL_X        # (2, ne, g)
        cols = 3 + le * EDGE_POINTS + np.arange(EDGE_POINTS)
        sources[:, cols] = 3 * ne + local[le][:, None] * EDGE_POINTS + np.arange(EDGE_POINTS)
        rc[:, cols] = (_GL_W[None, :, None, None] * poly(ys)[..., None]
                       * normal.T[:, None, None, :])
    Pinv = np.linalg.inv(poly(x))                   # (ne, j, q)
    coef = np.einsum("ejq,esjk->eqsk", Pinv, rc) / w[:, :, None, None]
    return (points, hint, np.repeat(sources, 3, axis=0),
            np.ascontiguousarray(coef.reshape(3 * ne, 3 + 3 * EDGE_POINTS, 2)))


def smoothed_quadratic(mesh, coordinates, x, w, elems):
    """Quadratic functions at the (2, ne, 3) points ``x`` of the triangles ``elems``
    (weights ``w``) and their smoothed gradients: ``(values CSR, gradients (2, nnz) on
    its pattern)``. ``coordinates(points, hint=...)`` gives the natural-neighbour
    coordinates (CSR) at (k, 2) points."""
    points, hint, sources, coef = quadratic_cells(mesh, x, w, elems)
    pts = x.transpose(1, 2, 0).reshape(-1, 2)
    Phi = coordinates(np.concatenate([pts, points]),
                      hint=np.concatenate([np.repeat(elems, 3), hint]))
    Q, _ = lift(mesh, Phi)
    ptr, idx, val, grad = combine(Q, Q, np.arange(pts.shape[0]), sources, coef)
    return sp.csr_matrix((val, idx, ptr), shape=(pts.shape[0], Q.shape[1])), grad
