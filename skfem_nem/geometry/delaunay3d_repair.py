"""Local repair of a 3D Delaunay tetrahedralisation whose nodes have moved.

Why not rebuild: a Lagrangian step moves every node a little, and about one face in a hundred
stops being Delaunay; rebuilding costs every insertion again and loses the identity of the
tetrahedra that integration-point fields live on. The paper could not do this in 3D ("there
is, as yet, no direct extension of the 2D flip operation"). :func:`repair` does it in rounds:

1. **Scan.** The nodes are put at their new positions and every tetrahedron is tested with
   the exact predicates (:func:`scan`): inverted, or a face failing the empty-sphere test.
2. **Freeze.** The moved vertices of inverted tetrahedra (and of tetrahedra under a hull face
   they poke through) go back to their old positions ("frozen"), and the tetrahedra around
   them are tested again, until none is inverted (:func:`freeze`). This ends, at worst with
   every node frozen, where the old tetrahedralisation is valid.
3. **Flip.** The failing faces are flipped (:mod:`.delaunay3d_flips`: 2-3, 3-2, and 4-4 on
   flat walls). Where flips stop at a face they cannot mend, its moved vertices are frozen
   too and the round starts again from the old tetrahedra.
4. **Relocate.** The tetrahedra are now the Delaunay tetrahedralisation of the nodes at these
   mixed positions. Each frozen node is removed (the hole it leaves is filled by the part of
   the Delaunay tetrahedralisation of its link that its own insertion would destroy:
   Devillers' removal by the link's triangulation) and re-inserted at its new position
   (Bowyer-Watson, :func:`.delaunay3d_build.insert_point`); the tetrahedralisation stays
   Delaunay after every node (:func:`relocate`).

Apart from the scan (one pass of two predicates per tetrahedron, on all threads) the work
grows with what changed, not with the mesh. Every decision is an exact sign with the symbolic
perturbation of :mod:`.delaunay3d_build`, so the result is the tetrahedralisation a fresh
build of the new positions gives, tetrahedron for tetrahedron. A rebuild from scratch happens
only when rounds stop freezing new nodes (counted, never seen in the tests or benchmarks).
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

from .delaunay3d_flips import (face_fails, flip_to_delaunay, glue, internal, push,
                               release_rows, take_rows)
from .nodesets import morton_order
from .delaunay3d_build import (OK, cavity, coincident, free_rows, o3, reserve, build,
                               insert_point, locate, new_work)

__all__ = ["repair", "RELOCATED", "LOST", "COINCIDENT"]

RELOCATED, LOST, COINCIDENT = 0, 1, 2  # relocate status codes
_HOLE_FACES = 256  # initial capacity of a star's boundary (a vertex has about 25 tets)


@njit(cache=True, inline="always")
def _apex(T, N, t, i):
    """The vertex of the neighbour across face i of tet t that is not on that face."""
    u = N[t, i]
    for j in range(4):
        if N[u, j] == t:
            return T[u, j]
    return -1


@njit(cache=True)
def _tet_fails(P, G, T, N, t):
    """Whether tet t is inverted or has a failing face on the hull (flips mend the others)."""
    if T[t, 3] != G and o3(P, T[t, 0], T[t, 1], T[t, 2], T[t, 3]) <= 0.0:
        return True
    for i in range(4):
        if (T[t, 3] == G) != (T[N[t, i], 3] == G) and face_fails(P, G, T, N, t, i):
            return True
    return False


@njit(cache=True)
def _mark(T, N, G, t, moved, frozen, mark):
    """Mark the moved, not yet frozen vertices of tet t and of the apexes across its faces."""
    count = 0
    for i in range(8):
        v = T[t, i] if i < 4 else _apex(T, N, t, i - 4)
        if v != G and moved[v] and not frozen[v] and not mark[v]:
            mark[v] = True
            count += 1
    return count


@njit(cache=True)
def _star(T, N, v, t0, stamp, it, out):
    """The tets having vertex v, by a search across the faces through v from t0; ``stamp``
    marks them with ``it``. Returns the (possibly grown) ``out`` and their number."""
    stamp[t0] = it
    out[0] = t0
    n = 1
    k = 0
    while k < n:
        t = out[k]
        k += 1
        for i in range(4):
            if T[t, i] == v:
                continue
            u = N[t, i]
            if stamp[u] != it:
                stamp[u] = it
                if n == out.shape[0]:
                    grown = np.empty(2 * n, np.int32)
                    grown[:n] = out
                    out = grown
                out[n] = u
                n += 1
    return out, n


@njit(cache=True, parallel=True)
def scan(P, G, T, N, ntet, flags):
    """Test every tet at the positions P: ``flags[t]`` 1 when t is inverted or has a
    failing face on the hull (its nodes are frozen), 2 when a face between finite tets fails
    (flips mend it), else 0. Faces between finite tets are tested once, from the higher row."""
    for t in prange(ntet):
        flags[t] = 0
        if T[t, 0] < 0:
            continue
        if T[t, 3] != G and o3(P, T[t, 0], T[t, 1], T[t, 2], T[t, 3]) <= 0.0:
            flags[t] = 1
            continue
        for i in range(4):
            u = N[t, i]
            beneath = (T[t, 3] == G) != (T[u, 3] == G)  # a hull face: inverted if failing
            # t as int32, as the tets' rows hold it (prange's index is int64 in typing and
            # uint64 in the parallel loop): one specialization of face_fails
            if (beneath or u < t) and face_fails(P, G, T, N, np.int32(t), i):
                if beneath:
                    flags[t] = 1
                    break
                flags[t] = 2


@njit(cache=True)
def freeze(P, P0, G, T, N, v2t, moved, frozen, flags):
    """Step 2 of the module docstring on the positions P (modified in place, as is
    ``frozen``, the nodes already at their old positions ``P0``), starting from the tets
    :func:`scan` flagged 1: moved nodes of inverted tets and of failing hull faces are frozen
    until none is left. Returns the flip stack: the tets flagged 2 and the tets around every
    node frozen here (whose faces changed)."""
    mark = np.zeros(P.shape[0], np.bool_)
    count = 0
    for t in np.flatnonzero(flags == 1):
        count += _mark(T, N, G, np.int32(t), moved, frozen, mark)  # int32 as the tets' rows
    stamp = np.zeros(T.shape[0], np.int64)
    star = np.empty(64, np.int32)
    stack = np.flatnonzero(flags == 2).astype(np.int32)
    nstack = stack.shape[0]
    it = 0
    while count > 0:
        changed = np.flatnonzero(mark)
        for v in changed:
            frozen[v] = True
            mark[v] = False
            P[v] = P0[v]
        count = 0
        for v in changed:  # every tet or face whose geometry changed has a changed vertex
            it += 1
            star, ns = _star(T, N, v, v2t[v], stamp, it, star)
            for k in range(ns):
                stack, nstack = push(stack, nstack, star[k])
                if _tet_fails(P, G, T, N, star[k]):
                    count += _mark(T, N, G, star[k], moved, frozen, mark)
    return stack[:nstack]


@njit(cache=True)
def stuck_nodes(T, N, G, left, moved, frozen):
    """The moved, not yet frozen nodes of the tets flips left failing (and their apexes)."""
    mark = np.zeros(moved.shape[0], np.bool_)
    for t in left:
        _mark(T, N, G, t, moved, frozen, mark)
    return mark


@njit(cache=True)
def _star_faces(T, N, v, star, ns):
    """The faces of the star of v opposite v: vertex triples (sorted), the star tet and the
    outside tet across each."""
    faces = np.empty((ns, 3), np.int64)
    inner = np.empty(ns, np.int32)
    outer = np.empty(ns, np.int32)
    for k in range(ns):
        t = star[k]
        m = 0
        for j in range(4):
            if T[t, j] == v:
                outer[k] = N[t, j]
            else:
                faces[k, m] = T[t, j]
                m += 1
        faces[k].sort()
        inner[k] = t
    return faces, inner, outer


@njit(cache=True)
def _link(T, v, G, star, ns):
    """The finite vertices of the star of v other than v (sorted, unique)."""
    vs = np.empty(4 * ns, np.int64)
    m = 0
    for k in range(ns):
        for j in range(4):
            w = T[star[k], j]
            if w != v and w != G:
                vs[m] = w
                m += 1
    return np.unique(vs[:m])


@njit(cache=True)
def _fill(P, G, v, link):
    """The tets filling the hole v leaves: the conflict region of v in the Delaunay
    tetrahedralisation of its link, in global vertex numbers (ghost G). Returns the tets
    (k, 4), their neighbours (k, 4) as indices among them or -1 on the hole's boundary, and
    whether it worked (False for a flat link)."""
    m = link.shape[0]
    Pl = np.empty((m + 1, 3))
    for k in range(m):
        Pl[k] = P[link[k]]
    Pl[m] = P[v]
    Gl = m + 1
    empty = np.empty((0, 4), np.int32)
    if m < 4:
        return empty, empty, False
    Tl, Nl, ntl, status, _, _ = build(Pl, np.arange(m))
    if status != OK:
        return empty, empty, False
    # int64s, not literals, as the insertions pass: one specialization of locate, cavity
    start = np.int64(0)
    while Tl[start, 0] < 0:
        start += 1
    t0, _ = locate(Pl, Gl, Tl, Nl, start, m, np.int64(12345))
    stamp = np.zeros(Tl.shape[0], np.int64)
    conf = np.zeros(Tl.shape[0], np.bool_)
    cav, ncav = cavity(Pl, Gl, Tl, Nl, stamp, conf, np.int64(1), t0, m,
                       np.empty(64, np.int32))
    index = np.full(Tl.shape[0], -1, np.int32)
    for k in range(ncav):
        index[cav[k]] = k
    tets = np.empty((ncav, 4), np.int32)
    nbrs = np.empty((ncav, 4), np.int32)
    for k in range(ncav):
        for j in range(4):
            w = Tl[cav[k], j]
            tets[k, j] = G if w == Gl else link[w]
            nbrs[k, j] = index[Nl[cav[k], j]]
    return tets, nbrs, True


@njit(cache=True)
def _flat_fill(T, N, G, v, star, ns):
    """The fill of the hole of a hull vertex v whose other neighbours are coplanar (a
    lattice's corner): the faces opposite v become hull faces, so the fill is a ghost on
    each (the faces are shared with the tets beyond, so no other fill could be glued).
    Fails when a face has no finite tet beyond it (too few nodes would be left)."""
    k = 0
    for m in range(ns):
        if T[star[m], 3] != G:
            k += 1
    tets = np.empty((k, 4), np.int32)
    k = 0
    for m in range(ns):
        t = star[m]
        if T[t, 3] == G:
            continue
        j = 0
        while T[t, j] != v:
            j += 1
        if T[N[t, j], 3] == G:
            return tets, tets, False
        f = 0
        for jj in range(4):  # (a, b, c) with (a, b, c, v) positive: v beyond the new face
            if jj != j:
                tets[k, f] = T[t, jj]
                f += 1
        if j == 0 or j == 2:
            tets[k, 0], tets[k, 1] = tets[k, 1], tets[k, 0]
        tets[k, 3] = G
        k += 1
    return tets, internal(tets), True


@njit(cache=True)
def _remove(P, G, T, N, stamp, it, free, nfree, ntet, v, v2t, star):
    """Remove vertex v (the tetrahedralisation stays Delaunay). Returns ``nfree, ntet``,
    the star buffer, a tet next to where v was, and whether it worked."""
    star, ns = _star(T, N, v, v2t[v], stamp, it, star)
    faces, inner, outer = _star_faces(T, N, v, star, ns)
    tets, nbrs, ok = _fill(P, G, v, _link(T, v, G, star, ns))
    if not ok:
        tets, nbrs, ok = _flat_fill(T, N, G, v, star, ns)
    if not ok or tets.shape[0] > ns + nfree + (T.shape[0] - ntet):
        return nfree, ntet, star, -1, False
    slots, nfree1, ntet1 = take_rows(star[:ns], tets.shape[0], free, nfree, ntet)
    if not glue(T, N, tets, nbrs, faces, inner, outer, slots):
        return nfree, ntet, star, -1, False
    nfree, ntet = release_rows(T, star[:ns], tets.shape[0], free, nfree1), ntet1
    for k in range(tets.shape[0]):
        for j in range(4):
            if tets[k, j] != G:
                v2t[tets[k, j]] = slots[k]
    return nfree, ntet, star, slots[0], True


_ROOM = 4096  # rows kept free in the flat arrays before each relocation


@njit(cache=True)
def relocate(P, P1, G, T, N, ntet, v2t, order):
    """Step 4 of the module docstring: each node of ``order`` removed at its position in P
    and re-inserted at its position in P1 (P updated). Returns the (grown) ``T, N, ntet``,
    a status (RELOCATED; LOST: a removal failed, ``i`` the node; COINCIDENT: node ``i``
    landed on node ``j``) and ``i, j``."""
    free, nfree = free_rows(T, ntet)
    stamp = np.zeros(T.shape[0], np.int64)
    conf = np.zeros(T.shape[0], np.bool_)
    work = new_work()
    star = np.empty(64, np.int32)
    it, seed = 0, np.int64(12345)
    for v in order:
        T, N, stamp, conf, free = reserve(T, N, stamp, conf, free, ntet + _ROOM)
        it += 1
        nfree, ntet, star, near, ok = _remove(P, G, T, N, stamp, it, free, nfree, ntet, v,
                                              v2t, star)
        if not ok:
            return T, N, ntet, LOST, v, -1
        P[v] = P1[v]
        t0, seed = locate(P, G, T, N, near, v, seed)
        if T[t0, 3] != G:
            w = coincident(P, T, t0, v)
            if w >= 0:
                return T, N, ntet, COINCIDENT, v, w
        it += 1
        T, N, stamp, conf, free, nfree, ntet, work, nnew = insert_point(
            P, G, T, N, stamp, conf, free, nfree, ntet, it, t0, v, work)
        for k in range(nnew):
            t = work[1][k]
            for j in range(4):
                if T[t, j] != G:
                    v2t[T[t, j]] = t
    return T, N, ntet, RELOCATED, -1, -1


@njit(cache=True)
def remove_points(P, T, N, ntet, order):
    """The vertices ``order`` removed from the ghost-closed tetrahedralisation ``T, N,
    ntet`` of the points P (ghost vertex ``P.shape[0]``), each hole filled as in a
    relocation (the result stays Delaunay; the rows of the removed points stay in P, in no
    tet). Returns ``T, N, ntet``, a status (RELOCATED, or LOST with ``i`` the vertex
    whose removal failed) and ``i``."""
    G = P.shape[0]
    v2t = vertex_tets(T, ntet, G)
    free, nfree = free_rows(T, ntet)
    stamp = np.zeros(T.shape[0], np.int64)
    conf = np.zeros(T.shape[0], np.bool_)
    star = np.empty(64, np.int32)
    it = 0
    for v in order:
        T, N, stamp, conf, free = reserve(T, N, stamp, conf, free, ntet + _ROOM)
        it += 1
        nfree, ntet, star, near, ok = _remove(P, G, T, N, stamp, it, free, nfree, ntet, v,
                                              v2t, star)
        if not ok:
            return T, N, ntet, LOST, v
    return T, N, ntet, RELOCATED, -1


_MAX_ROUNDS = 8  # rounds of freezing the nodes flips could not mend, before a rebuild
_SPARE = 0.25  # spare rows of the working arrays, a fraction of the tets


def working(T, N, ntet):
    """The flat arrays with room to grow: the tets and neighbours (copies, spare rows -1)."""
    rows = ntet + int(_SPARE * ntet) + 64
    out = []
    for a in (T, N):
        b = np.full((rows, 4), -1, np.int32)
        b[:ntet] = a[:ntet]
        out.append(b)
    return out[0], out[1]


@njit(cache=True)
def vertex_tets(T, ntet, G):
    """A live tet at each vertex (the ghost G included)."""
    v2t = np.full(G + 1, -1, np.int32)
    for t in range(ntet):
        if T[t, 0] >= 0:
            for j in range(4):
                v2t[T[t, j]] = t
    return v2t


def repair(raw, P0, P1):
    """The ghost-closed tetrahedralisation ``raw = (T, N, ntet)`` of the nodes at ``P0``,
    repaired for the nodes at ``P1``: flips where they can, relocation of the nodes they
    cannot mend (module docstring). Returns ``T, N, ntet``, a status (RELOCATED, LOST: call
    for a rebuild, COINCIDENT: nodes ``i`` and ``j`` coincide), ``i, j`` and the counts."""
    G = P0.shape[0]
    moved = (P1 != P0).any(axis=1)
    frozen = np.zeros(G, np.bool_)
    flips = 0
    for _ in range(_MAX_ROUNDS):
        T, N = working(*raw)
        ntet = raw[2]
        v2t = vertex_tets(T, ntet, G)
        P = np.where(frozen[:, None], P0, P1)
        flags = np.empty(ntet, np.int8)
        scan(P, G, T, N, ntet, flags)
        stack = freeze(P, P0, G, T, N, v2t, moved, frozen, flags)
        free = np.flatnonzero(T[:ntet, 0] < 0).astype(np.int32)
        nfree = free.size
        free = np.concatenate([free, np.empty(T.shape[0] - nfree, np.int32)])
        T, N, free, nfree, ntet, f, left = flip_to_delaunay(P, G, T, N, ntet, free, nfree,
                                                            stack, v2t)
        flips += f
        if left.size == 0:
            break
        new = stuck_nodes(T, N, G, left, moved, frozen)
        if not new.any():
            break
        frozen |= new
    counts = {"flips": int(flips), "relocated": int(frozen.sum())}
    if left.size:
        return T, N, ntet, LOST, -1, -1, counts
    order = np.flatnonzero(frozen)
    order = order[morton_order(P1[order])] if order.size > 1 else order
    T, N, ntet, status, i, j = relocate(P, P1, G, T, N, ntet, v2t, order)
    return T, N, ntet, status, i, j, counts
