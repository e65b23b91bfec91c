"""Mesh quality kernels of the evolving mesh: smallest angles, inverted triangles, and the
2D cross product, shared by the mesh, its injection and its removal of nodes."""
from __future__ import annotations

import numpy as np
from numba import njit

from ..geometry.predicates import orient2d

__all__ = ["min_angles", "inverted", "cross", "area_shares"]


@njit(cache=True)
def min_angles(P, T, out):
    """out[t]: the smallest angle (radians) of triangle t of the nodes P."""
    for t in range(T.shape[0]):
        best = np.pi
        for k in range(3):
            a = T[t, k]
            b = T[t, (k + 1) % 3]
            c = T[t, (k + 2) % 3]
            ux = P[b, 0] - P[a, 0]
            uy = P[b, 1] - P[a, 1]
            vx = P[c, 0] - P[a, 0]
            vy = P[c, 1] - P[a, 1]
            ang = np.arctan2(abs(ux * vy - uy * vx), ux * vx + uy * vy)
            best = min(best, ang)
        out[t] = best


@njit(cache=True)
def inverted(P, T):
    """Number of triangles of T (nodes P) that are not counter-clockwise (exact)."""
    n = 0
    for t in range(T.shape[0]):
        a = T[t, 0]
        b = T[t, 1]
        c = T[t, 2]
        if orient2d(P[a, 0], P[a, 1], P[b, 0], P[b, 1], P[c, 0], P[c, 1]) <= 0.0:
            n += 1
    return n


def cross(u, v):
    """z-component of the cross products of the 2D vectors u and v (broadcast)."""
    return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]


def area_shares(P, T) -> np.ndarray:
    """(n,) each node's share (a third) of the areas of its triangles T (nt, 3) of the
    nodes P (n, 2): the local measure of density that node removal and the time step use
    (its square root is the node's spacing)."""
    area = 0.5 * np.abs(cross(P[T[:, 1]] - P[T[:, 0]], P[T[:, 2]] - P[T[:, 0]]))
    share = np.zeros(P.shape[0])
    np.add.at(share, T.ravel(), np.repeat(area / 3.0, 3))
    return share
