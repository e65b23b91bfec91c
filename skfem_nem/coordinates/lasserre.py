"""Sibson coordinates and their gradients in 2, 3 and 4 dimensions (the paper's Box 1).

This is the paper's "method 2": natural-neighbour (Sibson) coordinates from the
volumes of second-order Voronoi cells, each a convex polytope ``{y : A y <= b}``
whose volume is computed with Lasserre's recursive formula. The 2D area method
is :mod:`skfem_nem.coordinates.area2d`; this module works in any of d = 2, 3, 4.

Natural neighbours
    The Delaunay triangulation comes from :class:`scipy.spatial.Delaunay`
    (Qhull). A query is located by a visibility walk (barycentric
    coordinates, tolerance ``_WALK``) from a simplex at its nearest node;
    scipy's ``find_simplex`` is not used: its first call builds barycentric
    transforms through LAPACK, which with a multithreaded BLAS took 32 s for
    1.3e5 simplices. The natural neighbours of x are the vertices of the
    simplices whose circumsphere contains x (the conflict region, grown
    through ``neighbors``). In-sphere test: the circumcentre is solved
    relative to the simplex's first vertex (Gaussian elimination with
    partial pivoting); the power ``|w|^2 - 2 w.c`` (``w = x - v``, ``c`` the
    circumcentre relative to v, v that vertex; within its round-off bound
    the power is recomputed relative to the vertex nearest to x, whose bound
    shrinks with the distance to a node) is negative strictly inside.
    Simplices with a power below
    ``_INSPHERE * |w| (|w| + 2|c|)`` (a generous bound on its round-off),
    and (nearly) flat ones (Qhull's ``Qt`` makes them for co-spherical
    nodes, e.g. lattices), join the region too, so that it stays connected
    and no neighbour is lost; only the nodes of simplices strictly in
    conflict get cells (the others' cells are empty). Should the walk's
    tolerance have ended in a simplex whose circumsphere x is outside of
    (x within ~1e-12 of a vertex), the walk goes on without tolerance to the
    simplex that holds x. When a call has at
    least one query per ``_CACHE_QUERIES`` simplices, the circumcentres of
    all simplices are computed once beforehand (in parallel; each simplex
    is tested ~20 times by spatially sorted queries in 3D), with the same
    function and so the same bits as computing them per test.

Second-order cells
    The cell of neighbour i is ``{y : |y - x| <= |y - p_i| <= |y - p_j|}``:
    row 0 ``q_i . y <= |q_i|^2 / 2`` (closer to x than to p_i, with
    ``q_j = p_j - x`` and x at the origin) and rows
    ``(q_j - q_i) . y <= (q_j - q_i).(q_j + q_i) / 2`` (closer to p_i than to
    p_j). Rows are scaled to unit normals, and the origin of each cell is
    moved to ``(x + p_i) / 2``, on the plane of row 0: near a node p_k the
    other cells are slabs of width ~|x - p_k| between nearly parallel
    planes, and an origin at x would make Lasserre's sum cancel terms of
    size one down to that width. ``phi_i = V_i / V``, ``V = sum_j V_j``.

Lasserre's recursion
    ``V_n(A, b) = (1/n) sum_i (b_i / |a_it|) V_{n-1}(facet i)``: facet i is
    the system with ``a_i . u = b_i`` used to eliminate the variable t of
    largest ``|a_it|``; the base case n = 1 is the length of the feasible
    interval. With unit rows, ``(b_i / |a_it|) V_{n-1}`` is the distance of
    the origin from facet i's plane times the facet's (n-1)-volume.

3D in general position: the faces from the combinatorics (:func:`_cells3`)
    Where the conflict region has no flat or borderline simplex (almost
    every query), the faces of all cells are known before any volume is
    computed: the cells of neighbours i < j share the polygon on the
    bisector of p_i and p_j (dual to the Delaunay edge ij of a conflict
    simplex), cell i has facet 0 on the bisector of x and p_i (dual to the
    new edge x p_i), and every polygon edge is dual to a triangle -- an
    interior face of the region, a boundary face, or x with a boundary edge
    -- running between the circumcentres of the two simplices on either
    side (conflict simplices; x and a boundary face). So each vertex is
    computed once, each polygon's Lasserre sum takes its edges' lengths
    (the base case) from their end vertices, the edge term is shared by the
    three polygons on the edge, the polygon between cells i and j by both,
    and ``V_i = (1/3) sum_j beta_ij area(P_ij)`` (facet 0 has ``beta = 0``
    at the origin ``(x + p_i) / 2``); facet 0's area and first moment give
    the gradient. No constraint is redundant and nothing is reduced or
    eliminated. A simplex with a shape measure (volume determinant over
    the product of its edge lengths) below ``_SHAPE``, combinatorics other
    than those of general position, a cell whose volume rounds to zero or
    below, or linear precision or its derivative
    (``sum_i q_i (x) grad V_i = V I``) violated beyond ``_LINEAR3`` /
    ``_GRAD3`` leave the query to the general recursion below, and so does
    a query closer to a node than ``_NEAR3`` times its largest distance to a
    neighbour (the other cells are then thin slabs, whose gradients the
    recursion gets about twice as accurately). That is 3 in 1e5 random
    queries; lattices and other co-spherical sets, points within ~1e-7 of
    the hull and near nodes mostly. Elsewhere this path is as accurate as
    the recursion or more: near thin hull simplices with huge
    circumspheres the identities hold to ~1e-12 where the recursion gave
    ~1e-10 (and ~1e-6 in rare cases).

The general recursion
    It runs iteratively (an explicit stack of one buffer level per
    dimension, in a numba kernel; numba cannot cache recursive functions).

    - Combinatorial filter: the vertices of cell i are the circumcentres of
      the conflict simplices holding i and of the new simplices (x + a face
      of the region's boundary holding i), so the face of the cell on the
      constraints J is bounded only by constraints k that share such a
      simplex with J; the others are left out. This makes the recursion
      about linear in the number of faces (3D: ~21 facet visits and ~50 row
      reductions per cell instead of thousands). When the region holds flat
      or borderline simplices, listed simplices whose d planes do not meet
      in a point satisfying all rows (within ``_VERTEX``) are dropped first.
      Safety nets: a query whose cells come out unbounded or whose volumes
      violate linear precision (``sum_i V_i (p_i - x) = 0`` within
      ``_LINEAR``) is recomputed with a relaxed filter, then with none.
    - Coincident constraints (lattices put many bisectors through the same
      lines): when a facet's system is built, rows whose planes coincide
      (within ``_ZERO_ROW`` in direction, ``_TIE`` times the local length in
      offset) are merged, keeping the smallest id and the union of the ids
      for the filter; two that coincide facing each other leave a slab of
      zero width, so the facet has zero volume. A reduced row parallel to
      the facet (normal shorter than ``_ZERO_ROW``) is dropped if it lies
      beyond it, empties it if it lies before it. Redundant constraints need
      nothing else: their facets are empty or lower-dimensional and give 0.
    - Consistent vertices: in the last level (polygons) the two ends of
      each edge are recomputed from the pair of lines that meets there by a
      formula symmetric in the pair, so that both edges of a vertex use the
      same point: where two nearly parallel lines meet, independently
      rounded ends would not cancel in Lasserre's sum. Each facet's origin
      is likewise moved onto the trace of row 0.
    - The cells of neighbours i and j share the face on the bisector of
      p_i and p_j: its area is computed once.

Gradients
    Only row 0 depends on x. Moving x moves the bisector between x and p_i
    with normal speed ``(y - x) . dx / |p_i - x|`` at a point y of it, hence
    ``grad V_i = (1 / |p_i - x|) integral over facet 0 of (y - x) dS``
    (in 2D ``(s_i / h_i) (c_i - x)``: facet length times midpoint; this is
    the paper's ``-dV/da_0 - x dV/db_0`` written as a surface integral).
    The first moment of facet 0 comes from the same recursion: for f
    homogeneous of degree q,
    ``integral_P f = 1/(n+q) sum_i (b_i / |a_it|) integral_{facet i} f``,
    so volumes and first moments recurse together. On facet 0 the rows of
    the planes between x and p_m replace those between p_i and p_m (the same
    half-spaces there, and at good angles to it). Then
    ``grad phi_i = (grad V_i - phi_i sum_j grad V_j) / V``, with the
    dominant neighbour's gradient from complement sums (as in
    :mod:`skfem_nem.coordinates.area2d`).

Special points
    At a node: the Kronecker delta (gradients undefined). On the convex hull
    (within ``_HULL`` times the distance to the facet's nodes, else outside
    is an error): the limits from inside, see :func:`_on_hull` -- inside a
    hull facet the weights ``integral over C_i of (|y - p_i|^2 - |y - x|^2)
    dy`` over the (d-1)-dimensional second-order cells of the facet's nodes
    (not their (d-1)-dimensional Sibson coordinates), linear interpolation
    on hull edges. Points on interior Delaunay faces and edges need nothing
    special: nothing divides by a quantity that vanishes there. Gradients at
    nodes or on the hull raise ``ValueError`` (``undefined="raise"``) or
    give NaN rows (``undefined="nan"``).

Kernels
    Every numba function below the parallel batch kernel is compiled
    without reference counting (``_nrt=False``; they allocate nothing):
    numba otherwise increments and decrements the count of every array
    argument atomically on each call, which took a quarter of the 3D time.
    The batch kernel allocates one set of buffers per block of queries.

Accuracy (measured, see tests/test_lasserre.py)
    Values agree with the 2D area method to ~2e-15 and gradients to ~2e-13
    relative; in 3D the second-order volumes sum to the Voronoi cell volume
    (scipy/Qhull) to ~1e-15 relative; partition of unity and linear
    precision hold to ~5e-16 in 3D and 4D, also on lattices and within
    1e-12 of a node (to ~1e-14 down to 1e-15 from one). Gradients lose digits near a node like ``1e-17 / r``
    (r the distance to it), as the area method does. Node sets that are
    nearly but not exactly co-spherical (lattices jittered by 1e-9) get
    errors of that size: Qhull's triangulation is then not Delaunay to that
    precision.
"""
from __future__ import annotations

from typing import Literal

import numpy as np
import scipy.sparse as sp
from numba import njit, prange
from scipy.spatial import cKDTree

from .batch import (AT_NODE, OK, ON_HULL, OUTSIDE, OVERFLOW, UNBOUNDED, check_queries,
                     compress, index_dtype, raise_outside, raise_undefined)
from .._numba import serial_twin
from ..geometry.delaunay_nd import check_delaunay, check_nodes, delaunay_of, triangulate

__all__ = ["sibson_coordinates_nd"]


# A reduced (unit) constraint normal shorter than this is parallel to the facet.
_ZERO_ROW = 1e-13
# Parallel planes closer than this times the local length scale coincide.
_TIE = 1e-13
# Relative tolerance of the in-sphere test (tolerant: includes borderline simplices).
_INSPHERE = 1e-10
# A simplex counts as flat when its volume determinant is below this times the
# product of its edge lengths from the first vertex.
_FLAT = 1e-12
# A point whose distance to a hull facet's plane is below this times its
# distance to the facet's nodes is on the hull.
_HULL = 1e-12
# A hull facet whose normal (generalised cross product of its edges) is
# shorter than this times the product of the edge lengths is degenerate.
_HULL_FLAT = 1e-6
# Linear precision residual |sum_i V_i (p_i - x)| / (V L) above which a query is
# recomputed without the combinatorial facet filter (a safety net).
_LINEAR = 1e-9
# A vertex of a cell may violate its constraints by this times the local length
# scale (vertex check of the combinatorial filter in degenerate configurations).
_VERTEX = 1e-9
# Barycentric coordinates above -_WALK count as inside a simplex (point location).
_WALK = 1e-12
# 3D cells from the known combinatorics (general position): a cell vertex whose
# simplex has a shape measure (volume determinant over the product of its edge
# lengths) below _SHAPE, a linear precision residual above _LINEAR3 (relative, as
# _LINEAR) or a residual of its derivative sum_i q_i (x) grad V_i = V I above
# _GRAD3 (relative to sum_i |q_i| |grad V_i|) leaves the query to the recursion.
_SHAPE = 1e-6
_LINEAR3 = 1e-12
_GRAD3 = 1e-11
# ... and so does a query closer to a node than _NEAR3 times its largest
# distance to a natural neighbour.
_NEAR3 = 1e-4

# The circumcentres of all simplices are computed once per call (in parallel)
# when there are at least 1/_CACHE_QUERIES queries per simplex.
_CACHE_QUERIES = 8

# default buffer sizes (natural neighbours, conflict simplices, output entries
# per query) per dimension
_CAPS = {2: (32, 64, 24), 3: (96, 384, 64), 4: (256, 2048, 256)}


# ---------------------------------------------------------------------------
# numba kernels
# ---------------------------------------------------------------------------

@njit(cache=True, error_model="numpy", _nrt=False)
def _cell(d, m0, A, B, I, AX, BX, M, W, Tc, nT, act, nact, mrows, cur, tpiv, acc, wm, gs, gc, gp,
          gq, rep, gmark, stamp, sc, full, strict, want_grad, want_mom, G, ztol, btol,
          flag, cell, tab):
    """Volume of the polytope {u in R^d : A[0, j] . u <= B[0, j], j < m0} by
    Lasserre's recursion, run iteratively with one buffer level per dimension
    (level l holds a system in d - l variables).

    Rows must have unit length; ``I[0, j]`` is row j's constraint id (0 for the
    bisector between x and the cell's node, whose facet's first moment
    ``integral u dS`` goes to ``G[:d]`` and its area to ``G[d]`` when
    ``want_grad``). With ``want_mom`` the first moments ``integral u du`` of
    the cell go to ``M[0, :d]`` (then ``cell`` must be -1: no shared faces).

    Coincident rows. When a facet's system is built, rows whose planes
    coincide (within ``ztol`` in direction and ``btol`` in offset) are merged
    into one, which keeps the smallest id and the union of the ids as its
    group ``gp[l, gs[l, j]:gs[l, j] + gc[l, j]]``; two rows that coincide
    facing each other leave a slab of zero width, so the facet has zero
    volume. (Lattices put many bisectors through the same lines.)

    Combinatorial filter (unless ``full``). The face of the cell on the
    constraints J is only bounded by constraints k such that a simplex in
    ``Tc[:nT]`` (rows of d constraint ids: the Delaunay simplices whose
    circumcentres are the cell's vertices) holds J and k, counting every id
    of a merged group; the other constraints are redundant there and are
    left out. This holds for nodes in general position; where more than
    d + 1 nodes are co-spherical a face can be held by simplices that only
    share a lower-dimensional coincidence with it, so the ``strict=False``
    variant only asks for a simplex holding the last constraint of J and k.

    Shared faces. The cells of x's neighbours i < j share the face on the
    bisector between p_i and p_j, with opposite normals: cell ``cell`` stores
    the area of that face in ``tab[cell, j]`` for j > cell and reuses
    ``tab[j, cell]`` for j < cell (ids are j + 1).

    Origins. Each facet system below the top is translated by ``W[l]`` so
    that the trace of row 0 passes through its origin (moments are shifted
    back); on facet 0 the rows ``AX, BX`` (planes between x and the other
    neighbours) replace ``A[0], B[0]``. Polygon edges end at points
    computed symmetrically from the two lines meeting there.

    (One function without array-passing helpers: numba reference-counts
    array arguments with atomic operations, which dominated the run time.)
    """
    for s in range(nT):
        act[0, s] = s
    nact[0] = nT
    for k in range(d):
        W[0, k] = 0.0
    mrows[0] = m0
    for j in range(m0):
        gs[0, j] = j
        gc[0, j] = 1
        gp[0, j] = I[0, j]
    cur[0] = -1
    acc[0] = 0.0
    wm[0] = want_mom
    if want_mom:
        for k in range(d):
            M[0, k] = 0.0
    if want_grad:
        for k in range(d + 1):
            G[k] = 0.0
    l = 0
    have = False   # a facet volume fv of facet cur[l] waits to be added to level l
    fv = 0.0
    while True:
        if have:
            # Lasserre's sum: (b_i / |a_it|) * (projected facet volume); and for
            # the first moments u_k = w_k (k != t), u_t = (b_i - sum a_ik w_k) / a_it
            have = False
            n = d - l
            i = cur[l]
            t = tpiv[l]
            ait = A[l, i, t]
            bi = B[l, i]
            coef = bi / abs(ait)
            acc[l] += coef * fv
            idc = I[l, i]
            if l == 0 and idc > 0:
                tab[cell, idc - 1] = fv / abs(ait)
            top = l == 0 and want_grad and idc == 0
            if wm[l] or top:
                c = 0
                s_ = 0.0
                for k in range(n):
                    if k != t:
                        mk = M[l + 1, c] + W[l + 1, c] * fv
                        s_ += A[l, i, k] * mk
                        if wm[l]:
                            M[l, k] += coef * mk
                        if top:
                            G[k] = mk / abs(ait)
                        c += 1
                mt = (bi * fv - s_) / ait
                if wm[l]:
                    M[l, t] += coef * mt
                if top:
                    G[t] = mt / abs(ait)
                    G[d] = fv / abs(ait)
        n = d - l
        cur[l] += 1
        i = cur[l]
        if i >= mrows[l]:
            v = acc[l] / n
            if wm[l]:
                for k in range(n):
                    M[l, k] /= n + 1
            if l == 0:
                return v
            l -= 1
            fv = v
            have = True
            continue
        idc = I[l, i]
        if B[l, i] == 0.0 and not wm[l] and (l > 0 or (idc == 0 and not want_grad)):
            continue  # the origin is on this facet's plane: no contribution
        if l == 0 and idc > 0:
            if idc - 1 < cell:
                # the face shared with an earlier cell: its area is known
                acc[0] += B[0, i] * tab[idc - 1, cell]
                continue
            tab[cell, idc - 1] = 0.0
        # facet i: pivot on its largest coefficient
        t = 0
        big = abs(A[l, i, 0])
        for k in range(1, n):
            if abs(A[l, i, k]) > big:
                big = abs(A[l, i, k])
                t = k
        tpiv[l] = t
        ait = A[l, i, t]
        inv_ait = 1.0 / ait
        bi = B[l, i]
        nl = l + 1
        if not full:
            # the simplices holding (a constraint of the group of) facet i,
            # and the ids they hold
            sc[0] += 1
            gstp = sc[0]
            for e in range(gs[l, i], gs[l, i] + gc[l, i]):
                gmark[gp[l, e]] = gstp
            sc[0] += 1
            na = 0
            pl = l if strict else 0
            for a in range(nact[pl]):
                s = act[pl, a]
                has = False
                for k in range(d):
                    if gmark[Tc[s, k]] == gstp:
                        has = True
                        break
                if has:
                    act[nl, na] = s
                    na += 1
                    for k in range(d):
                        stamp[Tc[s, k]] = sc[0]
            if na == 0:
                continue  # no vertex on this facet
            nact[nl] = na
        stp = sc[0]
        child_mom = wm[l] or (l == 0 and want_grad and idc == 0)
        # On facet 0 (|y - x| = |y - p_i|) "closer to p_i than to p_m" is
        # "closer to x than to p_m": reduce the rows of the planes x|m
        # (AX, BX) instead, which meet facet 0 at good angles even where
        # the planes p_i|p_m are nearly parallel to it (x close to a node).
        xm = l == 0 and idc == 0
        empty = False
        if n == 2:
            # the facet is a segment: reduce the rows straight to the
            # feasible interval lo <= w <= hi
            u = 1 - t
            lo = -np.inf
            hi = np.inf
            jlo = -1
            jhi = -1
            cnt = 0
        mm = 0
        pool = 0
        for j in range(mrows[l]):
            if j == i:
                continue
            if not full:
                cand = False
                for e in range(gs[l, j], gs[l, j] + gc[l, j]):
                    if stamp[gp[l, e]] == stp:
                        cand = True
                        break
                if not cand:
                    continue
            if xm:
                f = AX[j, t] * inv_ait
                bj = BX[j] - f * bi
            else:
                f = A[l, j, t] * inv_ait
                bj = B[l, j] - f * bi
            if n == 2:
                if xm:
                    a = AX[j, u] - f * A[l, i, u]
                else:
                    a = A[l, j, u] - f * A[l, i, u]
                nrm = abs(a)
            else:
                c = 0
                nrm2 = 0.0
                for k in range(n):
                    if k != t:
                        if xm:
                            v = AX[j, k] - f * A[l, i, k]
                        else:
                            v = A[l, j, k] - f * A[l, i, k]
                        A[nl, mm, c] = v
                        nrm2 += v * v
                        c += 1
                nrm = np.sqrt(nrm2)
            if nrm <= ztol:
                # the plane of row j is parallel to facet i
                if bj > btol:
                    continue          # it lies beyond the facet: redundant here
                if bj < -btol:
                    empty = True      # it cuts the whole facet away
                    break
                # coincident planes (not merged above): facing the same way,
                # the smaller id owns the facet; facing each other, they
                # bound a slab of zero width
                dot = 0.0
                for k in range(n):
                    if xm:
                        dot += AX[j, k] * A[l, i, k]
                    else:
                        dot += A[l, j, k] * A[l, i, k]
                if dot > 0.0 and I[l, j] > idc:
                    continue
                empty = True
                break
            if n == 2:
                r = bj / a
                cnt += 1
                if a > 0.0:
                    if r < hi:
                        hi = r
                        jhi = j
                elif r > lo:
                    lo = r
                    jlo = j
            else:
                inv = 1.0 / nrm
                for k in range(n - 1):
                    A[nl, mm, k] *= inv
                B[nl, mm] = bj * inv
                I[nl, mm] = I[l, j]
                gs[nl, mm] = pool
                gc[nl, mm] = gc[l, j]
                for e in range(gs[l, j], gs[l, j] + gc[l, j]):
                    gp[nl, pool] = gp[l, e]
                    pool += 1
                mm += 1
        if empty:
            continue
        if n == 2:
            if not hi > lo:
                continue
            if cnt == 0 or lo == -np.inf or hi == np.inf:
                flag[0] = 1
                continue
            # Recompute both ends as the intersection of the two lines by a
            # formula symmetric in the pair, so that the edge that ends at the
            # same vertex uses the very same point: at a vertex where two
            # nearly parallel lines meet, independently rounded ends would
            # not cancel in Lasserre's sum.
            for e in range(2):
                j = jhi if e == 0 else jlo
                if xm:
                    # facet 0 of a 2D cell: its ends from the planes x|m
                    a1x, a1y, b1 = A[0, i, 0], A[0, i, 1], B[0, i]
                    a2x, a2y, b2 = AX[j, 0], AX[j, 1], BX[j]
                else:
                    r1 = i
                    r2 = j
                    if I[l, j] < idc:
                        r1 = j
                        r2 = i
                    a1x, a1y, b1 = A[l, r1, 0], A[l, r1, 1], B[l, r1]
                    a2x, a2y, b2 = A[l, r2, 0], A[l, r2, 1], B[l, r2]
                det = a1x * a2y - a1y * a2x
                if u == 0:
                    w = (b1 * a2y - b2 * a1y) / det
                else:
                    w = (a1x * b2 - a2x * b1) / det
                if e == 0:
                    hi = w
                else:
                    lo = w
            if not hi > lo:
                continue
            if child_mom:
                M[nl, 0] = 0.5 * (hi - lo) * (hi + lo)
                W[nl, 0] = 0.0
            fv = hi - lo
            have = True
            continue
        if mm == 0:
            flag[0] = 1
            continue
        # merge coincident rows of the facet's system
        merged = False
        for b in range(mm):
            rep[b] = b
            for a in range(b):
                if rep[a] != a:
                    continue
                ds = 0.0
                do = 0.0
                for k in range(n - 1):
                    ds = max(ds, abs(A[nl, a, k] - A[nl, b, k]))
                    do = max(do, abs(A[nl, a, k] + A[nl, b, k]))
                if ds <= ztol and abs(B[nl, a] - B[nl, b]) <= btol:
                    rep[b] = a
                    merged = True
                    break
                if do <= ztol and abs(B[nl, a] + B[nl, b]) <= btol:
                    empty = True  # a slab of zero width: no volume
                    break
            if empty:
                break
        if empty:
            continue
        if merged:
            w = 0
            pool = 0
            for a in range(mm):
                if rep[a] != a:
                    continue
                start = pool
                idm = I[nl, a]
                for b in range(a, mm):
                    if rep[b] == a:
                        idm = min(idm, I[nl, b])
                        for e in range(gs[nl, b], gs[nl, b] + gc[nl, b]):
                            gq[pool] = gp[nl, e]
                            pool += 1
                for k in range(n - 1):
                    A[nl, w, k] = A[nl, a, k]
                B[nl, w] = B[nl, a]
                I[nl, w] = idm
                gs[nl, w] = start
                gc[nl, w] = pool - start
                w += 1
            for e in range(pool):
                gp[nl, e] = gq[e]
            mm = w
        # Put the facet's origin on the trace of row 0 (the bisector between
        # x and the cell's node), as at the top level: near a node the
        # facets are thin wedges along that plane.
        r0 = -1
        for j in range(mm):
            if I[nl, j] == 0:
                r0 = j
        for k in range(n - 1):
            W[nl, k] = 0.0
        if r0 >= 0 and B[nl, r0] != 0.0:
            for k in range(n - 1):
                W[nl, k] = B[nl, r0] * A[nl, r0, k]
            for j in range(mm):
                sh = 0.0
                for k in range(n - 1):
                    sh += A[nl, j, k] * W[nl, k]
                B[nl, j] -= sh
            B[nl, r0] = 0.0
        mrows[nl] = mm
        cur[nl] = -1
        acc[nl] = 0.0
        wm[nl] = child_mom
        if child_mom:
            for k in range(n - 1):
                M[nl, k] = 0.0
        l = nl


@njit(cache=True, _nrt=False)
def _det_small(E, k):
    """Determinant of the leading k x k block of E (destroyed), partial pivoting."""
    det = 1.0
    for c in range(k):
        p = c
        for r in range(c + 1, k):
            if abs(E[r, c]) > abs(E[p, c]):
                p = r
        if E[p, c] == 0.0:
            return 0.0
        if p != c:
            for j in range(k):
                E[c, j], E[p, j] = E[p, j], E[c, j]
            det = -det
        det *= E[c, c]
        for r in range(c + 1, k):
            f = E[r, c] / E[c, c]
            for j in range(c, k):
                E[r, j] -= f * E[c, j]
    return det


@njit(cache=True, error_model="numpy", _nrt=False)
def _circumcentre(P, S, s, d, E, rhs, flat):
    """Circumcentre of simplex s relative to its first vertex into ``rhs[:d]``
    (Gaussian elimination with partial pivoting; ``E`` (d, d) scratch).
    Returns the shape measure: the signed volume determinant over the
    product of the edge lengths from the first vertex (sign: the simplex's
    orientation), or 0.0 for a (nearly) flat simplex, at most ``flat`` in
    size (``rhs`` is then undefined)."""
    v0 = S[s, 0]
    prod = 1.0
    for r in range(d):
        v = S[s, r + 1]
        e2 = 0.0
        for k in range(d):
            e = P[v, k] - P[v0, k]
            E[r, k] = e
            e2 += e * e
        rhs[r] = 0.5 * e2
        prod *= np.sqrt(e2)
    det = 1.0
    for c in range(d):
        p = c
        for r in range(c + 1, d):
            if abs(E[r, c]) > abs(E[p, c]):
                p = r
        if p != c:
            for j in range(d):
                E[c, j], E[p, j] = E[p, j], E[c, j]
            rhs[c], rhs[p] = rhs[p], rhs[c]
            det = -det
        det *= E[c, c]
        if E[c, c] == 0.0:
            return 0.0
        for r in range(c + 1, d):
            f = E[r, c] / E[c, c]
            for j in range(c, d):
                E[r, j] -= f * E[c, j]
            rhs[r] -= f * rhs[c]
    if abs(det) <= flat * prod:
        return 0.0
    for c in range(d - 1, -1, -1):
        acc = rhs[c]
        for j in range(c + 1, d):
            acc -= E[c, j] * rhs[j]
        rhs[c] = acc / E[c, c]
    return det / prod


@njit(cache=True, parallel=True, error_model="numpy")
def _circumcentres(P, S, flat, CC, SH):
    """:func:`_circumcentre` of every simplex: ``CC`` (ns, d), ``SH`` (ns,)."""
    ns = S.shape[0]
    d = P.shape[1]
    nblocks = max(1, min(ns // 256, 64))
    for blk in prange(nblocks):
        E = np.empty((d, d))
        rhs = np.empty(d)
        for s in range(blk * ns // nblocks, (blk + 1) * ns // nblocks):
            SH[s] = _circumcentre(P, S, s, d, E, rhs, flat)
            for k in range(d):
                CC[s, k] = rhs[k]


@njit(cache=True, error_model="numpy", _nrt=False)
def _in_conflict(P, S, s, x, d, E, rhs, tol, flat, cached, CC, SH):
    """Is x inside the circumsphere of simplex s? Returns ``(code, shape)``:
    code 2: strictly inside (the circumcentre is a vertex of x's Voronoi
    cell); 1: on it within the tolerance, or the simplex is flat; 0: outside.
    Unless flat, ``rhs[:d]`` holds the circumcentre relative to the first
    vertex; ``shape`` is :func:`_circumcentre`'s, which is computed here or
    (``cached``) read from ``CC``, ``SH``."""
    if cached:
        shape = SH[s]
        for k in range(d):
            rhs[k] = CC[s, k]
    else:
        shape = _circumcentre(P, S, s, d, E, rhs, flat)
    if shape == 0.0:
        return 1, 0.0
    v0 = S[s, 0]
    w2 = 0.0
    wc = 0.0
    c2 = 0.0
    for k in range(d):
        w = x[k] - P[v0, k]
        w2 += w * w
        wc += w * rhs[k]
        c2 += rhs[k] * rhs[k]
    power = w2 - 2.0 * wc
    wn = np.sqrt(w2)
    bound = tol * wn * (wn + 2.0 * np.sqrt(c2))
    if abs(power) < bound:
        # within the round-off bound: recompute relative to the vertex
        # nearest to x, where the bound shrinks with the distance (within
        # ~1e-11 of a node every simplex around it is then decided, not
        # borderline, and the region stays connected)
        vn = v0
        best = w2
        for j in range(1, d + 1):
            v = S[s, j]
            e2 = 0.0
            for k in range(d):
                e2 += (x[k] - P[v, k]) ** 2
            if e2 < best:
                best = e2
                vn = v
        if vn != v0:
            w2 = 0.0
            wc = 0.0
            c2 = 0.0
            for k in range(d):
                w = x[k] - P[vn, k]
                cn = rhs[k] - (P[vn, k] - P[v0, k])
                w2 += w * w
                wc += w * cn
                c2 += cn * cn
            power = w2 - 2.0 * wc
            wn = np.sqrt(w2)
            bound = tol * wn * (wn + 2.0 * np.sqrt(c2))
    if power < 0.0:
        return 2, shape
    if power < bound:
        return 1, shape
    return 0, shape


@njit(cache=True, _nrt=False)
def _hull_distance(P, S, s, k, x, d, ctr, E, Mn):
    """Signed distance of x from the plane of the hull facet opposite vertex k
    of simplex s (positive on the side of ``ctr``, the centroid of the nodes,
    which lies inside the hull; the simplex itself may be flat) and the
    largest distance from x to the facet's vertices. The distance is +inf
    for a (nearly) degenerate facet, whose plane is ill-determined: Qhull
    makes such slivers along hull ridges with collinear nodes, and the
    well-shaped facets around them decide instead."""
    f0 = -1
    r = 0
    L = 0.0
    prod = 1.0
    for j in range(d + 1):
        if j == k:
            continue
        v = S[s, j]
        dx2 = 0.0
        for c in range(d):
            dx2 += (P[v, c] - x[c]) ** 2
        L = max(L, np.sqrt(dx2))
        if f0 < 0:
            f0 = v
        else:
            e2 = 0.0
            for c in range(d):
                E[r, c] = P[v, c] - P[f0, c]
                e2 += E[r, c] * E[r, c]
            prod *= np.sqrt(e2)
            r += 1
    # normal by the generalised cross product: n_c = (-1)^c det(E without column c)
    nrm2 = 0.0
    dist = 0.0
    side = 0.0
    for c in range(d):
        for rr in range(d - 1):
            cc = 0
            for j in range(d):
                if j != c:
                    Mn[rr, cc] = E[rr, j]
                    cc += 1
        nc = _det_small(Mn, d - 1) if d > 1 else 1.0
        if c % 2 == 1:
            nc = -nc
        nrm2 += nc * nc
        dist += nc * (x[c] - P[f0, c])
        side += nc * (ctr[c] - P[f0, c])
    if not np.sqrt(nrm2) > _HULL_FLAT * prod:
        return np.inf, L
    if side < 0.0:
        dist = -dist
    return dist / np.sqrt(nrm2), L


@njit(cache=True, error_model="numpy", _nrt=False)
def _barycentric(P, S, s, x, d, E, rhs, lam, flat_tol):
    """Barycentric coordinates of x in simplex s into ``lam``; returns True
    (and leaves ``lam`` alone) if the simplex is (nearly) flat: its volume
    determinant is at most ``flat_tol`` times the product of its edge lengths
    from the first vertex."""
    v0 = S[s, 0]
    prod = 1.0
    for c in range(d):
        e2 = 0.0
        for r in range(d):
            E[r, c] = P[S[s, c + 1], r] - P[v0, r]
            e2 += E[r, c] * E[r, c]
        prod *= np.sqrt(e2)
    for r in range(d):
        rhs[r] = x[r] - P[v0, r]
    det = 1.0
    for c in range(d):
        p = c
        for r in range(c + 1, d):
            if abs(E[r, c]) > abs(E[p, c]):
                p = r
        if E[p, c] == 0.0:
            return True
        if p != c:
            for j in range(d):
                E[c, j], E[p, j] = E[p, j], E[c, j]
            rhs[c], rhs[p] = rhs[p], rhs[c]
        det *= E[c, c]
        for r in range(c + 1, d):
            f = E[r, c] / E[c, c]
            for j in range(c, d):
                E[r, j] -= f * E[c, j]
            rhs[r] -= f * rhs[c]
    if not abs(det) > flat_tol * prod:
        return True
    tot = 0.0
    for c in range(d - 1, -1, -1):
        acc = rhs[c]
        for j in range(c + 1, d):
            acc -= E[c, j] * lam[j + 1]
        lam[c + 1] = acc / E[c, c]
        tot += lam[c + 1]
    lam[0] = 1.0 - tot
    return False


@njit(cache=True, error_model="numpy", _nrt=False)
def _locate(P, S, NB, x, s, d, ctr, E, Mn, rhs, lam, tol, htol, flat_tol):
    """Visibility walk from simplex s to a simplex containing x (barycentric
    coordinates >= -tol). Returns ``(simplex, status)``: OK, OUTSIDE (beyond a
    hull facet by more than the hull tolerance; the simplex is that facet's)
    or OVERFLOW (the walk did not end; the caller searches exhaustively).
    A point just outside a hull facet, within the hull tolerance, is
    returned with that facet's simplex (the caller's hull test takes over)."""
    ns = S.shape[0]
    prev = -1
    for step in range(ns + 100):
        flat = _barycentric(P, S, s, x, d, E, rhs, lam, flat_tol)
        if flat:
            # a (nearly) flat simplex, whose barycentric coordinates mean
            # nothing (co-spherical nodes, slivers on the hull): step on
            k = step % (d + 1)
            for kk in range(d + 1):
                t = NB[s, (k + kk) % (d + 1)]
                if t >= 0 and t != prev:
                    break
            if t < 0:
                return s, OVERFLOW
            prev = s
            s = t
            continue
        k = 0
        for j in range(1, d + 1):
            if lam[j] < lam[k]:
                k = j
        if lam[k] >= -tol:
            return s, OK
        t = NB[s, k]
        if t < 0:
            dist, L = _hull_distance(P, S, s, k, x, d, ctr, E, Mn)
            if dist == np.inf:
                # a degenerate hull facet: trust the barycentric coordinate
                dist = lam[k] * L
            if dist >= -htol * L:
                return s, OK
            return s, OUTSIDE
        prev = s
        s = t
    return s, OVERFLOW


@njit(cache=True, error_model="numpy", _nrt=False)
def _locate_brute(P, S, x, d, E, rhs, lam, tol, flat_tol):
    """Exhaustive search for a simplex containing x (-1 if none)."""
    best = -1
    bestv = -np.inf
    for s in range(S.shape[0]):
        flat = _barycentric(P, S, s, x, d, E, rhs, lam, flat_tol)
        if flat:
            continue
        mn = lam[0]
        for j in range(1, d + 1):
            mn = min(mn, lam[j])
        if mn > bestv:
            bestv = mn
            best = s
    return best, bestv


@njit(cache=True, error_model="numpy", _nrt=False)
def _vertex_simplices(d, m, A, B, Tc, nT, rowof, E, rhs, lam, ztol, vtol):
    """Keep the rows of ``Tc[:nT]`` (d constraint ids each) whose d planes meet
    in a point that satisfies all m rows of ``A[0], B[0]`` within ``vtol``;
    returns their number."""
    rowof[0] = 0
    kept = 0
    for c in range(nT):
        for r in range(d):
            row = rowof[Tc[c, r]]
            for k in range(d):
                E[r, k] = A[0, row, k]
            rhs[r] = B[0, row]
        ok = True
        for cc in range(d):
            pv = cc
            for r in range(cc + 1, d):
                if abs(E[r, cc]) > abs(E[pv, cc]):
                    pv = r
            if not abs(E[pv, cc]) > ztol:
                ok = False
                break
            if pv != cc:
                for k in range(d):
                    E[cc, k], E[pv, k] = E[pv, k], E[cc, k]
                rhs[cc], rhs[pv] = rhs[pv], rhs[cc]
            for r in range(cc + 1, d):
                f = E[r, cc] / E[cc, cc]
                for k in range(cc, d):
                    E[r, k] -= f * E[cc, k]
                rhs[r] -= f * rhs[cc]
        if ok:
            for cc in range(d - 1, -1, -1):
                acc_ = rhs[cc]
                for k in range(cc + 1, d):
                    acc_ -= E[cc, k] * lam[k]
                lam[cc] = acc_ / E[cc, cc]
            for r in range(m):
                viol = -B[0, r]
                for k in range(d):
                    viol += A[0, r, k] * lam[k]
                if viol > vtol:
                    ok = False
                    break
        if ok:
            for k in range(d):
                Tc[kept, k] = Tc[c, k]
            kept += 1
    return kept


@njit(cache=True, error_model="numpy", _nrt=False)
def _region(P, S, NB, ctr, x, hint, d, stamp_q, itol, flat, htol, wtol, cached, CC, SH, smark,
            mark, cav, cst, live, bf, nn, Tc, zc, zq, E, Mn, rhs, lam, out_i, out_v, out_g):
    """Locate x, grow its conflict region and collect the natural neighbours
    ``nn[:K]`` (``live`` marks those with cells of positive volume), the
    boundary faces ``bf[:nbf]`` and the conflict simplices ``cav[:ncav]``
    (``Tc[:ncav]``: in local indices; ``zc[:ncav]``: their circumcentres
    relative to x; ``zq[:ncav]``: their signed shape measures, see
    :func:`_in_conflict`; ``smark[cav[c]] = stamp_q * (ccap + 1) + c``, ccap
    the length of ``cav``). Returns
    ``(status, info, ncav, K, nbf, degenerate)``; at a node writes the
    Kronecker delta into ``out_*``."""
    ccap = cav.shape[0]
    ncap = nn.shape[0]
    s0, st = _locate(P, S, NB, x, hint, d, ctr, E, Mn, rhs, lam, wtol, htol, flat)
    if st == OUTSIDE:
        return OUTSIDE, 0, 0, 0, 0, False
    if st == OVERFLOW:
        s0, _ = _locate_brute(P, S, x, d, E, rhs, lam, wtol, flat)
        if s0 < 0:
            return OUTSIDE, 0, 0, 0, 0, False
    # at a node: Kronecker delta
    for j in range(d + 1):
        v = S[s0, j]
        same = True
        for k in range(d):
            if P[v, k] != x[k]:
                same = False
                break
        if same:
            out_i[0] = v
            out_v[0] = 1.0
            for k in range(d):
                out_g[0, k] = np.nan
            return AT_NODE, 0, 0, 0, 0, False
    # conflict region by breadth-first search; smark: IN + c for the conflict
    # simplex c, OUT for a simplex tested and found out
    IN = stamp_q * (ccap + 1)
    OUT = IN + ccap
    code, shape = _in_conflict(P, S, s0, x, d, E, rhs, itol, flat, cached, CC, SH)
    if code == 0:
        # x is outside the circumsphere of s0, so outside s0 itself, which the
        # walk's tolerance accepted (within ~1e-12 of a vertex, closer than
        # the in-sphere test's round-off bound): the region would not grow
        # from there; walk on with no tolerance to the simplex holding x
        s1, st = _locate(P, S, NB, x, s0, d, ctr, E, Mn, rhs, lam, 0.0, htol, flat)
        if st == OVERFLOW:
            s1, _ = _locate_brute(P, S, x, d, E, rhs, lam, 0.0, flat)
        if st != OUTSIDE and s1 >= 0 and s1 != s0:
            s0 = s1
            code, shape = _in_conflict(P, S, s0, x, d, E, rhs, itol, flat, cached, CC, SH)
    cav[0] = s0
    cst[0] = max(1, code)
    zq[0] = shape
    for k in range(d):
        zc[0, k] = rhs[k] + (P[S[s0, 0], k] - x[k])
    smark[s0] = IN
    ncav = 1
    head = 0
    while head < ncav:
        s = cav[head]
        head += 1
        for k in range(d + 1):
            t = NB[s, k]
            if t < 0:
                dist, L = _hull_distance(P, S, s, k, x, d, ctr, E, Mn)
                if dist < -htol * L:
                    return OUTSIDE, s * (d + 1) + k, 0, 0, 0, False
                if dist <= htol * L:
                    return ON_HULL, s * (d + 1) + k, 0, 0, 0, False
                continue
            if IN <= smark[t] <= OUT:
                continue
            code, shape = _in_conflict(P, S, t, x, d, E, rhs, itol, flat, cached, CC, SH)
            if code > 0:
                if ncav == ccap:
                    return OVERFLOW, 0, 0, 0, 0, False
                cav[ncav] = t
                cst[ncav] = code
                zq[ncav] = shape
                for k in range(d):
                    zc[ncav, k] = rhs[k] + (P[S[t, 0], k] - x[k])
                smark[t] = IN + ncav
                ncav += 1
            else:
                smark[t] = OUT
    # natural neighbours (local indices through mark); only the nodes of
    # simplices strictly in conflict have cells of positive volume ("live")
    K = 0
    for c in range(ncav):
        for j in range(d + 1):
            v = S[cav[c], j]
            if mark[v] < 0:
                if K == ncap:
                    for jj in range(K):
                        mark[nn[jj]] = -1
                    return OVERFLOW, 0, 0, 0, 0, False
                mark[v] = K
                nn[K] = v
                live[K] = 0
                K += 1
            if cst[c] == 2:
                live[mark[v]] = 1
    # boundary faces of the conflict region (the new simplices are x + face)
    nbf = 0
    for c in range(ncav):
        s = cav[c]
        for k in range(d + 1):
            t = NB[s, k]
            if t >= 0 and IN <= smark[t] < OUT:
                continue
            if nbf == bf.shape[0]:
                for jj in range(K):
                    mark[nn[jj]] = -1
                return OVERFLOW, 0, 0, 0, 0, False
            r = 0
            for j in range(d + 1):
                if j != k:
                    bf[nbf, r] = mark[S[s, j]]
                    r += 1
            nbf += 1
    degenerate = False
    for c in range(ncav):
        if cst[c] != 2:
            degenerate = True
    # local indices of the conflict simplices, in place of node indices
    for c in range(ncav):
        for j in range(d + 1):
            Tc[c, j] = mark[S[cav[c], j]]  # scratch: rows 0..ncav-1 of Tc (d + 1 wide)
    for j in range(K):
        mark[nn[j]] = -1
    return OK, 0, ncav, K, nbf, degenerate


@njit(cache=True, error_model="numpy", _nrt=False)
def _cells3(S, NB, cav, ncav, smark, IN, Tc, zc, zq, K, q, qq, want_grad, ftol, pid,
            pu, pv, pS, pf, pt, zf, a0, vol, gv):
    """Second-order volumes ``vol[:K]`` (and their gradients ``gv[:K]``) of a
    3D query in general position, from the known combinatorics of its
    conflict region. Returns False (and leaves the work to :func:`_cell`)
    where a vertex would be ill-conditioned or the combinatorics are not
    those of general position.

    The faces of the cells are known: the cells of neighbours i < j share
    the polygon P_ij on the bisector of p_i and p_j (dual to the Delaunay
    edge ij of a conflict simplex), and cell i has the polygon F_i on the
    bisector of x and p_i (row 0, dual to the new edge x p_i). Their edges
    are dual to triangles: an interior face of the conflict region (from
    the circumcentre of one conflict simplex to the other's), a boundary face
    (from the conflict simplex's circumcentre to that of x and the face) and
    a new triangle x u v on a boundary edge uv (between the circumcentres
    of x and the two boundary faces holding uv). Every vertex is computed
    once (``zc``: conflict simplices, from the in-sphere test; ``zf``: x and
    a boundary face, by Cramer's rule); a vertex whose simplex has a shape
    measure (volume determinant over the product of its edge lengths) below
    ``ftol`` gives up.

    Lasserre's sum, with the cell's origin o_i = (x + p_i) / 2 on row 0:
    ``V_i = (1/3) sum_j beta_ij area(P_ij)``, ``beta_ij`` the distance of
    o_i from the plane of P_ij (facet 0 has ``beta = 0``), and in each
    polygon ``area = (1/2) sum_e gamma_e len_e`` over its edges, the base
    case ``len_e`` read off the edge's two end vertices:
    ``gamma_e len_e = n . ((v_1 - o) x (v_2 - o))`` (n: the polygon's unit
    normal, edges counterclockwise about it; the sum does not depend on the
    origin o in the plane, and the edge term ``v_1 x v_2`` is shared by the
    three polygons on the edge, with the orientation of the triangle). The
    gradient needs facet 0's area and first moment, by the same sum of
    degree 1: ``integral (y - o) dS = (1/3) sum_e gamma_e len_e m_e`` with
    ``m_e = (v_1 + v_2) / 2 - o``; on facet 0 the normal is parallel to
    ``o_i - x``, so there ``gamma_e len_e = n . (v_1 x v_2)`` with the
    vertices relative to x.

    Shapes: ``Tc[:ncav]`` (ncav, 4) local node indices, ``zc``/``zq`` and
    ``smark`` (``IN + c`` for the conflict simplex c) as filled by
    :func:`_region`, ``q[:K]`` (K, 3) neighbours relative to x,
    ``qq`` (K,) scratch; ``pid`` (ncap, ncap) all -1 (restored on return);
    polygon buffers ``pu, pv, pf, pt`` (npcap,), ``pS`` (npcap, 3), ``zf``
    (nfcap, 3); ``a0`` (K,) scratch.
    """
    ok = True
    for i in range(K):
        qq[i] = q[i, 0] * q[i, 0] + q[i, 1] * q[i, 1] + q[i, 2] * q[i, 2]
        vol[i] = 0.0
        a0[i] = 0.0
        for k in range(3):
            gv[i, k] = 0.0
    ftol2 = ftol * ftol
    npair = 0
    nb = 0
    pcap = pu.shape[0]
    for c in range(ncav):
        if not abs(zq[c]) > ftol:
            ok = False
            break
        s = cav[c]
        sgn = 1.0 if zq[c] > 0.0 else -1.0
        for k in range(4):
            t = NB[s, k]
            o = smark[t] - IN if t >= 0 else -1
            inner = 0 <= o < cav.shape[0]
            if inner and o < c:
                continue   # the other simplex did this face
            # the face's nodes sorted, i < j < l, and the orientation
            # eps of (p_i, p_j, p_l, p_a), p_a the simplex's other node
            # (and x: on the same side of the face)
            if k == 0:
                i, j, l = Tc[c, 1], Tc[c, 2], Tc[c, 3]
            elif k == 1:
                i, j, l = Tc[c, 0], Tc[c, 2], Tc[c, 3]
            elif k == 2:
                i, j, l = Tc[c, 0], Tc[c, 1], Tc[c, 3]
            else:
                i, j, l = Tc[c, 0], Tc[c, 1], Tc[c, 2]
            eps = sgn if k % 2 == 1 else -sgn
            if i > j:
                i, j = j, i
                eps = -eps
            if j > l:
                j, l = l, j
                eps = -eps
            if i > j:
                i, j = j, i
                eps = -eps
            if inner:
                y0, y1, y2 = zc[o, 0], zc[o, 1], zc[o, 2]
            else:
                # the circumcentre of x and the face (a new simplex)
                c0 = q[j, 1] * q[l, 2] - q[j, 2] * q[l, 1]
                c1 = q[j, 2] * q[l, 0] - q[j, 0] * q[l, 2]
                c2 = q[j, 0] * q[l, 1] - q[j, 1] * q[l, 0]
                det = q[i, 0] * c0 + q[i, 1] * c1 + q[i, 2] * c2
                # orient(p_i, p_j, p_l, x) = -sign(det) must be eps
                if not (det * det > ftol2 * qq[i] * qq[j] * qq[l] and det * eps < 0.0):
                    ok = False
                    break
                d0 = q[l, 1] * q[i, 2] - q[l, 2] * q[i, 1]
                d1 = q[l, 2] * q[i, 0] - q[l, 0] * q[i, 2]
                d2 = q[l, 0] * q[i, 1] - q[l, 1] * q[i, 0]
                e0 = q[i, 1] * q[j, 2] - q[i, 2] * q[j, 1]
                e1 = q[i, 2] * q[j, 0] - q[i, 0] * q[j, 2]
                e2 = q[i, 0] * q[j, 1] - q[i, 1] * q[j, 0]
                h = 0.5 / det
                y0 = (qq[i] * c0 + qq[j] * d0 + qq[l] * e0) * h
                y1 = (qq[i] * c1 + qq[j] * d1 + qq[l] * e1) * h
                y2 = (qq[i] * c2 + qq[j] * d2 + qq[l] * e2) * h
                if nb == zf.shape[0]:
                    ok = False
                    break
                zf[nb, 0] = y0
                zf[nb, 1] = y1
                zf[nb, 2] = y2
            # the edge runs from this simplex's circumcentre away from p_a:
            # counterclockwise in P_ij and P_jl iff eps < 0, reversed in P_il
            x0, x1, x2 = zc[c, 0], zc[c, 1], zc[c, 2]
            if eps > 0.0:
                x0, x1, x2, y0, y1, y2 = y0, y1, y2, x0, x1, x2
            r0 = x1 * y2 - x2 * y1
            r1 = x2 * y0 - x0 * y2
            r2 = x0 * y1 - x1 * y0
            for e in range(3):
                if e == 0:
                    u, v, sg = i, j, 1.0
                elif e == 1:
                    u, v, sg = j, l, 1.0
                else:
                    u, v, sg = i, l, -1.0
                p = pid[u, v]
                if p < 0:
                    if npair == pcap:
                        ok = False
                        break
                    p = npair
                    npair += 1
                    pid[u, v] = p
                    pu[p] = u
                    pv[p] = v
                    pf[p] = -1
                    pS[p, 0] = 0.0
                    pS[p, 1] = 0.0
                    pS[p, 2] = 0.0
                pS[p, 0] += sg * r0
                pS[p, 1] += sg * r1
                pS[p, 2] += sg * r2
                if inner:
                    continue
                # the boundary edge uv: the new triangle x u v, between the
                # circumcentres of x and the two boundary faces on uv;
                # tau = orient(p_u, p_v, p_w, x), p_w the face's third node
                tau = sg * eps
                g = pf[p]
                if g == -1:
                    pf[p] = nb
                    pt[p] = tau
                    continue
                if g < 0 or pt[p] == tau:
                    ok = False  # a third face on the edge, or not a surface
                    break
                if pt[p] > 0.0:
                    a, b = g, nb
                else:
                    a, b = nb, g
                w0 = zf[a, 1] * zf[b, 2] - zf[a, 2] * zf[b, 1]
                w1 = zf[a, 2] * zf[b, 0] - zf[a, 0] * zf[b, 2]
                w2 = zf[a, 0] * zf[b, 1] - zf[a, 1] * zf[b, 0]
                # counterclockwise in F_u: from the face with tau > 0; P_uv
                # lies on x's side of this edge, so it runs the other way there
                pS[p, 0] -= w0
                pS[p, 1] -= w1
                pS[p, 2] -= w2
                pf[p] = -2
                if want_grad:
                    # facet 0 of cell u and (reversed) of cell v: area terms
                    # n . (v_1 x v_2) with n || q
                    wu = q[u, 0] * w0 + q[u, 1] * w1 + q[u, 2] * w2
                    wv = q[v, 0] * w0 + q[v, 1] * w1 + q[v, 2] * w2
                    a0[u] += wu
                    a0[v] -= wv
                    for kk in range(3):
                        m = zf[a, kk] + zf[b, kk]
                        gv[u, kk] += wu * m
                        gv[v, kk] -= wv * m
            if not ok:
                break
            if not inner:
                nb += 1
        if not ok:
            break
    for p in range(npair):
        u = pu[p]
        v = pv[p]
        pid[u, v] = -1
        if pf[p] >= 0:
            ok = False  # a boundary edge on one face only
    if not ok:
        return False
    # Lasserre's sum over the facets: V_u += beta_uv area(P_uv) / 3 with
    # beta_uv = q_v . D / (2 |D|), D = q_v - q_u, area = D . S / (2 |D|)
    for p in range(npair):
        u = pu[p]
        v = pv[p]
        D0 = q[v, 0] - q[u, 0]
        D1 = q[v, 1] - q[u, 1]
        D2 = q[v, 2] - q[u, 2]
        sD = (D0 * pS[p, 0] + D1 * pS[p, 1] + D2 * pS[p, 2]) / (
            12.0 * (D0 * D0 + D1 * D1 + D2 * D2))
        vol[u] += (q[v, 0] * D0 + q[v, 1] * D1 + q[v, 2] * D2) * sD
        vol[v] -= (q[u, 0] * D0 + q[u, 1] * D1 + q[u, 2] * D2) * sD
    if want_grad:
        # grad V_i = (1 / |q_i|) integral over facet 0 of (y - x) dS
        #          = (sum_e w_e (v_1 + v_2) + a0 q_i / 2) / (6 |q_i|^2)
        for i in range(K):
            f = 1.0 / (6.0 * qq[i])
            for k in range(3):
                gv[i, k] = (gv[i, k] + 0.5 * a0[i] * q[i, k]) * f
    return True


@njit(cache=True, error_model="numpy", _nrt=False)
def _finish(K, d, nn, vol, gv, want_grad, raw, gc, out_i, out_v, out_g):
    """Coordinates (or raw volumes) and gradients of the K neighbours into
    ``out_*``, sorted by node index; returns ``(count, status, 0)``. ``gc``:
    scratch of length d."""
    # The dominant neighbour gets its gradient from complement sums,
    #   grad phi_d = (grad V_d (1 - phi_d) - phi_d sum_{j != d} grad V_j) / V,
    # which avoids cancelling two large terms close to node d.
    dom = 0
    for i in range(1, K):
        if vol[i] > vol[dom]:
            dom = i
    rest = 0.0
    for k in range(d):
        gc[k] = 0.0
    for i in range(K):
        if i != dom:
            rest += vol[i]
            if want_grad:
                for k in range(d):
                    gc[k] += gv[i, k]
    total = vol[dom] + rest
    if not total > 0.0:
        return 0, UNBOUNDED, 0
    cnt = 0
    for i in range(K):
        if vol[i] <= 0.0:
            continue
        phi = vol[i] / total
        out_i[cnt] = nn[i]
        out_v[cnt] = phi
        if raw:
            out_v[cnt] = vol[i]
        if want_grad:
            for k in range(d):
                if raw:
                    out_g[cnt, k] = gv[i, k]
                elif i == dom:
                    out_g[cnt, k] = (gv[i, k] * (rest / total) - phi * gc[k]) / total
                else:
                    out_g[cnt, k] = (gv[i, k] - phi * (gv[dom, k] + gc[k])) / total
        j = cnt
        while j > 0 and out_i[j - 1] > out_i[j]:
            out_i[j - 1], out_i[j] = out_i[j], out_i[j - 1]
            out_v[j - 1], out_v[j] = out_v[j], out_v[j - 1]
            for k in range(d):
                out_g[j - 1, k], out_g[j, k] = out_g[j, k], out_g[j - 1, k]
            j -= 1
        cnt += 1
    return cnt, OK, 0


@njit(cache=True, error_model="numpy", _nrt=False)
def _query(P, S, NB, ctr, x, hint, d, stamp_q, want_grad, kind, tols, cached, CC, SH, smark, mark,
           cav, cst, live, rowof, bf, nn, q, Tc, zc, zq, qq, pid, pu, pv, pS, pf, pt, zf,
           a0, tab, A, B, I, AX, BX, M, W, act, nact, mrows, cur, tpiv, acc, wm, gs, gc, gp,
           gq, rep, gmark, stamp, sc, flag, G, E, Mn, rhs, lam, vol, gv, out_i, out_v, out_g):
    """Sibson coordinates of one point x, searched for from simplex ``hint``.

    Writes up to ``nn.shape[0]`` entries into ``out_*`` (sorted by node
    index) and returns ``(count, status, info)``. ``kind`` 0: Sibson
    coordinates; 1: the second-order volumes V_i and their gradients instead;
    2: coordinates from the hull-facet weights ``integral over the cell of
    (|y - p_i|^2 - |y - x|^2) dy`` (for a point on a hull facet, in the
    facet's own coordinates). ``info`` is
    ``s * (d + 1) + k`` for the hull facet (s, k) of an ON_HULL point.
    ``stamp_q > 0`` must differ between the queries sharing ``smark``.
    3D queries in general position are done by :func:`_cells3`, the others
    (and those it gives up on) by the recursion of :func:`_cell`.
    """
    ztol, btol, itol, flat, htol, lintol, wtol, vtol = (tols[0], tols[1], tols[2], tols[3],
                                                        tols[4], tols[5], tols[6], tols[7])
    shape, lintol3, gradtol3, near3 = tols[8], tols[9], tols[10], tols[11]
    raw = kind == 1
    hullw = kind == 2
    st, info, ncav, K, nbf, degenerate = _region(
        P, S, NB, ctr, x, hint, d, stamp_q, itol, flat, htol, wtol, cached, CC, SH, smark, mark,
        cav, cst, live, bf, nn, Tc, zc, zq, E, Mn, rhs, lam, out_i, out_v, out_g)
    if st != OK:
        return (1 if st == AT_NODE else 0), st, info
    # coordinates relative to x
    L = 0.0
    for j in range(K):
        h2 = 0.0
        for k in range(d):
            q[j, k] = P[nn[j], k] - x[k]
            h2 += q[j, k] * q[j, k]
        L = max(L, np.sqrt(h2))
        if h2 == 0.0:
            # at a node after all (the walk ended in a simplex near it)
            out_i[0] = nn[j]
            out_v[0] = 1.0
            for k in range(d):
                out_g[0, k] = np.nan
            return 1, AT_NODE, 0
    # near a node (closer than _NEAR3 L) the cells of the other neighbours are
    # thin slabs: the recursion, with its origins on row 0 and vertices from
    # pairs of lines, keeps about twice the digits of their gradients there
    near = False
    for j in range(K):
        near = near or q[j, 0] * q[j, 0] + q[j, 1] * q[j, 1] + q[j, 2] * q[j, 2] < (
            near3 * L) ** 2
    if d == 3 and not hullw and not degenerate and not near:
        # general position: the cells' faces from the known combinatorics,
        # accepted if linear precision (and its derivative, sum_i q_i (x)
        # grad V_i = V I) hold tightly; otherwise the general recursion below
        if _cells3(S, NB, cav, ncav, smark, stamp_q * (cav.shape[0] + 1), Tc, zc, zq, K, q, qq,
                   want_grad,
                   shape, pid, pu, pv, pS, pf, pt, zf, a0, vol, gv):
            # every neighbour has a cell of positive volume here (a vertex
            # of a simplex strictly in conflict); one that rounds to zero
            # or below is left to the recursion
            total = 0.0
            good = True
            for i in range(K):
                total += vol[i]
                if not vol[i] > 0.0:
                    good = False
            for k in range(d):
                s = 0.0
                for i in range(K):
                    s += vol[i] * q[i, k]
                if not abs(s) <= lintol3 * total * L:
                    good = False
            if good and want_grad:
                scale = 0.0
                for i in range(K):
                    scale += max(abs(q[i, 0]), abs(q[i, 1]), abs(q[i, 2])) * max(
                        abs(gv[i, 0]), abs(gv[i, 1]), abs(gv[i, 2]))
                for k in range(d):
                    for kk in range(d):
                        s = -total if k == kk else 0.0
                        for i in range(K):
                            s += q[i, k] * gv[i, kk]
                        if not abs(s) <= gradtol3 * scale:
                            good = False
            if good:
                return _finish(K, d, nn, vol, gv, want_grad, raw, rhs, out_i, out_v, out_g)
    for mode in range(3):
        # strict combinatorial filter, relaxed filter, no filter (safety nets)
        full = mode == 2
        strict = mode == 0
        flag[0] = 0
        for i in range(K):
            if live[i] == 0:
                # an empty cell (the node is only on simplices whose sphere
                # passes through x, or flat ones)
                vol[i] = 0.0
                for k in range(d):
                    gv[i, k] = 0.0
                for j in range(K):
                    tab[i, j] = 0.0
                continue
            # the simplices whose circumcentres are vertices of cell i, as rows
            # of constraint ids (0: x, j + 1: neighbour j), after the conflict
            # simplices' local indices in Tc[:ncav]
            nT = 0
            base = ncav
            if not full:
                for c in range(ncav):
                    pos = -1
                    for j in range(d + 1):
                        if Tc[c, j] == i:
                            pos = j
                    if pos < 0:
                        continue
                    if base + nT == Tc.shape[0]:
                        return 0, OVERFLOW, 0
                    r = 0
                    for j in range(d + 1):
                        if j != pos:
                            Tc[base + nT, r] = Tc[c, j] + 1
                            r += 1
                    nT += 1
                for c in range(nbf):
                    pos = -1
                    for j in range(d):
                        if bf[c, j] == i:
                            pos = j
                    if pos < 0:
                        continue
                    if base + nT == Tc.shape[0]:
                        return 0, OVERFLOW, 0
                    Tc[base + nT, 0] = 0
                    r = 1
                    for j in range(d):
                        if j != pos:
                            Tc[base + nT, r] = bf[c, j] + 1
                            r += 1
                    nT += 1
                # the constraints: every id in those simplices
                sc[0] += 1
                for c in range(nT):
                    for j in range(d):
                        stamp[Tc[base + c, j]] = sc[0]
            # Row 0: closer to x than to p_i; then closer to p_i than to p_j.
            # The origin is the midpoint o = (x + p_i) / 2, on the plane of
            # row 0: near a node p_k the cells of the other neighbours are
            # slabs of width ~ |x - p_k| between two nearly parallel planes,
            # and an origin at x would make Lasserre's sum cancel terms of
            # size one down to that width.
            h = 0.0
            for k in range(d):
                h += q[i, k] * q[i, k]
            h = np.sqrt(h)
            for k in range(d):
                A[0, 0, k] = q[i, k] / h
            B[0, 0] = 0.0
            I[0, 0] = 0
            m = 1
            for j in range(K):
                if j == i or (not full and stamp[j + 1] != sc[0]):
                    continue
                nrm2 = 0.0
                bb = 0.0
                for k in range(d):
                    a = q[j, k] - q[i, k]
                    A[0, m, k] = a
                    nrm2 += a * a
                    bb += a * q[j, k]
                nrm = np.sqrt(nrm2)
                for k in range(d):
                    A[0, m, k] /= nrm
                B[0, m] = 0.5 * bb / nrm
                I[0, m] = j + 1
                rowof[j + 1] = m
                # the plane x|p_j, about the same origin o = q_i / 2
                hj = 0.0
                ao = 0.0
                for k in range(d):
                    hj += q[j, k] * q[j, k]
                hj = np.sqrt(hj)
                for k in range(d):
                    AX[m, k] = q[j, k] / hj
                    ao += AX[m, k] * q[i, k]
                BX[m] = 0.5 * hj - 0.5 * ao
                m += 1
            if not full and degenerate:
                # Flat or borderline simplices in the conflict region can give
                # simplices whose circumcentre is no vertex of the cell, and
                # the filter needs every listed simplex to be one: keep those
                # whose d planes meet in a point that satisfies all the rows.
                nT = _vertex_simplices(d, m, A, B, Tc[base:], nT, rowof, E, rhs, lam, ztol,
                                       vtol * L)
            cell = i
            if hullw:
                cell = -1
            v = _cell(d, m, A, B, I, AX, BX, M, W, Tc[base:], nT, act, nact, mrows, cur, tpiv, acc,
                      wm, gs, gc, gp, gq, rep, gmark, stamp, sc, full, strict, want_grad,
                      hullw, G, ztol, btol * L, flag, cell, tab)
            if hullw:
                # limit weight on a hull facet: integral over the cell of
                # |y - p_i|^2 - |y - x|^2 = -2 q_i . (y - o)
                v = 0.0
                for k in range(d):
                    v -= 2.0 * q[i, k] * M[0, k]
            vol[i] = max(v, 0.0)
            if want_grad:
                # grad V_i = (1 / h) integral over facet 0 of (y - x) dS, with
                # G = integral of (y - o) dS and G[d] the facet's area
                for k in range(d):
                    gv[i, k] = (G[k] + 0.5 * q[i, k] * G[d]) / h
        if flag[0] != 0:
            continue
        # check linear precision, sum_i V_i (p_i - x) = 0: a violated
        # combinatorial filter (never seen) would show here; redo unfiltered
        total = 0.0
        lin = 0.0
        for k in range(d):
            s = 0.0
            for i in range(K):
                s += vol[i] * q[i, k]
            lin = max(lin, abs(s))
        for i in range(K):
            total += vol[i]
        if total > 0.0 and lin <= lintol * total * L:
            break
    if flag[0] != 0:
        return 0, UNBOUNDED, 0
    return _finish(K, d, nn, vol, gv, want_grad, raw, rhs, out_i, out_v, out_g)


@njit(cache=True, error_model="numpy", _nrt=False)
def _block(lo, hi, P, S, NB, ctr, Q, start, d, want_grad, kind, tols, cached, CC, SH, smark,
           mark, cav, cst, live, rowof, bf, nn, q, Tc, zc, zq, qq, pid, pu, pv, pS, pf, pt,
           zf, a0, tab, A, B, I, AX, BX, M, W, act, nact, mrows, cur, tpiv, acc, wm, gs, gc, gp,
           gq, rep, gmark, stamp, sc, flag, G, E, Mn, rhs, lam, vol, gv, oi, ov, og, out_i,
           out_v, out_g, count, status, info):
    """Queries lo..hi-1 of ``Q`` with one set of buffers (see :func:`_query`)
    into rows of the padded outputs; a query with more entries than a row
    holds gets status OVERFLOW (redone with larger buffers)."""
    width = out_i.shape[1]
    for r in range(lo, hi):
        cnt, st, inf = _query(P, S, NB, ctr, Q[r], start[r], d, r + 1, want_grad, kind, tols,
                              cached, CC, SH, smark, mark, cav, cst, live, rowof, bf, nn, q, Tc,
                              zc, zq, qq, pid, pu, pv, pS, pf, pt, zf, a0, tab, A, B, I,
                              AX, BX, M, W, act, nact, mrows, cur, tpiv, acc, wm, gs, gc, gp, gq,
                              rep, gmark, stamp, sc, flag, G, E, Mn, rhs, lam, vol, gv, oi, ov,
                              og)
        if cnt > width:
            cnt, st, inf = 0, OVERFLOW, 0
        count[r] = cnt
        status[r] = st
        info[r] = inf
        for j in range(cnt):
            out_i[r, j] = oi[j]
            out_v[r, j] = ov[j]
            if want_grad:
                for k in range(d):
                    out_g[k, r, j] = og[j, k]


@njit(cache=True, parallel=True, error_model="numpy")
def _query_batch(P, S, NB, Q, start, want_grad, kind, ncap, ccap, nblocks, tols, cached, CC, SH,
                 out_i, out_v, out_g, count, status, info):
    """Coordinates of m points into padded (m, ncap) arrays, parallel over blocks."""
    m = Q.shape[0]
    n = P.shape[0]
    d = P.shape[1]
    ns = S.shape[0]
    ctr = np.zeros(d)
    for v in range(n):
        for k in range(d):
            ctr[k] += P[v, k]
    for k in range(d):
        ctr[k] /= n
    for blk in prange(nblocks):
        lo = blk * m // nblocks
        hi = (blk + 1) * m // nblocks
        smark = np.zeros(ns, np.int64)
        mark = np.full(n, -1, np.int64)
        cav = np.empty(ccap, np.int64)
        cst = np.empty(ccap, np.int64)
        live = np.empty(ncap, np.int64)
        rowof = np.empty(ncap + 1, np.int64)
        bf = np.empty((2 * ccap, d), np.int64)
        nn = np.empty(ncap, np.int64)
        q = np.empty((ncap, d))
        Tc = np.empty((4 * ccap, d + 1), np.int64)
        zc = np.empty((ccap, d))
        zq = np.empty(ccap)
        qq = np.empty(ncap)
        pid = np.full((ncap, ncap), -1, np.int64)
        pu = np.empty(6 * ccap, np.int64)
        pv = np.empty(6 * ccap, np.int64)
        pS = np.empty((6 * ccap, d))
        pf = np.empty(6 * ccap, np.int64)
        pt = np.empty(6 * ccap)
        zf = np.empty((2 * ccap, d))
        a0 = np.empty(ncap)
        tab = np.empty((ncap, ncap))
        A = np.empty((d, ncap + 1, d))
        B = np.empty((d, ncap + 1))
        I = np.empty((d, ncap + 1), np.int64)
        AX = np.empty((ncap + 1, d))
        BX = np.empty(ncap + 1)
        M = np.empty((d, d))
        W = np.zeros((d, d))
        act = np.empty((d, 3 * ccap), np.int64)
        nact = np.empty(d, np.int64)
        mrows = np.empty(d, np.int64)
        cur = np.empty(d, np.int64)
        tpiv = np.empty(d, np.int64)
        acc = np.empty(d)
        wm = np.zeros(d, np.bool_)
        gs = np.empty((d, ncap + 1), np.int64)
        gc = np.empty((d, ncap + 1), np.int64)
        gp = np.empty((d, ncap + 1), np.int64)
        gq = np.empty(ncap + 1, np.int64)
        rep = np.empty(ncap + 1, np.int64)
        gmark = np.zeros(ncap + 1, np.int64)
        stamp = np.zeros(ncap + 1, np.int64)
        sc = np.zeros(1, np.int64)
        flag = np.zeros(1, np.int64)
        G = np.empty(d + 1)
        E = np.empty((d, d))
        Mn = np.empty((d, d))
        rhs = np.empty(d)
        lam = np.empty(d + 1)
        vol = np.empty(ncap)
        gv = np.empty((ncap, d))
        oi = np.empty(ncap, np.int64)
        ov = np.empty(ncap)
        og = np.empty((ncap, d))
        _block(lo, hi, P, S, NB, ctr, Q, start, d, want_grad, kind, tols, cached, CC, SH, smark,
               mark, cav, cst, live, rowof, bf, nn, q, Tc, zc, zq, qq, pid, pu, pv, pS, pf,
               pt, zf, a0, tab, A, B, I, AX, BX, M, W, act, nact, mrows, cur, tpiv, acc, wm, gs,
               gc, gp, gq, rep, gmark, stamp, sc, flag, G, E, Mn, rhs, lam, vol, gv, oi, ov, og,
               out_i, out_v, out_g, count, status, info)


_query_batch_serial = serial_twin(_query_batch, error_model="numpy")
# queries per batch from which the parallel kernel is used (a 3D query costs
# ~50 us, a 2D one ~7 us: a few thousand amortise the thread pool's wake-up)
_PARALLEL_MIN = 2000


# ---------------------------------------------------------------------------
# Python orchestration
# ---------------------------------------------------------------------------

def _circumcentre_cache(P, S, m):
    """``(cached, CC, SH)`` for the kernels: the circumcentres and shape
    measures of all simplices (:func:`_circumcentres`) when m queries will
    probably test most of them (each tests ~40 in 3D), else empty arrays."""
    ns, d = S.shape[0], P.shape[1]
    if _CACHE_QUERIES * m < ns:
        return False, np.empty((0, d)), np.empty(0)
    CC = np.empty((ns, d))
    SH = np.empty(ns)
    _circumcentres(P, S, _FLAT, CC, SH)
    return True, CC, SH


def _run(P, S, NB, Q, start, gradient, kind, caps, cache=None, out=None):
    """Run the kernel on a batch with buffer sizes ``caps`` (see ``_CAPS``);
    returns ((rows, cols, values, gradients), status, info). ``cache``:
    :func:`_circumcentre_cache` (computed here if None); ``out``: padded
    output buffers ``(out_i, out_v, out_g)`` of at least m rows and the
    width ``caps[2]`` to reuse (allocated here if None)."""
    import numba
    m, d = Q.shape
    ncap, ccap, width = caps
    if cache is None:
        cache = _circumcentre_cache(P, S, m)
    if out is None or out[0].shape[0] < m or out[0].shape[1] != width:
        out = _out_buffers(m, d, width, gradient)
    out_i, out_v = out[0][:m], out[1][:m]
    out_g = out[2][:d * m * width].reshape(d, m, width) if gradient else out[2]
    count = np.empty(m, np.int64)
    status = np.empty(m, np.int64)
    info = np.empty(m, np.int64)
    tols = np.array([_ZERO_ROW, _TIE, _INSPHERE, _FLAT, _HULL, _LINEAR, _WALK, _VERTEX,
                     _SHAPE, _LINEAR3, _GRAD3, _NEAR3])
    nblocks = max(1, min(m // 16, 4 * numba.get_num_threads()))
    # small batches run serially: waking the thread pool costs more than it saves
    kernel = _query_batch if m >= _PARALLEL_MIN else _query_batch_serial
    kernel(P, S, NB, Q, start, gradient, kind, ncap, ccap, nblocks, tols, *cache,
           out_i, out_v, out_g, count, status, info)
    _, indices, data, grads = compress(count, out_i, out_v, out_g, gradient, P.shape[0])
    rows = np.repeat(np.arange(m), count)
    return (rows, indices, data, grads), status, info


def _out_buffers(m, d, width, gradient):
    """Padded kernel outputs for m queries of up to ``width`` entries (the
    gradients' flat, viewed as (d, m', width) for m' <= m queries)."""
    return (np.empty((m, width), np.int64), np.empty((m, width)),
            np.empty(d * m * width if gradient else (d, 1, 1)))


def _facet_planes(p, S, facets):
    """Unit normals (pointing out of the hull) and offsets, n . y = c, of the
    hull facets ``s * (d + 1) + k`` (the facet opposite vertex k of simplex s)."""
    d = p.shape[1]
    s, k = np.divmod(np.asarray(facets, np.int64), d + 1)
    keep = np.ones((s.size, d + 1), bool)
    keep[np.arange(s.size), k] = False
    F = S[s][keep].reshape(s.size, d)
    E = p[F[:, 1:]] - p[F[:, :1]]
    normal = np.linalg.svd(E)[2][:, -1]
    off = (normal * p[F[:, 0]]).sum(1)
    flip = normal @ p.mean(axis=0) > off
    normal[flip] *= -1
    off[flip] *= -1
    return normal, off, F


def _on_hull(p, tri, Q, facets):
    """Coordinates of points on the boundary of the convex hull, as the limits
    of the coordinates from inside. Returns a CSR matrix (m, n).

    ``facets[r]`` names a hull facet whose plane query r lies on (from the
    query kernel). On a face of the hull of codimension k only the nodes on
    that face get weights, ``integral over C_i of (|y - p_i|^2 - |y - x|^2)^k
    dy``, where C_i is the second-order Voronoi cell of x and p_i among the
    face's nodes in the face's own dimension: as x approaches the face, its
    Voronoi cell becomes a spike whose sections are power diagrams of the
    face's nodes, and integrating over the spike gives these weights. So

    - inside a facet (k = 1) the weights come from the Lasserre recursion
      with first moments (kind 2 of the query kernel), in the facet's
      coordinates; with only d nodes on the facet they are its barycentric
      coordinates;
    - on a hull edge (dimension 1) they reduce to linear interpolation
      between the two nodes around x, for every k (as on hull edges in 2D);
    - on a 2-face of a 4D hull (k = 2) the limit is extrapolated from two
      points just inside (Richardson; error about 1e-12).

    These are not the (d-1)-dimensional Sibson coordinates of the facet's
    nodes (those would weigh C_i by its area alone).
    """
    m, d = Q.shape
    n = p.shape[0]
    S = np.ascontiguousarray(tri.simplices, dtype=np.int64)
    normal, off, F = _facet_planes(p, S, facets)
    diam = np.ptp(p, axis=0).max()
    tol = 1e-9 * diam
    key = np.round(np.c_[normal, off / diam] * 1e8).astype(np.int64)
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    hull_nodes = np.unique(np.asarray(tri.convex_hull))
    rows, cols, vals = [], [], []
    for g, f in enumerate(first):
        rs = np.flatnonzero(inverse.ravel() == g)
        x = Q[rs]
        nodes = hull_nodes[np.abs(p[hull_nodes] @ normal[f] - off[f]) <= tol]
        f0 = p[nodes[0]]
        basis = np.linalg.svd(normal[f][None, :])[2][1:].T  # the plane's directions
        pn = np.ascontiguousarray((p[nodes] - f0) @ basis)
        xn = (x - f0) @ basis
        if d == 2:
            H = _linear_on_line(pn[:, 0], xn[:, 0])
        elif nodes.size == d:
            # a simplex facet: the limit has linear precision, so barycentric
            lam = np.linalg.solve((pn[1:] - pn[0]).T[None], (xn - pn[0])[..., None])[..., 0]
            lam = np.clip(np.c_[1.0 - lam.sum(1), lam], 0.0, None)
            H = sp.csr_matrix(lam / lam.sum(1, keepdims=True))
        else:
            ftri = triangulate(pn)
            H, status, info = _coordinates(pn, xn, False, ftri, "nan", 2, hull_status=True)
            edge = np.flatnonzero(status == ON_HULL)
            if edge.size:
                H = H.tolil()
                # on the boundary of the facet: in 3D an edge, linear along it;
                # in 4D extrapolated, on the nodes of the lower face only
                E = _on_hull(pn, ftri, xn[edge], info[edge])
                if d == 4:
                    R = _extrapolate_to_hull(p, tri, x[edge], nodes)[:, nodes].toarray()
                    R *= E.toarray() != 0.0
                    E = sp.csr_matrix(R / R.sum(axis=1, keepdims=True))
                H[edge] = E
                H = H.tocsr()
        H = H.tocoo()
        rows.append(rs[H.row])
        cols.append(nodes[H.col])
        vals.append(H.data)
    R = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                      shape=(m, n))
    R.eliminate_zeros()
    R.sort_indices()
    return R


def _linear_on_line(u, t):
    """Linear interpolation weights at t between the nodes u on a line (CSR)."""
    order = np.argsort(u)
    us = u[order]
    j = np.clip(np.searchsorted(us, t, side="right") - 1, 0, us.size - 2)
    w = np.clip((t - us[j]) / (us[j + 1] - us[j]), 0.0, 1.0)
    r = np.arange(t.size)
    return sp.csr_matrix((np.r_[1.0 - w, w], (np.r_[r, r], np.r_[order[j], order[j + 1]])),
                         shape=(t.size, u.size))


def _extrapolate_to_hull(p, tri, x, nodes):
    """Coordinates on the hull by Richardson extrapolation from two points just
    inside, towards the centroid, keeping only the given face nodes."""
    n = p.shape[0]
    diam = np.ptp(p, axis=0).max()
    v = p.mean(axis=0) - x
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    t = 1e-8 * diam
    F1 = _coordinates(p, x + t * v, False, tri, "nan", 0)
    F2 = _coordinates(p, x + 2 * t * v, False, tri, "nan", 0)
    F = (2 * F1 - F2).toarray()[:, nodes]
    F = np.maximum(F, 0.0)
    F /= F.sum(axis=1, keepdims=True)
    F = sp.coo_matrix(F)
    return sp.csr_matrix((F.data, (F.row, nodes[F.col])), shape=(x.shape[0], n))


def _coordinates(p, q, gradient, tri, undefined, kind, hull_status=False, chunk=1 << 15):
    """Coordinates (kind 0), second-order volumes (1) or hull-facet weights (2)
    of the points q; see :func:`sibson_coordinates_nd`."""
    d = p.shape[1]
    if tri is None:
        tri = triangulate(p)
    m, n = q.shape[0], p.shape[0]
    S = np.ascontiguousarray(tri.simplices, dtype=np.int64)
    NB = np.ascontiguousarray(tri.neighbors, dtype=np.int64)
    # start each walk from a simplex at the nearest node (scipy's find_simplex
    # is avoided: its first call computes barycentric transforms through
    # LAPACK, which is very slow with a multithreaded BLAS)
    if m:
        near = cKDTree(p).query(q)[1]
        start = np.ascontiguousarray(tri.vertex_to_simplex[near], dtype=np.int64)
    else:
        start = np.zeros(0, np.int64)
    status = np.full(m, OUTSIDE, np.int64)
    info = np.zeros(m, np.int64)
    parts = []
    cache = _circumcentre_cache(p, S, m)
    # chunks bound the padded output buffers (d + 2 numbers per neighbour slot),
    # which the chunks reuse
    out = _out_buffers(min(m, chunk), d, _CAPS[d][2], gradient)
    for c0 in range(0, m, chunk):
        todo = np.arange(c0, min(m, c0 + chunk))
        caps = _CAPS[d]
        while todo.size:
            (r, c, v, g), st, inf = _run(p, S, NB, np.ascontiguousarray(q[todo]), start[todo],
                                         gradient, kind, caps, cache, out)
            status[todo] = st
            info[todo] = inf
            parts.append((todo[r], c, v, g))
            # rare: more natural neighbours or conflict simplices than the buffers
            # hold (co-spherical clusters); redo those with larger buffers
            todo = todo[st == OVERFLOW]
            caps = tuple(4 * c for c in caps)
    raise_outside(status, q)
    bad = np.flatnonzero(status == UNBOUNDED)
    if bad.size:  # pragma: no cover - a bounded cell is guaranteed inside the hull
        raise ValueError(
            f"second-order Voronoi cells of {bad.size} query point(s) came out unbounded; "
            f"first is x[{bad[0]}] = {q[bad[0]].tolist()}")
    hull = np.flatnonzero(status == ON_HULL)
    if hull.size and not hull_status:
        H = _on_hull(p, tri, q[hull], info[hull]).tocoo()
        parts.append((hull[H.row], H.col, H.data, np.full((d, H.nnz), np.nan)))
    # one COO -> CSR conversion per matrix from the same (row, col) arrays:
    # all matrices get the same pattern, rows sorted by column index
    if not parts:
        parts = [(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0), np.zeros((d, 0)))]

    def joined(k, axis=0):
        return parts[0][k] if len(parts) == 1 else np.concatenate([a[k] for a in parts], axis)

    rows, cols = joined(0), joined(1)
    vals = [joined(2)]
    if gradient:
        vals += list(joined(3, axis=1))
    indptr = np.zeros(m + 1, np.int64)
    np.cumsum(np.bincount(rows, minlength=m), out=indptr[1:])
    idx_dtype = index_dtype(n, rows.size)
    indptr = indptr.astype(idx_dtype)
    # every row comes from one part, sorted by column, and the kernel's rows
    # come in order: only redone (overflow) and hull rows need moving, and a
    # stable sort by row (nearly sorted data) does it
    if np.all(rows[1:] >= rows[:-1]):
        indices = cols.astype(idx_dtype, copy=False)
    else:
        order = np.argsort(rows, kind="stable")
        indices = cols[order].astype(idx_dtype)
        vals = [v[order] for v in vals]
    mats = [sp.csr_matrix((v, indices, indptr), shape=(m, n)) for v in vals]
    if hull_status:
        return mats[0], status, info
    if gradient and undefined == "raise":
        raise_undefined(status, q, p, "the convex hull")
    return (mats[0], mats[1:]) if gradient else mats[0]


def sibson_coordinates_nd(nodes, x, gradient: bool = False, delaunay=None,
                          undefined: Literal["raise", "nan"] = "raise", chunk: int = 1 << 15,
                          *, _raw=False):
    """Sibson natural-neighbour coordinates (and gradients) in 2, 3 or 4 dimensions.

    Volumes of second-order Voronoi cells by Lasserre's recursive formula
    (the paper's Box 1); see the module docstring for the method.

    Parameters
    ----------
    nodes
        (n, d) node coordinates, d = 2, 3 or 4.
    x
        (m, d) query points inside the convex hull of the nodes (its boundary
        included).
    gradient
        Also return the gradients.
    delaunay
        Optional :class:`scipy.spatial.Delaunay` of ``nodes`` to reuse.
    undefined
        What to do when gradients are requested at a node or on the convex
        hull, where they are not defined: ``"raise"`` a ``ValueError`` naming
        the query, or give that row NaN gradients.
    chunk
        Queries are processed in chunks of this many points (bounds memory).

    Returns
    -------
    Phi : scipy.sparse.csr_matrix, shape (m, n)
        ``Phi[q, i] = phi_i(x_q)``, rows sorted by column index.
    dPhi : list of d csr_matrix, shape (m, n)
        Only with ``gradient=True``: ``dPhi[k][q, i] = d phi_i / d x_k (x_q)``,
        same sparsity pattern as ``Phi``.

    Raises
    ------
    ValueError
        For non-finite, too few, duplicate or flat (degenerate) nodes,
        non-finite queries, queries outside the convex hull (naming the first
        and the count) and gradients at nodes or on the hull with
        ``undefined="raise"``.

    Notes
    -----
    ``_raw=True`` (for tests) returns the second-order volumes ``V_i`` and
    their gradients instead, for points inside the hull and off the nodes.
    """
    p = check_nodes(nodes)
    if undefined not in ("raise", "nan"):
        raise ValueError(f"undefined must be 'raise' or 'nan', got {undefined!r}")
    q = check_queries(x, p.shape[1])
    if delaunay is not None:
        check_delaunay(delaunay, p)
        tri = delaunay
    else:
        tri = delaunay_of(p)
    if not (isinstance(chunk, (int, np.integer)) and chunk > 0):
        raise ValueError(f"chunk must be a positive integer, got {chunk!r}")
    return _coordinates(p, q, gradient, tri, undefined, 1 if _raw else 0, chunk=int(chunk))
