"""Walls in a tetrahedralisation: faces that natural neighbours do not see through.

Why
---
Sibson functions are smooth across every face, so on a plain tetrahedralisation a field
cannot kink at a material interface: a stiff sphere drags a layer of fluid about one node
spacing thick along (the settling sphere ran 25-30% slow at the spacings measured). In
2D the constrained natural element method (Yvonnet, Ryckelynck, Lorong & Chinesta 2004)
stops a point's conflict region at the interface's segments
(:mod:`~skfem_nem.geometry.constrained`). This is its 3D counterpart for interfaces whose
triangles already are faces of the Delaunay tetrahedralisation (a surface sampled more
finely than the nodes beside it: every triangle whose smallest sphere holds no other node
is a Delaunay face); a surface that is not is refused, naming its first missing triangle,
rather than recovered with extra nodes.

How
---
A wall is marked in the neighbour array the coordinate kernels read: the entry across a
wall face from tetrahedron s to t is ``WALL - t`` (``-2 - t``), below the hull's -1. A
conflict region stops there, as at the hull, but walks step across (:func:`through`), so
that a point is located wherever it is. Watson's signed decomposition over a conflict
region cut at walls keeps its partition of unity and linear precision exactly (each
tetrahedron's terms satisfy both on their own), and on a wall face its limit from either
side is the face's barycentric coordinates: the functions are continuous across the wall,
linear on it, and kink there. Not cut: the rule on the hull (a point on a hull facet takes
the weights of the facet's plane, which see across the edge where a wall meets the hull;
docs/stokes_3d.md measures it).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .entities import MAX_KEYED_NODES

__all__ = ["WALL", "through", "check_faces", "face_keys", "wall_slots", "walled",
           "MissingFace"]

#: neighbour entries at or below this mark a wall: ``WALL - t`` for the tetrahedron t beyond
WALL = -2

# the face opposite slot k of a tetrahedron, in its vertex slots
_FACES = np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]])


class MissingFace(ValueError):
    """A wall triangle that is no face of the tetrahedralisation: ``name`` and ``index``
    locate it in the given faces, ``nodes`` are its three node indices."""

    def __init__(self, message, name, index, nodes):
        super().__init__(message)
        self.name, self.index, self.nodes = name, index, nodes


@njit(cache=True, inline="always")
def through(nb):
    """The tetrahedron across a face for a walk (a wall is crossed; -1 on the hull)."""
    return WALL - nb if nb <= WALL else nb


def face_keys(tri_nodes: np.ndarray, n: int) -> np.ndarray:
    """One int64 key per triangle of (..., 3) node indices below n, whatever their order;
    ``ValueError`` past :data:`~.entities.MAX_KEYED_NODES` nodes, where keys would
    overflow."""
    if n > MAX_KEYED_NODES:
        raise ValueError(f"walls need at most {MAX_KEYED_NODES:,} nodes (their triangles' "
                         f"int64 keys), got {n:,}")
    s = np.sort(np.asarray(tri_nodes), axis=-1).astype(np.int64)
    return (s[..., 0] * n + s[..., 1]) * n + s[..., 2]


def check_faces(faces, n: int, name: str = "faces") -> np.ndarray:
    """``faces`` as a (k, 3) int64 array of distinct node indices below n; ``ValueError``
    naming the input otherwise."""
    f = np.asarray(faces)
    if f.size == 0:
        return np.zeros((0, 3), np.int64)
    if f.ndim != 2 or f.shape[1] != 3 or not np.issubdtype(f.dtype, np.integer):
        raise ValueError(f"{name} must be an integer array of node triples, shape (k, 3), "
                         f"got shape {f.shape} of {f.dtype}")
    bad = np.flatnonzero(((f < 0) | (f >= n)).any(axis=1))
    if bad.size:
        raise ValueError(f"{name}[{bad[0]}] = {f[bad[0]].tolist()} names a node outside "
                         f"0..{n - 1}")
    s = np.sort(f, axis=1)
    bad = np.flatnonzero((s[:, 0] == s[:, 1]) | (s[:, 1] == s[:, 2]))
    if bad.size:
        raise ValueError(f"{name}[{bad[0]}] = {f[bad[0]].tolist()} repeats a node")
    return f.astype(np.int64)


def wall_slots(simplices: np.ndarray, n: int, faces: dict) -> np.ndarray:
    """(m, 4) True where the face opposite a vertex slot is one of ``faces`` (name -> (k, 3)
    checked node triples); :class:`MissingFace` for the first triangle that is no face of
    the tetrahedra."""
    T = np.asarray(simplices, dtype=np.int64)
    K = face_keys(T[:, _FACES], n)                              # (m, 4)
    order = np.argsort(K, axis=None)
    flat = K.ravel()[order]
    slots = np.zeros(T.shape, dtype=bool)
    for name, f in faces.items():
        want = face_keys(f, n)
        at = np.minimum(np.searchsorted(flat, want), flat.size - 1)
        found = flat[at] == want
        if not found.all():
            i = int(np.flatnonzero(~found)[0])
            raise MissingFace(
                f"{name}[{i}] = {f[i].tolist()} is not a face of the Delaunay tetrahedra: "
                f"a node lies in the smallest sphere through its three nodes (sample the "
                f"surface more finely than the nodes beside it, or keep those nodes further "
                f"from it)", name, i, f[i])
        hit = np.isin(K, want)
        slots |= hit
    return slots


def walled(neighbors: np.ndarray, slots: np.ndarray) -> np.ndarray:
    """A copy of ``neighbors`` (m, 4) with ``WALL - t`` across the wall faces ``slots``."""
    NB = np.array(neighbors, dtype=np.int64)
    NB[slots] = WALL - NB[slots]
    return NB
