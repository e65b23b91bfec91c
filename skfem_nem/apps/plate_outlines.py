"""The sinking plate's outline: one polygon of nodes until the plate breaks, then one
per piece.

The plate is the region inside its outline, a closed loop of nodes that moves with the
flow (kept as segments of the mesh). A weak plate pressed onto the bottom arches and
necks; where the neck thins until its two faces meet (a film of plate between two
outline segments closes within any step, :func:`~.plate_time_step.film_dt`), the plate
breaks, and the model follows: :meth:`PlateOutlines.pinch` cuts the loop in two there.
Of the two nodes that meet, a and b, one piece keeps both (its new segment b-a crosses
the neck) and the other closes with a segment between their outer neighbours, so the
pieces share no node and the fluid between them opens as they separate; what the cut
takes from the plate (a sliver one film thick) the area constraint gives back, piece by
piece, over the next steps. A node left closer than :data:`PINCH_FRACTION` of the
outline's spacing to the other end of its new segment is removed with it.

Where the plate folds onto itself instead (two faces meet from outside, across the
fluid the fold encloses), the same cut would leave the enclosed fluid as a loop of its
own. The fold is closed instead (:meth:`PlateOutlines.pinch`, a weld): of the two arcs
of the loop between the outer ends of the segments that met, the one around the pocket
is released (its fluid, and the film between those segments, joins the plate) and the
other, closed by a segment between those ends, is the plate's loop. Both segments that
met are released, so they cannot cross afterwards. With the pocket, the plate's area
(all pieces) stays within :data:`FOLD_AREA_TOLERANCE` above its reference area (the
area constraint then squeezes the pocket out over the next steps); a larger fold stops
the run.

Where two pieces meet (a film of fluid between two pieces closes), they are joined
(:meth:`PlateOutlines.pinch` again): the two segments that met are released and their
ends joined crosswise, so the two loops become one and the film joins the plate; the
piece's reference area is the two pieces' together. The segments' facing ends must be
closer than the outline's spacing, and the plate's area with the film within
:data:`FOLD_AREA_TOLERANCE` above its reference area.

Where the two faces that meet are a few nodes apart along the loop (a spike: a sliver
of plate, or a crack of fluid, thinner than the mesh resolves, closing within one step),
a cut would leave a piece of fewer than three nodes or one of at most
:data:`WELD_FRACTION` of the plate's area, a sliver squeezed again in the next steps. The
spike is closed instead: the arc around it is released, the nodes at its tip removed,
and a segment joins its ends; the sliver is at most :data:`WELD_FRACTION` of the piece's
area.
"""
from __future__ import annotations

from typing import List, Optional

import numpy as np

from ..geometry.constrained import pair_keys
from ..geometry.polylines import segments_cross

__all__ = ["PlateOutlines", "polygon_area_centroid", "PINCH_FRACTION", "WELD_FRACTION",
           "FOLD_AREA_TOLERANCE"]

#: after a cut, a node closer than this fraction of the outline's spacing to the node at
#: the other end of its new segment is removed (the two met as the neck closed; kept,
#: they would bound a triangle as thin as the closed film)
PINCH_FRACTION = 0.25
#: a spike (a sliver of plate or of fluid, a few nodes along the loop) is closed only if
#: its area is at most this fraction of the piece's reference area, and a piece cut off
#: at a neck is followed only if it is larger (a smaller one is closed as a spike): half
#: the 1% to which the plate's area is held
WELD_FRACTION = 0.005
#: a fold is closed (its pocket of fluid joins the plate) only if the plate's area, all
#: pieces together and the pocket joined, stays within this fraction above its reference
#: area: the 1% to which the plate's area is held (the area constraint then squeezes the
#: pocket out over the next steps)
FOLD_AREA_TOLERANCE = 0.01


def polygon_area_centroid(P):
    """Signed area and centroid of the closed polygon P (k, 2)."""
    x, y = P[:, 0], P[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    c = x * yn - xn * y
    A = 0.5 * c.sum()
    return A, np.array([((x + xn) * c).sum(), ((y + yn) * c).sum()]) / (6 * A)


def crossings(polygons) -> int:
    """Number of pairs of edges of the closed polygons (each (k, 2)) that cross, edges
    of one polygon that share a node not counted."""
    ends = [(P, np.roll(P, -1, axis=0)) for P in polygons]
    count = 0
    for m, (P, Q) in enumerate(ends):
        k = P.shape[0]
        for i in range(k - 2):
            j = np.arange(i + 2, k if i else k - 1)
            count += int(segments_cross(P[i], Q[i], P[j], Q[j]).sum())
        for R, S in ends[m + 1:]:
            count += int(segments_cross(P[:, None], Q[:, None], R[None], S[None]).sum())
    return count


class PlateOutlines:
    """The plate's outline loops (node indices in order, one per piece) and each
    piece's reference area (what the area constraint holds it to)."""

    def __init__(self, loops, areas0):
        self.loops: List[np.ndarray] = [np.asarray(o, dtype=np.int64) for o in loops]
        self.areas0 = [float(a) for a in areas0]
        if len(self.loops) != len(self.areas0):
            raise ValueError(f"{len(self.loops)} outline loops but {len(self.areas0)} areas")

    # -- geometry --------------------------------------------------------------
    @property
    def nodes(self) -> np.ndarray:
        """The outline nodes, piece after piece."""
        return np.concatenate(self.loops)

    def polygons(self, P) -> list:
        return [P[o] for o in self.loops]

    def area_centroid(self, P):
        """Total area of the pieces and their common centroid."""
        ac = [polygon_area_centroid(Q) for Q in self.polygons(P)]
        A = np.array([abs(a) for a, _ in ac])
        return A.sum(), (A[:, None] * np.array([c for _, c in ac])).sum(axis=0) / A.sum()

    def deficits(self, P) -> np.ndarray:
        """(pieces,) reference area minus area now."""
        return np.array([a0 - abs(polygon_area_centroid(Q)[0])
                         for a0, Q in zip(self.areas0, self.polygons(P))])

    def inside(self, P, pts) -> np.ndarray:
        """Whether each point of pts (m, 2) lies inside a piece."""
        from matplotlib.path import Path as MPath
        out = np.zeros(pts.shape[0], dtype=bool)
        for Q in self.polygons(P):
            out |= MPath(Q).contains_points(pts, radius=0.0)
        return out

    def crossings(self, P) -> int:
        return crossings(self.polygons(P))

    def segment_pairs(self) -> np.ndarray:
        """(k, 2) every outline edge, as consecutive loop nodes."""
        return np.concatenate([np.c_[o, np.roll(o, -1)] for o in self.loops])

    # -- following the mesh ----------------------------------------------------
    def renumber(self, node_map, lm=None) -> None:
        """Follow the mesh's node map (old -> new, -1 removed) and, with ``lm``, put
        the nodes injected on the outline's segments in their places."""
        loops = [node_map[o] for o in self.loops]
        loops = [o[o >= 0] for o in loops]
        if lm is not None:
            loops = [lm.polyline(o, closed=True) for o in loops]
        self.loops = loops

    # -- breakup ---------------------------------------------------------------
    def pinch(self, lm, first: int, second: int, spacing: float) -> Optional[str]:
        """Cut the piece whose faces hold the segments ``first`` and ``second`` (rows of
        ``lm.triangulation.segments``, a film of plate closing between them) in two,
        close the fold where they meet from outside, or join two pieces that meet, as
        the module docs say;
        ``spacing``: the outline's node spacing. Returns None, or why not (the mesh and
        the loops then unchanged)."""
        where = [self._position(key)
                 for key in pair_keys(lm.triangulation.segments[[first, second]])]
        if None in where:
            return "a segment of the film is not on the plate's outline"
        (k, p), (k2, q) = where
        if k != k2:
            return self._join(lm, (k, p), (k2, q), spacing)
        o, P = self.loops[k], lm.nodes
        plan = _cut(P, o, p, q)
        if plan is None:
            return self._trim(lm, k, p, q)
        # a neck leaves two pieces turning the way the plate does; where the plate folds
        # onto itself (its faces meet from outside) one of them is the fluid it encloses
        turn = np.sign(polygon_area_centroid(P[o])[0])
        areas = [polygon_area_centroid(P[piece])[0] * turn for piece in plan[:2]]
        if min(areas) <= 0:
            return self._weld(lm, k, p, q, turn)
        if min(areas) <= WELD_FRACTION * self.areas0[k]:
            return self._trim(lm, k, p, q)       # a sliver, not a piece worth following
        return self._apply(lm, k, plan, spacing)

    def _weld(self, lm, k, p, q, turn: float) -> Optional[str]:
        """Close a fold of piece ``k`` where its segments at positions p and q met: of
        the two arcs of the loop from the outer end of one to the outer end of the other
        (each holds both segments, which can then never cross), the one turning against
        the plate bounds the enclosed fluid; its segments are released and the other
        arc, closed by a new segment between those ends, becomes the loop."""
        P = lm.nodes
        arcs = [arc for arc in _arcs(self.loops[k], p, q) if len(arc[1]) >= 3]
        if not arcs:
            return "a piece would keep fewer than three nodes"
        inner, outer = min(arcs, key=lambda arc: polygon_area_centroid(P[arc[0]])[0] * turn)
        pocket = abs(polygon_area_centroid(P[inner])[0])
        after = self._excess_with(P, pocket)
        if after > FOLD_AREA_TOLERANCE:
            return (f"the plate folds onto itself (its faces meet from outside) around "
                    f"fluid of {pocket / sum(self.areas0):.2%} of its area; with it the "
                    f"plate would be {after:.2%} above its reference area (more than "
                    f"FOLD_AREA_TOLERANCE), which the model does not follow")
        why = self._close(lm, k, inner, outer, remove=())
        return None if why is None else f"the fold cannot be closed ({why})"

    def _trim(self, lm, k, p, q) -> Optional[str]:
        """Close a spike of piece ``k``: its segments at positions p and q of the loop
        meet a few nodes apart along it (a sliver of plate, or of fluid, thinner than
        the mesh resolves). Of the two arcs between them, the one around the smaller
        area is released, the nodes inside it removed (kept if they cannot go), and a
        segment joins its ends."""
        P = lm.nodes
        arcs = [(abs(polygon_area_centroid(P[inner])[0]), inner, outer)
                for inner, outer in _arcs(self.loops[k], p, q) if len(outer) >= 3]
        if not arcs:
            return "a piece would keep fewer than three nodes"
        area, inner, outer = min(arcs, key=lambda arc: arc[0])
        ratio = area / self.areas0[k]
        if ratio > WELD_FRACTION:
            return (f"two faces of the plate meet around a sliver of {ratio:.2%} of its "
                    f"area (more than WELD_FRACTION), which the model does not follow")
        why = self._close(lm, k, inner, outer, remove=inner[1:-1])
        if why is not None:
            why = self._close(lm, k, inner, outer, remove=())
        return None if why is None else f"the spike cannot be closed ({why})"

    def _close(self, lm, k, inner, outer, remove) -> Optional[str]:
        """Release the segments along the arc ``inner`` of loop ``k``, join its ends by
        a segment and make ``outer`` (the rest of the loop, from the end of ``inner``
        to its start) the loop, removing the nodes ``remove``. None, or why not (the
        mesh and the loops then unchanged)."""
        tri = lm.triangulation
        rows = tri.segment_rows(np.c_[inner[:-1], inner[1:]])
        try:
            new = lm.reconnect_segments(rows, [[outer[-1], outer[0]]],
                                        tri.segment_source[rows[:1]], remove=remove)
        except ValueError as err:
            return str(err)
        self.loops = [new[np.asarray(outer if m == k else o)]
                      for m, o in enumerate(self.loops)]
        return None

    def _excess_with(self, P, area: float) -> float:
        """How far above its reference area the plate (all pieces) would be with
        ``area`` more, as a fraction of the reference area."""
        return (self.area_centroid(P)[0] + area) / sum(self.areas0) - 1

    def _join(self, lm, first, second, spacing: float) -> Optional[str]:
        """Join pieces ``first[0]`` and ``second[0]`` where their segments at positions
        ``first[1]`` and ``second[1]`` met (a film of fluid between them closing): both
        segments are released and their ends joined crosswise (each end to the facing
        end of the other), so the two loops become one, turning the same way; the film
        joins the plate, whose reference area is the two pieces' together."""
        (k1, p), (k2, q) = first, second
        o1, o2, P = self.loops[k1], self.loops[k2], lm.nodes
        a0, a1, b0, b1 = o1[p], o1[(p + 1) % len(o1)], o2[q], o2[(q + 1) % len(o2)]
        rungs = np.hypot(*(P[[a0, b0]] - P[[b1, a1]]).T)
        if rungs.max() > spacing:
            return (f"two pieces of the plate meet ({rungs.max():.3g} apart at the ends of "
                    f"the segments that met, more than the outline's spacing), which the "
                    f"model does not follow")
        film = abs(polygon_area_centroid(P[[a0, a1, b0, b1]])[0])
        if self._excess_with(P, film) > FOLD_AREA_TOLERANCE:
            return "two pieces of the plate meet around more fluid than FOLD_AREA_TOLERANCE"
        tri = lm.triangulation
        rows = tri.segment_rows(np.array([[a0, a1], [b0, b1]]))
        try:
            new = lm.reconnect_segments(rows, [[a0, b1], [b0, a1]], tri.segment_source[rows])
        except ValueError as err:
            return f"two pieces of the plate meet and cannot be joined ({err})"
        joined = np.r_[np.roll(o1, -(p + 1)), np.roll(o2, -(q + 1))]   # a1 .. a0 b1 .. b0
        first, gone = min(k1, k2), max(k1, k2)
        self.loops[first], self.areas0[first] = joined, self.areas0[k1] + self.areas0[k2]
        del self.loops[gone], self.areas0[gone]
        self.loops = [new[o] for o in self.loops]
        return None

    def _position(self, key):
        """(piece, position) of the outline segment with pair key ``key``, or None."""
        for k, o in enumerate(self.loops):
            pos = np.flatnonzero(pair_keys(np.c_[o, np.roll(o, -1)]) == key)
            if pos.size:
                return k, int(pos[0])
        return None

    def _apply(self, lm, k, plan, spacing) -> Optional[str]:
        keep, rest, add, release = plan
        tri = lm.triangulation
        rows = tri.segment_rows(release)
        source = tri.segment_source[rows]
        P = lm.nodes
        drop = [v for piece, (u, v) in ((keep, add[0]), (rest, add[1]))
                if len(piece) > 3 and np.hypot(*(P[u] - P[v])) < PINCH_FRACTION * spacing]
        areas = [abs(polygon_area_centroid(P[piece])[0]) for piece in (keep, rest)]
        for remove in (drop, []):
            try:
                new = lm.reconnect_segments(rows, add, source, remove=remove)
                break
            except ValueError as err:
                why = str(err)
        else:
            return f"the cut cannot be made ({why})"
        share = self.areas0[k] / sum(areas)
        pieces = [new[np.asarray(piece)] for piece in (keep, rest)]
        self.loops[k:k + 1] = [piece[piece >= 0] for piece in pieces]
        self.areas0[k:k + 1] = [a * share for a in areas]
        for m, o in enumerate(self.loops):
            if m not in (k, k + 1):
                self.loops[m] = new[o]
        return None

    # -- checkpoints -----------------------------------------------------------
    def to_meta(self) -> dict:
        return {"outlines": [o.tolist() for o in self.loops], "areas0": self.areas0}

    @classmethod
    def from_meta(cls, meta: dict, area0: float) -> "PlateOutlines":
        """From a checkpoint's metadata (``area0``: the plate's area, for checkpoints
        written before the plate could break, which hold one ``outline``)."""
        if "outlines" in meta:
            return cls(meta["outlines"], meta["areas0"])
        return cls([meta["outline"]], [area0])


def _arcs(o, p, q):
    """The two ways to close loop o where its segments at positions p and q meet, as
    (inner, outer): ``inner`` runs from the start of one segment to the end of the
    other (o[s] ... o[t + 1], holding both), ``outer`` is the rest of the loop, from the
    end of ``inner`` back to its start."""
    n = len(o)
    arcs = []
    for s, t in ((p, q), (q, p)):
        inner = [o[(s + m) % n] for m in range((t - s) % n + 2)]
        outer = [o[(t + 1 + m) % n] for m in range(n - len(inner) + 2)]
        arcs.append((inner, outer))
    return arcs


def _cut(P, o, p, q):
    """How to cut loop o where its segments p and q (positions) meet: the two pieces (the
    one that keeps both nodes that meet, the other), the two new segments, the two
    segments released; None if a piece would keep fewer than three nodes."""
    n = len(o)
    cand = [(np.hypot(*(P[o[i % n]] - P[o[j % n]])), i % n, j % n)
            for i in (p, p + 1) for j in (q, q + 1)]
    _, ia, ib = min(cand)
    best = None
    for s, t in ((ia, ib), (ib, ia)):
        # piece from s to t keeps both; the rest runs from t + 1 to s - 1
        keep = [o[(s + m) % n] for m in range((t - s) % n + 1)]
        rest = [o[(t + m) % n] for m in range(1, (s - t) % n)]
        if len(keep) < 3 or len(rest) < 3:
            continue
        add = np.array([[o[t], o[s]], [o[(s - 1) % n], o[(t + 1) % n]]])
        length = np.hypot(*(P[add[1, 0]] - P[add[1, 1]]))
        if best is None or length < best[0]:
            release = np.array([[o[(s - 1) % n], o[s]], [o[t], o[(t + 1) % n]]])
            best = (length, (keep, rest, add, release))
    return None if best is None else best[1]
