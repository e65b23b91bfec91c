"""Points on the boundary of a non-convex 2D domain that round-off put outside it.

On a non-convex mesh (or one whose boundary nodes are not exactly on its hull: the midpoints
of a refined circle's chords, a mapped tensor mesh whose straight side is straight only to
round-off) the coordinates come from a constrained triangulation whose triangles outside the
domain are void. A point computed on a boundary facet (a facet quadrature point, a point of a
smoothing cell's edge, a node of a refined plotting mesh) may then land a few ulps outside
the facet, in a void sliver, and the coordinates would call it outside the domain.

:func:`into_domain` moves such points, within the hull policy's round-off
(``geometry.hull.OUTSIDE_ROUNDOFF``, relative to the diagonal of the nodes' bounding box) of
a boundary facet, onto the facet and :data:`NUDGE` inside, towards
the centroid of the facet's triangle: the values change by about ``NUDGE`` times the
diagonal times the gradient. Points farther out are left alone and reported.
"""
from __future__ import annotations

import numpy as np

from ..geometry.hull import OUTSIDE_ROUNDOFF
from ..geometry.meshes import outside_domain

__all__ = ["into_domain", "check_used_nodes", "NUDGE"]

#: how far inside (relative to the diagonal) a point outside by round-off is put
NUDGE = 1e-12
#: point-segment pairs measured at once
_CHUNK = 1 << 22


def _nearest_facets(mesh, x, facets):
    """For each point of x (m, 2): the nearest of ``facets``, its distance and the foot."""
    a = mesh.p[:, mesh.facets[0, facets]].T           # (nf, 2)
    d = mesh.p[:, mesh.facets[1, facets]].T - a
    dd = np.maximum((d ** 2).sum(axis=1), np.finfo(float).tiny)
    m = x.shape[0]
    best = np.empty(m, dtype=np.int64)
    dist = np.empty(m)
    foot = np.empty((m, 2))
    step = max(1, _CHUNK // max(1, facets.size))
    for s in range(0, m, step):
        xs = x[s:s + step]
        t = np.clip((((xs[:, None, :] - a[None]) * d[None]).sum(axis=2)) / dd, 0.0, 1.0)
        f = a[None] + t[..., None] * d[None]                # (k, nf, 2)
        r = np.hypot(*(xs[:, None, :] - f).transpose(2, 0, 1))
        j = r.argmin(axis=1)
        k = np.arange(xs.shape[0])
        best[s:s + step], dist[s:s + step], foot[s:s + step] = j, r[k, j], f[k, j]
    return best, dist, foot


def into_domain(mesh, x):
    """``(x', far)``: the (m, 2) points x, those outside the domain of the 2D ``mesh`` by
    round-off (within ``OUTSIDE_ROUNDOFF`` of a boundary facet) moved just inside; ``far`` holds the
    indices of the points outside by more (in a hole or a notch). x is not modified."""
    x = np.asarray(x, dtype=np.float64)
    out = outside_domain(mesh, x)
    if not out.size:
        return x, out
    bf = mesh.boundary_facets()
    diag = float(np.hypot(*np.ptp(mesh.p, axis=1)))
    j, dist, foot = _nearest_facets(mesh, x[out], bf)
    near = dist <= OUTSIDE_ROUNDOFF * diag
    tri = mesh.f2t[0, bf[j[near]]]
    c = mesh.p[:, mesh.t[:, tri]].mean(axis=1).T       # centroids of the facets' triangles
    step = c - foot[near]
    step /= np.hypot(*step.T)[:, None]
    x = x.copy()
    x[out[near]] = foot[near] + NUDGE * diag * step
    return x, out[~near]


def check_used_nodes(mesh, who):
    """Raise if a node of ``mesh`` belongs to no cell: no natural-neighbour function could
    be defined there (a mixed mesh's triangle part keeps the other cells' nodes)."""
    used = np.zeros(mesh.p.shape[1], dtype=bool)
    used[mesh.t.ravel()] = True
    if not used.all():
        bad = np.flatnonzero(~used)
        cell = "triangle" if mesh.dim() == 2 else "tetrahedron"
        raise ValueError(
            f"{who}: mesh node {int(bad[0])} at {mesh.p[:, bad[0]].tolist()} belongs to no "
            f"{cell} ({bad.size} such node(s)), so no natural-neighbour function is defined "
            f"there; drop them with mesh.remove_unused_nodes() (the domain stays the same, "
            f"the nodes are renumbered)")
