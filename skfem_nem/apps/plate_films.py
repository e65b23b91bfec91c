"""The sinking plate's films: where two material lines come closer than the mesh resolves.

The plate's outline and the layer interface are segments of the mesh: edges that no
flip removes, so each line keeps its own side of the fluid. Where the flow squeezes the
fluid between two lines thinner than the nodes resolve (the interface pressed against
the plate, or two parts of the interface folded onto each other against the bottom
wall), keeping both lines as edges would carry one through the other within a step,
which no flip or relocation can undo. The plate's outline is the material boundary that
matters (its area is held, its stress carried), so the interface gives way: its
segments in such a film are released (``LagrangianMesh.release_segments``) and their
nodes go on as ordinary fluid nodes, whose layer (and viscosity) is still set by their
initial height. The outline's own films (the plate necking through, folding onto
itself) are cut or closed by :class:`~.plate_outlines.PlateOutlines` instead.
"""
from __future__ import annotations

import numpy as np

from ..geometry.polylines import close_segment_pairs, segment_distances
from .plate_time_step import FILM_FRACTION, film_apart

__all__ = ["interface_rows", "on_interface", "release_near_outline", "release_interface_film"]


def interface_rows(tri, outline_segments: int) -> np.ndarray:
    """Rows of ``tri.segments`` that are the layer interface's (given segments from
    ``outline_segments`` on; those below are the outline's)."""
    return np.flatnonzero(tri.segment_source >= outline_segments)


def on_interface(tri, rows, outline_segments: int) -> bool:
    """Whether any of the rows ``rows`` of ``tri.segments`` is the layer interface's."""
    return bool((tri.segment_source[np.asarray(rows, dtype=np.int64)]
                 >= outline_segments).any())


def release_near_outline(lm, outlines, outline_segments: int, spacing: float) -> int:
    """Release the interface segments of ``lm`` closer to the plate's outline
    (``outlines``) than :data:`FILM_FRACTION` of the outline's node spacing ``spacing``:
    the film of fluid between them has no node inside and closes within a few steps.
    Returns how many segments were released."""
    tri, P = lm.triangulation, lm.nodes
    rows = interface_rows(tri, outline_segments)
    if not rows.size:
        return 0
    seg = tri.segments[rows]
    o = outlines.segment_pairs()
    gap = segment_distances(P[seg[:, 0]], P[seg[:, 1]], P[o[:, 0]], P[o[:, 1]])
    return lm.release_segments(rows[gap < FILM_FRACTION * spacing])


def release_interface_film(lm, rows, outline_segments: int, spacing: float,
                           cfl: float) -> int:
    """Release the interface segments among ``rows`` (segments of a film found closing
    within any step, or crossing within a relocation) and every interface segment of
    ``lm`` closer than :data:`FILM_FRACTION` of the outline's spacing ``spacing`` to
    another segment a film away (not its neighbours along the line for the step's
    ``cfl``, :func:`~.plate_time_step.film_apart`): the whole film
    the mesh no longer resolves goes at once, not a segment per step. Returns how many
    segments were released (none if ``rows`` are all the outline's)."""
    tri, P = lm.triangulation, lm.nodes
    rows = np.asarray(rows, dtype=np.int64).reshape(-1)
    if not on_interface(tri, rows, outline_segments):
        return 0
    i, j, _ = close_segment_pairs(P, tri.segments, FILM_FRACTION * spacing, film_apart(cfl))
    near = np.r_[rows, i, j]
    return lm.release_segments(near[tri.segment_source[near] >= outline_segments])
