"""The sinking plate's time step: how far the next step may go without a collision.

A Lagrangian step can be repaired by flips, substeps and relocation as long as nothing
passes through anything: not a node through a wall, not one material line (the plate's
outline, the layer interface) through another. The mesh cannot see a collision coming;
the time step can, from the step's nodal velocities: the spacing limit (cfl), the walls
(a node approaching one covers at most a fraction of its distance per step) and the films
between material lines (their gaps shrink by at most that fraction). Distances shrinking
geometrically keep the step bounded; a film that closes within any step is returned to
the caller: where the plate's two faces meet as it necks, the plate breaks there and the
caller cuts its outline in two, or closes a fold or a spike (``plate_outlines``); where
the interface is on one side, the caller releases it there (``plate_films``).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..evolution.quality import area_shares
from ..geometry.polylines import close_segment_pairs, segment_gaps

__all__ = ["ClosingFilm", "stable_dt", "velocity_now", "film_dt", "film_apart",
           "hold_off_walls", "node_spacing", "FILM_FRACTION", "WALL_FRACTION", "FILM_WATCH",
           "FILM_HALVINGS"]

#: an interface segment closer to the plate's outline than this fraction of the outline's
#: node spacing is released (``plate_films``): a film thinner than a
#: quarter of the spacing has no node inside and closes within a few steps
FILM_FRACTION = 0.25
#: a node approaching a wall moves at most this fraction of its distance to it per step
#: (the distance shrinks geometrically, the step stays bounded: no collision in a step)
WALL_FRACTION = 0.5
#: the films between material lines thinner than this many times cfl outline spacings
#: are watched by the time step (a step moves each side by at most cfl local spacings:
#: thicker films cannot close within it)
FILM_WATCH = 2.0
#: the time step is halved at most this many times for a closing film; one that still
#: closes within a step 2^-10 of the last is where the plate breaks (its faces meet)
FILM_HALVINGS = 10



def node_spacing(P: np.ndarray, T: np.ndarray) -> np.ndarray:
    """(n,) local spacing of each node: the square root of its share (a third)
    of the areas of its triangles. P (n, 2) nodes, T (nt, 3) triangles."""
    return np.sqrt(area_shares(P, T))


def hold_off_walls(lm, v: np.ndarray, c) -> np.ndarray:
    """The nodal velocities v with the component towards a wall set to zero for the nodes
    of material lines (outline, interface) closer to that wall than :data:`FILM_FRACTION`
    of the outline's spacing: a plate pressed onto the bottom rests there on a film of
    fluid that the mesh does not resolve, instead of being pushed ever closer (stopped
    short of the wall step after step, its triangles with the wall flatten to nothing)."""
    P, W = lm.nodes, lm.on_walls
    lo, hi = lm.box
    line = lm.segment_nodes()
    h = FILM_FRACTION * c.outline_spacing * c.plate_thickness
    v = np.array(v, dtype=float)
    for axis in (0, 1):
        free = line & ~W[:, axis]
        towards = (free & (P[:, axis] - lo[axis] < h) & (v[:, axis] < 0)) \
            | (free & (hi[axis] - P[:, axis] < h) & (v[:, axis] > 0))
        v[towards, axis] = 0.0
    return v


def velocity_now(lm, v: np.ndarray) -> np.ndarray:
    """The step's nodal velocities v on the nodes of the mesh ``lm`` now: moved along with
    its node map; a node injected after the solve gets the mean of its neighbours' (it
    may sit next to a wall that a plate presses its neighbours towards)."""
    new = lm.node_map[:v.shape[0]]
    out = np.full((lm.nodes.shape[0], 2), np.nan)
    out[new[new >= 0]] = v[new >= 0]
    unknown = np.isnan(out[:, 0])
    if unknown.any():
        E = lm.triangulation.edges
        E = np.r_[E, E[:, ::-1]]
        E = E[unknown[E[:, 0]] & ~unknown[E[:, 1]]]
        total = np.zeros((out.shape[0], 2))
        np.add.at(total, E[:, 0], out[E[:, 1]])
        count = np.bincount(E[:, 0], minlength=out.shape[0])
        with np.errstate(invalid="ignore", divide="ignore"):
            out[unknown] = total[unknown] / count[unknown, None]
        out[np.isnan(out)] = 0.0  # no known neighbour: the next solve limits it
    return out


def stable_dt(lm, v: np.ndarray, c, outline_segments: int):
    """Largest dt that moves no node of ``lm`` by more than ``c.cfl`` times its local
    spacing (the square root of its share of the triangle areas; slivers do not limit
    the step: flips repair them, and inverting moves are substepped), nor by more than
    :data:`WALL_FRACTION` of its distance to a wall of the mesh's box it approaches, nor
    closes a film between material lines by more than that fraction (:func:`film_dt`).
    ``v``: this step's nodal velocities (before injection and removal). Returns dt and
    :func:`film_dt`'s closing film (or None)."""
    v = velocity_now(lm, v)
    h = node_spacing(lm.nodes, lm.triangles)
    x = lm.nodes
    lo, hi = lm.box
    gap = np.c_[x - lo, hi - x]                                    # left, bottom, right, top
    approach = np.c_[-v, v]                                        # speed towards each
    with np.errstate(divide="ignore", invalid="ignore"):
        lim = c.cfl * h / np.hypot(v[:, 0], v[:, 1])
        wall = np.where((gap > 0) & (approach > 0), WALL_FRACTION * gap / approach, np.inf)
    return film_dt(lm, v, float(min(c.max_dt, lim.min(), wall.min())), c, outline_segments)


def film_apart(cfl: float) -> int:
    """Segments at most this many apart along a material line are never a film: a step
    of ``cfl`` spacings brings them within :data:`FILM_WATCH` x cfl spacings of each other
    anyway."""
    return 2 * math.ceil(FILM_WATCH * cfl) + 2


def film_dt(lm, v: np.ndarray, dt: float, c, outline_segments: int):
    """``dt``, halved until every film between two material lines (segments of ``lm``
    closer than :data:`FILM_WATCH` x cfl outline spacings: outline and interface, the
    outline's two faces where the plate necks, the interface folded onto itself) keeps
    at least 1 - :data:`WALL_FRACTION` of its thickness over the step (Euler move with
    the nodal velocities v on the nodes now): a film that closes within a step carries
    one line through the other, which no flip or relocation can undo. Given segments
    below ``outline_segments`` are the outline's. Returns dt and None, or, for a film
    that still closes after :data:`FILM_HALVINGS` halvings, the last dt that did not
    collapse and the :class:`ClosingFilm` (where the plate necks through, the caller
    cuts it in two there; where the interface closes, the caller releases it)."""
    P, S = lm.nodes, lm.triangulation.segments
    watch = FILM_WATCH * c.cfl * c.outline_spacing * c.plate_thickness
    i, j, gap = close_segment_pairs(P, S, watch, film_apart(c.cfl))
    for _ in range(FILM_HALVINGS + 1):
        Q = P + dt * v
        closing = segment_gaps(Q[S[i, 0]], Q[S[i, 1]], Q[S[j, 0]], Q[S[j, 1]]) \
            < (1 - WALL_FRACTION) * gap
        if not closing.any():
            return dt, None
        dt *= 0.5
    k = np.flatnonzero(closing)[np.argmin(gap[closing])]
    x = P[S[i[k]]].mean(axis=0)
    outline = lm.triangulation.segment_source[[i[k], j[k]]] < outline_segments
    what = ("two faces of the plate's outline" if outline.all()
            else "the outline and the interface" if outline.any()
            else "two parts of the layer interface")
    return 2.0 * dt, ClosingFilm(int(i[k]), int(j[k]), bool(outline.all()), float(gap[k]), (
        f"{what} close at x = {x[0]:.4g}, z = {x[1]:.4g} ({gap[k]:.2g} apart) within any "
        f"step {2 ** FILM_HALVINGS} times shorter than the last"))


class ClosingFilm(NamedTuple):
    """A film between two material lines that closes within any step (:func:`film_dt`):
    rows ``first`` and ``second`` of ``triangulation.segments``, whether both are the
    outline's, their gap and a line saying where."""
    first: int
    second: int
    outline: bool
    gap: float
    message: str
