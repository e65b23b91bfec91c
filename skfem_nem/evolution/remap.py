"""Remap of integration-point fields when Lawson flips replace two triangles by two others.

The rules (see :mod:`skfem_nem.evolution.lagrangian` and docs/evolution.md) work on batches
of flips as logged by the Lawson kernel, rows ``(t, u, k, l, a, b, c, d)``: triangle
t = (a, b, c) (a at position k) was flipped across b-c with u = (d, c, b) (d at position
l); afterwards t holds ``(a, b, d)`` and u ``(a, d, c)``. Also the values of children of
a split triangle from the parent's linear field.
"""
from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["remap_average", "remap_conservative", "vertex_values", "barycentric",
           "child_values"]


@njit(cache=True)
def remap_average(log, F):
    """The paper's averaging-and-splitting rule for a batch of flips."""
    for r in range(log.shape[0]):
        t, u, k, l = log[r, 0], log[r, 1], log[r, 2], log[r, 3]
        ta = F[t, k].copy()
        tb = F[t, (k + 1) % 3].copy()
        tc = F[t, (k + 2) % 3].copy()
        ud = F[u, l].copy()
        uc = F[u, (l + 1) % 3].copy()
        ub = F[u, (l + 2) % 3].copy()
        # new t = (a, b, d), new u = (a, d, c)
        F[t, 0] = ta
        F[t, 1] = 0.5 * (tb + ub)
        F[t, 2] = ud
        F[u, 0] = ta
        F[u, 1] = ud
        F[u, 2] = 0.5 * (tc + uc)


@njit(cache=True)
def vertex_values(f):
    """Vertex values of the linear field with values f at the 3-point rule's points."""
    s = f[0] + f[1] + f[2]
    return 2.0 * f[0] - s / 3.0, 2.0 * f[1] - s / 3.0, 2.0 * f[2] - s / 3.0


@njit(cache=True)
def barycentric(px, py, ax, ay, bx, by, cx, cy):
    d = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
    l1 = ((px - ax) * (cy - ay) - (py - ay) * (cx - ax)) / d
    l2 = ((bx - ax) * (py - ay) - (by - ay) * (px - ax)) / d
    return 1.0 - l1 - l2, l1, l2


@njit(cache=True)
def remap_conservative(P, log, F):
    """L2-projection remap over the four sub-triangles, for a batch of flips.

    Log rows ``(t, u, k, l, a, b, c, d)`` as written by the Lawson kernel.
    """
    ncomp = F.shape[2]
    for r in range(log.shape[0]):
        t, u = log[r, 0], log[r, 1]
        a = log[r, 4]
        b = log[r, 5]
        c = log[r, 6]
        d = log[r, 7]
        k, l = log[r, 2], log[r, 3]
        ax, ay = P[a, 0], P[a, 1]
        bx, by = P[b, 0], P[b, 1]
        cx, cy = P[c, 0], P[c, 1]
        dx, dy = P[d, 0], P[d, 1]
        # intersection O of the diagonals a-d and b-c
        den = (dx - ax) * (cy - by) - (dy - ay) * (cx - bx)
        s = ((bx - ax) * (cy - by) - (by - ay) * (cx - bx)) / den
        ox = ax + s * (dx - ax)
        oy = ay + s * (dy - ay)
        for m in range(ncomp):
            # old vertex values: t = (a, b, c) from position k, u = (d, c, b) from l
            fa, fb, fc = vertex_values(np.array([F[t, k, m], F[t, (k + 1) % 3, m],
                                                  F[t, (k + 2) % 3, m]]))
            gd, gc, gb = vertex_values(np.array([F[u, l, m], F[u, (l + 1) % 3, m],
                                                  F[u, (l + 2) % 3, m]]))
            # old field at O, from either side (they differ: the field jumps)
            la, lb, lc = barycentric(ox, oy, ax, ay, bx, by, cx, cy)
            fo_t = la * fa + lb * fb + lc * fc
            ld, lc2, lb2 = barycentric(ox, oy, dx, dy, cx, cy, bx, by)
            fo_u = ld * gd + lc2 * gc + lb2 * gb
            # new t = (a, b, d) covers sub-triangles (a, b, O) [old t] and (b, d, O) [old u]
            # new u = (a, d, c) covers (d, c, O) [old u] and (c, a, O) [old t]
            for which in range(2):
                if which == 0:
                    v0x, v0y, v1x, v1y, v2x, v2y = ax, ay, bx, by, dx, dy
                    subs = ((ax, ay, fa, bx, by, fb, fo_t),
                            (bx, by, gb, dx, dy, gd, fo_u))
                else:
                    v0x, v0y, v1x, v1y, v2x, v2y = ax, ay, dx, dy, cx, cy
                    subs = ((dx, dy, gd, cx, cy, gc, fo_u),
                            (cx, cy, fc, ax, ay, fa, fo_t))
                area = 0.5 * ((v1x - v0x) * (v2y - v0y) - (v1y - v0y) * (v2x - v0x))
                rhs = np.zeros(3)
                for (p1x, p1y, f1, p2x, p2y, f2, fo) in subs:
                    sa = 0.5 * abs((p2x - p1x) * (oy - p1y) - (p2y - p1y) * (ox - p1x))
                    # int over the sub-triangle (p1, p2, O) of f * lambda_j:
                    # (|S| / 12) (sum_i f_i lam_ji + (sum_i f_i)(sum_i lam_ji))
                    l1 = barycentric(p1x, p1y, v0x, v0y, v1x, v1y, v2x, v2y)
                    l2 = barycentric(p2x, p2y, v0x, v0y, v1x, v1y, v2x, v2y)
                    l3 = barycentric(ox, oy, v0x, v0y, v1x, v1y, v2x, v2y)
                    fs = f1 + f2 + fo
                    for j in range(3):
                        lj = l1[j] * f1 + l2[j] * f2 + l3[j] * fo
                        rhs[j] += sa / 12.0 * (lj + fs * (l1[j] + l2[j] + l3[j]))
                # P1 mass matrix (|T| / 12)(I + 1 1^T): inverse (12/|T|)(I - 1 1^T / 4)
                tot = rhs[0] + rhs[1] + rhs[2]
                nv = np.empty(3)
                for j in range(3):
                    nv[j] = 12.0 / area * (rhs[j] - tot / 4.0)
                s3 = nv[0] + nv[1] + nv[2]
                tgt = t if which == 0 else u
                for j in range(3):
                    F[tgt, j, m] = 0.5 * nv[j] + s3 / 6.0


def child_values(X, Ft, Y):
    """Values at the 3-point rule's points of the children ``Y`` (c, 3, 2) (vertex
    coordinates) of a parent triangle with vertices ``X`` (3, 2), from the parent's
    linear field (its values ``Ft`` (3, m) at the parent's own points). Conserves
    integrals when the children tile the parent."""
    Fv = 2.0 * Ft - Ft.sum(axis=0) / 3.0  # values at the parent's vertices
    M = np.vstack([X.T, np.ones(3)])
    A3 = np.array([[2 / 3, 1 / 6, 1 / 6], [1 / 6, 2 / 3, 1 / 6], [1 / 6, 1 / 6, 2 / 3]])
    pts = np.einsum("kj,cjd->ckd", A3, Y).reshape(-1, 2)
    lam = np.linalg.solve(M, np.vstack([pts.T, np.ones(pts.shape[0])]))  # (3, c*3)
    return (lam.T @ Fv).reshape(Y.shape[0], 3, Ft.shape[1])
