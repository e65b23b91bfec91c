"""One Lagrangian time step's checks and node update, shared by the 2D and 3D meshes.

:class:`~skfem_nem.evolution.lagrangian.LagrangianMesh` (flips and remap) and
:class:`~skfem_nem.evolution.lagrangian3d.LagrangianMesh3D` (retriangulation) differ in how they
repair the triangulation after a move, not in how they validate a step, evaluate the velocity
or move the nodes: that part lives here once.
"""
from __future__ import annotations

import os
import tempfile
from typing import Dict

import numpy as np

__all__ = ["StepTooLong", "MoveNotConverged", "LagrangianStep", "check_node_fields",
           "evaluate_velocity", "check_step_arguments", "predictor_corrector", "keep_in_box",
           "WALL_REACH", "LEAVE_TOLERANCE", "save_npz_atomically"]


class StepTooLong(ValueError):
    """A step the mesh cannot follow at this dt, though a shorter one may pass: a
    triangle that inverts with no vertex to relocate, segments that cannot be edges
    again, a node carried out of the box. The mesh is left as it was before the step;
    a caller may retry with a shorter step (the sinking plate halves it). ``crossing``:
    the node pairs of two segments that would cross, where that is the cause."""

    def __init__(self, message, crossing=None):
        super().__init__(message)
        self.crossing = crossing


class MoveNotConverged(StepTooLong):
    """The predictor-corrector of a step did not converge: the nodes' end positions are
    not known to its tolerance, and a step is never accepted with them. A shorter step
    converges (the iteration contracts by about dt times the velocity's gradient)."""


def check_node_fields(node_fields, n) -> Dict[str, np.ndarray]:
    """Float copies of named per-node arrays (n, ...), checked finite."""
    out = {}
    for name, a in (node_fields or {}).items():
        a = np.array(a, dtype=float, copy=True)
        if a.shape[:1] != (n,):
            raise ValueError(f"node field {name!r} has shape {a.shape}, expected ({n}, ...)")
        if not np.isfinite(a).all():
            raise ValueError(f"node field {name!r} has non-finite values "
                             f"(first at node {np.argwhere(~np.isfinite(a))[0][0]})")
        out[name] = a
    return out


def evaluate_velocity(velocity, x, on_wall=None):
    """``velocity(x)`` checked: shape of x, finite (naming the node); the
    components normal to a wall (``on_wall`` (n, d) bool) set to zero."""
    v = np.asarray(velocity(x.copy()), dtype=float)
    if v.shape != x.shape:
        raise ValueError(f"velocity returned shape {v.shape}, expected {x.shape}")
    bad = np.flatnonzero(~np.isfinite(v).all(axis=1))
    if bad.size:
        raise ValueError(f"velocity returned non-finite values at {bad.size} node(s), "
                         f"first node {bad[0]} at {x[bad[0]].tolist()}")
    if on_wall is not None:
        v = np.where(on_wall, 0.0, v)
    return v


def check_step_arguments(velocity, dt, tol, maxiter, max_substeps, inject):
    """``ValueError`` (``TypeError`` for velocity) naming the first bad
    argument of :meth:`LagrangianMesh.advance`, before anything moves."""
    if not callable(velocity):
        raise TypeError(f"velocity must be a callable x (n, d) -> (n, d), got "
                        f"{type(velocity).__name__}")

    def number(v):
        return isinstance(v, (int, float, np.floating, np.integer)) and not isinstance(v, bool)

    for name, v in (("dt", dt), ("tol", tol)):
        if not (number(v) and np.isfinite(v) and v > 0):
            raise ValueError(f"{name} must be positive and finite, got {v!r}")
    for name, v in (("maxiter", maxiter), ("max_substeps", max_substeps)):
        if not (isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v >= 1):
            raise ValueError(f"{name} must be a positive integer, got {v!r}")
    if inject is not None and not (number(inject) and np.isfinite(inject) and inject > 1):
        raise ValueError(f"inject must be None or a factor above 1, got {inject!r}")


def predictor_corrector(velocity, x0, dt, tol, maxiter, step):
    """Trapezoidal update x = x0 + dt/2 (v(x0) + v(x)), iterated from the Euler
    predictor until the largest change is below ``tol`` times the size of the
    node set (at most ``maxiter`` corrections). Returns ``(x, iterations, converged)``;
    :class:`MoveNotConverged` from :meth:`LagrangianStep.step_transaction` if not."""
    if not np.isfinite(dt) or dt <= 0:
        raise ValueError(f"dt must be positive and finite, got {dt}")
    size = float(np.ptp(x0, axis=0).max())
    v0 = velocity(x0)
    x = x0 + dt * v0
    it = 0
    converged = False
    for it in range(1, maxiter + 1):
        xn = x0 + 0.5 * dt * (v0 + velocity(x))
        change = np.abs(xn - x).max()
        x = xn
        if change <= tol * size:
            converged = True
            break
    if not converged:
        raise MoveNotConverged(f"step {step}: the predictor-corrector did not converge in "
                               f"{maxiter} iterations (last change {change:.3e}, tolerance "
                               f"{tol * size:.3e}): reduce dt")
    return x, it, converged


#: a node that a step moves towards a wall covers at most this fraction of its distance to
#: it. The nodal velocity of a node next to a free-slip wall is a solution value, not the
#: interpolant that vanishes on the wall, and can carry it through the wall when it is
#: closer than its spacing resolves; the exact flow never reaches the wall in finite time
#: and the discrete one should not either (the node approaches it geometrically)
WALL_REACH = 0.9
#: a move that overshoots a wall by more than the node's distance to it and by more than
#: this fraction of the box's size is an error (a velocity not tangent to the walls, a time
#: step far too long), not a node closer to a wall than the mesh resolves
LEAVE_TOLERANCE = 1e-3


def keep_in_box(x, x0, on_wall, box):
    """Wall coordinates kept exactly, and a node that would reach or pass a wall stopped
    at :data:`WALL_REACH` of its distance; returns the positions and how many nodes were
    stopped. ``ValueError`` naming the first node whose move would overshoot a wall by
    more than its distance to it and more than :data:`LEAVE_TOLERANCE` of the box."""
    x = np.where(on_wall, x0, x)
    lo, hi = box
    slack = LEAVE_TOLERANCE * float(np.max(hi - lo))
    far = np.flatnonzero(((x < lo - np.maximum(x0 - lo, slack))
                          | (x > hi + np.maximum(hi - x0, slack))).any(axis=1))
    if far.size:
        raise StepTooLong(f"{far.size} node(s) would leave the box, first node {far[0]} "
                          f"to {x[far[0]].tolist()}: reduce dt")
    low, high = lo + (1 - WALL_REACH) * (x0 - lo), hi - (1 - WALL_REACH) * (hi - x0)
    stopped = ((x < low) | (x > high)) & ~on_wall
    return np.clip(x, low, high), int(stopped.any(axis=1).sum())


class LagrangianStep:
    """The transaction of one Lagrangian time step, shared by the 2D and 3D meshes.

    :meth:`step_transaction` checks the arguments before anything moves, saves the state,
    moves the nodes (predictor-corrector, box walls kept exactly), hands the move to the
    dimension's repair, and on any error or interruption restores the saved state
    exactly. A subclass provides ``nodes``, ``walls``, ``_on_wall``, ``_box``, ``step``,
    ``history`` and three methods: ``_state()`` and ``_restore(state)`` (everything a step
    may change), and ``_repair(x0, x, dt, max_substeps, inject)``, which moves the mesh
    from x0 to x, advances the clock and returns the dimension's part of the report.
    """

    @property
    def box(self):
        """``(lo, hi)``: the corners of the box of the initial nodes (the walls, with
        ``walls="box"``)."""
        return self._box[0].copy(), self._box[1].copy()

    def snapshot(self):
        """Everything a step may change, for :meth:`restore`: a caller's step of several
        moves (the 3D plate's midpoint step) is taken back whole when a later part fails."""
        return self._state(), len(self.history)

    def restore(self, snapshot) -> None:
        """Put back the state of a :meth:`snapshot`: the moves since and their reports are
        undone."""
        state, reports = snapshot
        self._restore(state)
        del self.history[reports:]

    def _velocity(self, velocity, x):
        if self.walls != "box":
            return evaluate_velocity(velocity, x)
        # the velocity is defined in the box: a predictor that overshoots a wall (a node
        # pressed towards it) is evaluated on the wall; the positions themselves are
        # checked by keep_in_box
        lo, hi = self._box
        return evaluate_velocity(velocity, np.clip(x, lo, hi), self._on_wall)

    def step_transaction(self, velocity, dt, tol, maxiter, max_substeps=1, inject=None,
                         **options) -> dict:
        """One step as a transaction; returns its report (appended to ``history``).
        ``options``: further keywords of the dimension's repair."""
        check_step_arguments(velocity, dt, tol, maxiter, max_substeps, inject)
        state = self._state()
        try:
            x0 = np.array(self.nodes)
            x, it, converged = predictor_corrector(lambda y: self._velocity(velocity, y), x0,
                                                   dt, tol, maxiter, self.step + 1)
            stopped = 0
            if self.walls == "box":
                x, stopped = keep_in_box(x, x0, self._on_wall, self._box)
            report = {"step": self.step + 1, "time": self.time + dt, "dt": dt,
                      "iterations": it, "converged": converged, "stopped_at_walls": stopped}
            report.update(self._repair(x0, x, dt, max_substeps, inject, **options))
        except BaseException:
            self._restore(state)
            raise
        self.history.append(report)
        return report


def save_npz_atomically(path, arrays) -> None:
    """``np.savez`` of ``arrays`` to ``path`` through a temporary file in the same folder,
    flushed and renamed: a checkpoint is either the old one or the new one, never torn."""
    path = os.fspath(path)
    folder = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(dir=folder, suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            np.savez(fh, **arrays)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise

