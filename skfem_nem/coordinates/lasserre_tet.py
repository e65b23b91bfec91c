"""3D cells from the known combinatorics of the conflict region (general position).

The faces from the combinatorics (:func:`cells_3d`)
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

"""
from __future__ import annotations

from numba import njit

__all__ = ["cells_3d"]


@njit(cache=True, error_model="numpy", _nrt=False)
def cells_3d(S, NB, cav, ncav, smark, IN, Tc, zc, zq, K, q, qq, want_grad, ftol, pid,
             pu, pv, pS, pf, pt, zf, a0, vol, gv):
    """Second-order volumes ``vol[:K]`` (and their gradients ``gv[:K]``) of a
    3D query in general position, from the known combinatorics of its
    conflict region. Returns False (and leaves the work to :func:`lasserre_cell`)
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
    :func:`conflict_region`, ``q[:K]`` (K, 3) neighbours relative to x,
    ``qq`` (K,) scratch; ``pid`` (ncap, ncap) all -1 (restored on return);
    polygon buffers ``pu, pv, pf, pt`` (npcap,), ``pS`` (npcap, 3), ``zf``
    (nfcap, 3); ``a0`` (K,) scratch.
    """
    # Long kernel: the vertices, edges and polygons of all cells are built in one sweep over
    # the conflict region, sharing every vertex and edge term between the three cells that
    # meet there; separate passes would recompute or store them.
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
