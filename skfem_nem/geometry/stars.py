"""Removing a vertex from a triangulation: the polygon its triangles leave, refilled.

When the evolving mesh takes a node out for good (where the flow crowds nodes together,
:mod:`skfem_nem.evolution.merging`), the triangles around it (its star) leave a polygon,
its link, which is refilled with the constrained-Delaunay triangles of the link alone by
ear clipping with the exact in-circle test (each ear's circumcircle holds no other link
vertex: the Delaunay triangulation of a star-shaped polygon). The star of an interior
node is closed; a node on a straight stretch of the hull (a wall node between two
nodes of the same wall, exactly collinear) has an open fan of triangles, whose link is
closed by the hull edge that replaces the node. The functions here work on the arrays of
a :class:`~skfem_nem.geometry.triangulation.Triangulation` (``triangles``,
``neighbours``, ``nodes``; see its conventions), which calls them.
"""
from __future__ import annotations

import numpy as np

from .predicates import incircle_sign, orient2d

__all__ = ["delaunay_ears", "link_star", "delete_rows", "fan_of", "star_of"]


def star_of(T: np.ndarray, N: np.ndarray, v: int, t0: int):
    """Walk counter-clockwise around node v from its triangle t0. Returns ``(star,
    closed)``: the triangles met, in order, and whether the walk came back to t0
    (False: it stopped at the hull)."""
    star, t = [], t0
    while True:
        star.append(t)
        j = int(np.flatnonzero(T[t] == v)[0])
        t = int(N[t, (j + 1) % 3])
        if t < 0:
            return np.array(star, dtype=np.int64), False
        if t == t0:
            return np.array(star, dtype=np.int64), True


def fan_of(T: np.ndarray, N: np.ndarray, v: int, t0: int) -> np.ndarray:
    """The triangles around the hull node v counter-clockwise, from the one on the
    hull edge before v to the one on the hull edge after it."""
    t = t0
    while True:
        j = int(np.flatnonzero(T[t] == v)[0])
        prev = int(N[t, (j + 2) % 3])
        if prev < 0:
            return star_of(T, N, v, t)[0]
        t = prev


def delaunay_ears(P: np.ndarray, link, v: int):
    """Delaunay triangles (vertex triples) filling the counter-clockwise polygon
    ``link`` (node indices) left by node v; ``RuntimeError`` naming v if no ear is
    found (the polygon is not star-shaped)."""
    poly, new = list(range(len(link))), []
    while len(poly) > 3:
        for idx in range(len(poly)):
            i0, i1, i2 = poly[idx - 1], poly[idx], poly[(idx + 1) % len(poly)]
            p, q, r = link[i0], link[i1], link[i2]
            if orient2d(*P[p], *P[q], *P[r]) <= 0:
                continue
            if any(incircle_sign(*P[p], *P[q], *P[r], *P[link[s]]) > 0
                   for s in poly if s not in (i0, i1, i2)):
                continue
            new.append((p, q, r))
            poly.pop(idx)
            break
        else:
            raise RuntimeError(f"no Delaunay ear in the star of node {v}")
    new.append(tuple(link[i] for i in poly))
    return new


def link_star(T: np.ndarray, N: np.ndarray, slots, link, outer) -> None:
    """Set the neighbours of the triangles ``slots`` that refill a polygon whose edge
    ``(link[i], link[i + 1])`` has the outer neighbour ``outer[i]`` (-1: the hull)."""
    m = len(link)
    polyedge = {(link[i], link[(i + 1) % m]): outer[i] for i in range(m)}
    diag = {}
    for s_ in slots:
        for k in range(3):
            e1, e2 = int(T[s_, (k + 1) % 3]), int(T[s_, (k + 2) % 3])
            if (e1, e2) in polyedge:
                nb = polyedge[(e1, e2)]
                N[s_, k] = nb
                if nb >= 0:
                    N[nb, (T[nb] != e1) & (T[nb] != e2)] = s_
            elif (min(e1, e2), max(e1, e2)) in diag:
                o, ko = diag[(min(e1, e2), max(e1, e2))]
                N[s_, k], N[o, ko] = o, s_
            else:
                diag[(min(e1, e2), max(e1, e2))] = (s_, k)


def delete_rows(T: np.ndarray, N: np.ndarray, dead):
    """Remove the triangle rows ``dead`` (descending), moving the last rows in.
    Returns the cut arrays and the moves ``(src, dst)`` made, in order."""
    nt, moves = T.shape[0], []
    for d in dead:
        last = nt - 1
        if d != last:
            T[d], N[d] = T[last], N[last]
            for nb in N[d]:
                if nb >= 0:
                    N[nb][N[nb] == last] = d
            moves.append((last, d))
        nt -= 1
    return np.ascontiguousarray(T[:nt]), np.ascontiguousarray(N[:nt]), moves
