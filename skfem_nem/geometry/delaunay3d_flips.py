"""Bistellar flips that make a valid 3D tetrahedralisation Delaunay again.

Why flips: after a small Lagrangian step about one face in a hundred fails the empty-sphere
test, and a flip mends it by replacing two or three tetrahedra, where removing and
re-inserting a node rebuilds its whole star. A face failing between finite tetrahedra
``t = (a, b, c, d)`` and ``u = (a, b, c, e)`` is flipped

* **2-3** when the segment ``d e`` crosses the triangle ``a b c``: ``t`` and ``u`` become the
  three tetrahedra around the new edge ``d e``;
* **3-2** when ``d e`` passes beside the edge ``a b`` and exactly three tetrahedra
  ``t, u, (a, b, d, e)`` surround that edge: they become the two on the triangle ``c d e``.

Each flip replaces the upper by the lower faces of the five points lifted to the paraboloid,
so flipping ends. It can stop at a failing face that neither flip mends (more than three
tetrahedra around the edge, four coplanar points, or a face on the hull); the caller
(:mod:`.delaunay3d_repair`) then relocates the nodes of that face. Every decision is an exact
orientation (:mod:`.predicates3d`); a zero is never flipped through, so no flat tetrahedron
is made.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .delaunay3d_build import conflict, o3

__all__ = ["flip_to_delaunay", "glue", "face_fails", "internal", "push", "take_rows",
           "release_rows"]

_FLIPPED, _STUCK = 0, 1
_FLIP_BUDGET = 4  # flips per tet before the flips are taken to cycle (each is finite)


@njit(cache=True, inline="always")
def _apex_slot(N, t, i):
    """The slot, in the neighbour across face i of tet t, of the vertex not on that face."""
    u = N[t, i]
    for j in range(4):
        if N[u, j] == t:
            return j
    return -1


@njit(cache=True)
def face_fails(P, G, T, N, t, i):
    """Whether the face of tet t opposite slot i fails: not locally Delaunay, or (for a
    ghost) the hull is not convex there, or the finite tet under a hull face is inverted."""
    u = N[t, i]
    a = T[u, _apex_slot(N, t, i)]
    if a == G:  # seen from the ghost: t's own vertex against the hull face
        return conflict(P, G, T, N, u, T[t, i])
    return conflict(P, G, T, N, t, a)


@njit(cache=True)
def glue(T, N, tets, nbrs, faces, inner, outer, slots):
    """Write the tets ``tets`` (k, 4) into rows ``slots`` in place of a cavity: ``nbrs``
    their neighbours among themselves (-1 on the cavity's boundary), ``faces`` (f, 3) the
    sorted boundary triples with the cavity tet ``inner`` and the outside tet ``outer``
    across each. Returns False, and changes nothing, when the boundaries do not match."""
    nf = faces.shape[0]
    across = np.full((tets.shape[0], 4), -1, np.int64)
    used = np.zeros(nf, np.bool_)
    f = np.empty(3, np.int64)
    for k in range(tets.shape[0]):
        for i in range(4):
            if nbrs[k, i] >= 0:
                continue
            m = 0
            for j in range(4):
                if j != i:
                    f[m] = tets[k, j]
                    m += 1
            f.sort()
            for h in range(nf):
                if not used[h] and faces[h, 0] == f[0] and faces[h, 1] == f[1] \
                        and faces[h, 2] == f[2]:
                    used[h] = True
                    across[k, i] = h
                    break
            if across[k, i] < 0:
                return False
    if not used.all():
        return False
    oslot = np.empty(nf, np.int64)  # found before any row changes: cavity rows are reused
    for h in range(nf):
        for jj in range(4):
            if N[outer[h], jj] == inner[h]:
                oslot[h] = jj
    for k in range(tets.shape[0]):
        t = slots[k]
        for j in range(4):
            T[t, j] = tets[k, j]
            if nbrs[k, j] >= 0:
                N[t, j] = slots[nbrs[k, j]]
            else:
                h = across[k, j]
                N[t, j] = outer[h]
                N[outer[h], oslot[h]] = t
    return True


@njit(cache=True)
def internal(tets):
    """Neighbours of each new tet among the new tets (-1 where none shares the face)."""
    k = tets.shape[0]
    nbrs = np.full((k, 4), -1, np.int32)
    for p in range(k):
        for i in range(4):
            for q in range(k):
                if q == p:
                    continue
                shared = 0
                for j in range(4):
                    if j != i:
                        for jj in range(4):
                            if tets[q, jj] == tets[p, j]:
                                shared += 1
                if shared == 3:
                    nbrs[p, i] = q
    return nbrs


@njit(cache=True, inline="always")
def _member(x, rows):
    for r in rows:
        if r == x:
            return True
    return False


@njit(cache=True)
def _replace(T, N, old, tets, free, nfree, ntet):
    """Replace the tets of rows ``old`` by ``tets`` (same region): rows reused, then free
    rows, then new rows (:func:`take_rows`). Returns ``nfree, ntet`` and the rows of the new
    tets (none if the boundaries did not match, and nothing changed)."""
    nold = old.shape[0]
    faces = np.empty((4 * nold, 3), np.int64)
    inner = np.empty(4 * nold, np.int32)
    outer = np.empty(4 * nold, np.int32)
    nf = 0
    for s in old:
        for j in range(4):
            o = N[s, j]
            if _member(o, old):
                continue
            m = 0
            for jj in range(4):
                if jj != j:
                    faces[nf, m] = T[s, jj]
                    m += 1
            faces[nf].sort()
            inner[nf] = s
            outer[nf] = o
            nf += 1
    slots, nfree1, ntet1 = take_rows(old, tets.shape[0], free, nfree, ntet)
    if not glue(T, N, tets, internal(tets), faces[:nf], inner[:nf], outer[:nf], slots):
        return nfree, ntet, slots[:0]          # never seen: the flip is left undone
    return release_rows(T, old, tets.shape[0], free, nfree1), ntet1, slots


@njit(cache=True)
def take_rows(old, count, free, nfree, ntet):
    """Rows for ``count`` new tets replacing the tets of rows ``old``: those rows first,
    then free rows, then new rows at the end. Returns the rows and ``nfree, ntet``."""
    slots = np.empty(count, np.int32)
    for k in range(count):
        if k < old.shape[0]:
            slots[k] = old[k]
        elif nfree > 0:
            nfree -= 1
            slots[k] = free[nfree]
        else:
            slots[k] = ntet
            ntet += 1
    return slots, nfree, ntet


@njit(cache=True)
def release_rows(T, old, count, free, nfree):
    """Free the rows of ``old`` beyond the first ``count`` (reused); returns ``nfree``."""
    for k in range(count, old.shape[0]):
        T[old[k], 0] = -1
        free[nfree] = old[k]
        nfree += 1
    return nfree


@njit(cache=True, inline="always")
def _positive(P, tet):
    """Swap the first two vertices of tet (4,) if negatively oriented; False if flat."""
    o = o3(P, tet[0], tet[1], tet[2], tet[3])
    if o < 0.0:
        tet[0], tet[1] = tet[1], tet[0]
    return o != 0.0


@njit(cache=True)
def _flip(P, G, T, N, t, i, free, nfree, ntet):
    """Flip the failing face of finite tet t opposite slot i, if a 2-3 or 3-2 flip can.
    Returns a status, ``nfree, ntet`` and the rows of the new tets."""
    none = np.empty(0, np.int32)
    u = N[t, i]
    if T[t, 3] == G and T[u, 3] == G:
        return _flip_hull(P, G, T, N, t, i, free, nfree, ntet)
    if T[t, 3] == G or T[u, 3] == G:
        return _STUCK, nfree, ntet, none
    d, e = T[t, i], T[u, _apex_slot(N, t, i)]
    f = np.empty(3, np.int64)  # a, b, c with (a, b, c, d) positive
    m = 0
    for j in range(4):
        if j != i:
            f[m] = T[t, j]
            m += 1
    if i == 0 or i == 2:
        f[0], f[1] = f[1], f[0]
    s = np.empty(3)
    for k in range(3):
        s[k] = o3(P, f[k], f[(k + 1) % 3], e, d)
    if s[0] > 0.0 and s[1] > 0.0 and s[2] > 0.0:  # 2-3
        tets = np.empty((3, 4), np.int32)  # int32 as T: glue, internal compile once
        for k in range(3):
            tets[k, 0], tets[k, 1], tets[k, 2], tets[k, 3] = f[k], f[(k + 1) % 3], e, d
        nfree, ntet, rows = _replace(T, N, np.array([t, u], np.int32), tets, free, nfree, ntet)
        return _FLIPPED, nfree, ntet, rows
    neg = -1
    for k in range(3):
        if s[k] < 0.0 and s[(k + 1) % 3] > 0.0 and s[(k + 2) % 3] > 0.0:
            neg = k
    if neg < 0:
        return _STUCK, nfree, ntet, none
    x, y, z = f[neg], f[(neg + 1) % 3], f[(neg + 2) % 3]
    w = -1  # the third tet around edge x y: across t's face (x, y, d), holding e
    for j in range(4):
        if T[t, j] == z:
            w = N[t, j]
    if T[w, 3] == G or T[w, _apex_slot(N, t, _slot(T, t, z))] != e \
            or N[u, _slot(T, u, z)] != w:
        return _STUCK, nfree, ntet, none
    tets = np.empty((2, 4), np.int32)
    tets[0, 0], tets[0, 1], tets[0, 2], tets[0, 3] = z, d, e, x
    tets[1, 0], tets[1, 1], tets[1, 2], tets[1, 3] = z, d, e, y
    if o3(P, z, d, e, x) * o3(P, z, d, e, y) >= 0.0:  # x y must pierce z d e
        return _STUCK, nfree, ntet, none
    _positive(P, tets[0])
    _positive(P, tets[1])
    nfree, ntet, rows = _replace(T, N, np.array([t, u, w], np.int32), tets, free, nfree, ntet)
    return _FLIPPED, nfree, ntet, rows


@njit(cache=True, inline="always")
def _ghost_over(P, G, p, q, r, s, row):
    """Write the ghost on the hull face (p, q, r) whose inner side holds point s."""
    if o3(P, p, q, r, s) > 0.0:
        p, q = q, p
    row[0], row[1], row[2], row[3] = p, q, r, G


@njit(cache=True)
def _flip_hull(P, G, T, N, t, i, free, nfree, ntet):
    """Mend a failing hull edge between the ghosts ``t`` = (a, b, c) and ``u`` = (a, c, d)
    with a b c d coplanar (nodes sliding along a flat wall): the 4-4 flip swaps the edge
    a c for b d, in the hull and in the two tets beneath it, which must share their apex x.
    A hull that bends at the edge (nodes leaving a wall) is left to the caller's
    relocation. Returns as :func:`_flip`."""
    none = np.empty(0, np.int32)
    u = N[t, i]
    b, d = T[t, i], T[u, _apex_slot(N, t, i)]
    a, c = -1, -1
    for j in range(3):
        if j != i:
            if a < 0:
                a = T[t, j]
            else:
                c = T[t, j]
    if o3(P, T[t, 0], T[t, 1], T[t, 2], d) != 0.0:  # the hull bends there
        return _STUCK, nfree, ntet, none
    t1, u1 = N[t, 3], N[u, 3]
    x = T[t1, _apex_slot(N, t, 3)]
    if T[u1, _apex_slot(N, u, 3)] != x or N[t1, _slot(T, t1, b)] != u1:
        return _STUCK, nfree, ntet, none
    if o3(P, b, d, x, a) * o3(P, b, d, x, c) >= 0.0:  # the quadrilateral a b c d convex
        return _STUCK, nfree, ntet, none
    tets = np.empty((4, 4), np.int32)
    tets[0, 0], tets[0, 1], tets[0, 2], tets[0, 3] = a, b, d, x
    tets[1, 0], tets[1, 1], tets[1, 2], tets[1, 3] = c, b, d, x
    if not (_positive(P, tets[0]) and _positive(P, tets[1])):
        return _STUCK, nfree, ntet, none
    _ghost_over(P, G, a, b, d, x, tets[2])
    _ghost_over(P, G, c, b, d, x, tets[3])
    nfree, ntet, rows = _replace(T, N, np.array([t, u, t1, u1], np.int32), tets, free, nfree,
                                 ntet)
    return _FLIPPED, nfree, ntet, rows


@njit(cache=True, inline="always")
def _slot(T, t, v):
    for j in range(4):
        if T[t, j] == v:
            return j
    return -1


@njit(cache=True)
def push(stack, n, t):
    if n == stack.shape[0]:
        grown = np.empty(2 * n + 16, np.int32)
        grown[:n] = stack
        stack = grown
    stack[n] = t
    return stack, n + 1


@njit(cache=True)
def flip_to_delaunay(P, G, T, N, ntet, free, nfree, stack, v2t):
    """Flip the failing faces of the tets on ``stack`` (and of the tets the flips make)
    until none fails or none that fails can be flipped. Returns the (grown) ``T, N, free``,
    ``nfree, ntet``, the number of flips and the tets with a failing face left; ``v2t`` (a
    tet at each vertex) is kept up to date."""
    flips = 0
    stuck = np.empty(16, np.int32)
    nstuck = np.int64(0)  # not a literal 0: one specialization of push
    nstack = stack.shape[0]
    budget = _FLIP_BUDGET * ntet + 1000
    while nstack > 0:
        if flips > budget:  # a cycle (never seen): the caller's relocation takes over
            for k in range(nstack):
                stuck, nstuck = push(stuck, nstuck, stack[k])
            break
        nstack -= 1
        t = stack[nstack]
        if T[t, 0] < 0:
            continue
        if ntet + 1 >= T.shape[0]:  # a 2-3 flip may take one new row
            T, N, free = _grow(T, np.int64(-1)), _grow(N, np.int64(-1)), _grow(free, np.int64(0))
        for i in range(4):
            if not face_fails(P, G, T, N, t, i):
                continue
            status, nfree, ntet, rows = _flip(P, G, T, N, t, i, free, nfree, ntet)
            if status == _FLIPPED and rows.shape[0] > 0:
                flips += 1
                for r in rows:
                    stack, nstack = push(stack, nstack, r)
                    for j in range(4):
                        v2t[T[r, j]] = r
                break
            stuck, nstuck = push(stuck, nstuck, t)
    left = np.empty(nstuck, np.int32)
    nleft = 0
    for k in range(nstuck):
        t = stuck[k]
        if T[t, 0] >= 0:
            for i in range(4):
                if face_fails(P, G, T, N, t, i):
                    left[nleft] = t
                    nleft += 1
                    break
    return T, N, free, nfree, ntet, flips, left[:nleft]


@njit(cache=True)
def _grow(A, fill):
    B = np.full((2 * A.shape[0],) + A.shape[1:], fill, A.dtype)
    B[:A.shape[0]] = A
    return B
