"""The ``skfem-nem`` command line.

``skfem-nem interpolate NODES (QUERIES | --grid NX NY) -o OUT`` interpolates scattered data
from a CSV file (:mod:`skfem_nem.apps.interpolate_cli`); ``skfem-nem sinking-plate`` runs the
paper's showcase. One module for the entry point, so that every command reports a user error
alike: one line on stderr, exit status 2, no traceback.
"""
from __future__ import annotations

import argparse
import contextlib
import io
import sys
import warnings

import numpy as np

#: exit status of a user error (as argparse's own): one line on stderr, no traceback
USER_ERROR = 2
#: parameters a restarted run may change: when it ends, how often it writes,
#: and how large its time steps may be (the physics and the node set stay)
RESTART_CHANGEABLE = ("end_time", "output_interval", "checkpoint_every", "max_dt", "min_dt",
                      "cfl")
#: exit status of a run that stopped (its outputs and a checkpoint are kept)
STOPPED = 1


def _one_line_warning(message, category, *args, **kwargs):
    """Warnings of a run (a step retried with a smaller time step, ...) as
    one line each on stderr, without the source line."""
    print(f"skfem-nem: {category.__name__}: {message}", file=sys.stderr)


def _fail(message: str):
    """One line naming the problem on stderr, exit status 2."""
    print(f"skfem-nem: {message}", file=sys.stderr)
    raise SystemExit(USER_ERROR)


def interpolate(args) -> int:
    """``skfem-nem interpolate``: :mod:`skfem_nem.apps.interpolate_cli`, its input errors as
    one line."""
    from .interpolate_cli import InputError, run_interpolate
    try:
        return run_interpolate(args)
    except InputError as err:
        _fail(str(err))


def sinking_plate(args) -> int:
    from ..parallel.petsc import PetscUnavailableError
    from .plate_config import load_config, stored_dim

    if args.max_steps is not None and args.max_steps < 0:
        _fail(f"sinking-plate: --max-steps must be a non-negative integer, got "
              f"{args.max_steps}")
    try:
        dim = _plate_dim(args, stored_dim)
        kind, run_class = _plate_kind(dim)
        given = _given_parameters(args, kind, dim)
        if args.restart:
            cfg = _restart_config(args, given, kind)
        else:
            cfg = load_config(args.config, given, kind)
        sim = (run_class.restart(args.output, cfg) if args.restart
               else run_class(cfg, args.output))
    except (ValueError, OSError, PetscUnavailableError) as err:
        _fail(f"sinking-plate: {err}")
    with _silent(not sim.root):  # over MPI: rank 0 speaks for all
        return _run_plate(sim, cfg, args)


def _plate_dim(args, stored_dim) -> int:
    """2 or 3: ``--dim`` (default 2), or on ``--restart`` the stored run's, which
    ``--dim`` may only repeat."""
    if not args.restart:
        return args.dim or 2
    dim = stored_dim(args.output)
    if args.dim is not None and args.dim != dim:
        raise ValueError(f"--dim {args.dim} cannot change when a run is restarted (the run "
                         f"in {args.output} is {dim}D)")
    return dim


def _plate_kind(dim: int):
    """The configuration class and the run class of the 2D or the 3D plate."""
    if dim == 3:
        from .plate3d_config import Plate3DConfig
        from .sinking_plate_3d import SinkingPlate3D
        return Plate3DConfig, SinkingPlate3D
    from .sinking_plate import PlateConfig, SinkingPlate
    return PlateConfig, SinkingPlate


def _given_parameters(args, kind, dim) -> dict:
    """The parameters given on the command line; one of the other plate's raises."""
    from dataclasses import fields as dfields
    names = {f.name for f in dfields(kind)}
    given = {}
    for name in _plate_parameters():
        value = getattr(args, name)
        if value is None:
            continue
        if name not in names:
            flag = "--" + name.replace("_", "-")
            raise ValueError(f"{flag} is not a parameter of the {dim}D plate"
                             + (" (it is one of the 2D plate only)"
                                if dim == 3 else " (it is one of the 3D plate: --dim 3)"))
        given[name] = value
    return given


def _plate_parameters() -> dict:
    """Every parameter of the 2D and the 3D plate: name -> (2D default or None, 3D
    default or None, help)."""
    from dataclasses import fields as dfields

    from .plate3d_config import HELP_3D, Plate3DConfig
    from .sinking_plate import HELP, PlateConfig
    out = {f.name: (getattr(PlateConfig, f.name), None, HELP.get(f.name, ""))
           for f in dfields(PlateConfig)}
    for f in dfields(Plate3DConfig):
        d2, _, text = out.get(f.name, (None, None, HELP_3D[f.name]))
        out[f.name] = (d2, getattr(Plate3DConfig, f.name), text)
    return out


def _silent(on: bool):
    """A context that discards standard output and error if ``on``."""
    stack = contextlib.ExitStack()
    if on:
        stack.enter_context(contextlib.redirect_stdout(io.StringIO()))
        stack.enter_context(contextlib.redirect_stderr(io.StringIO()))
    return stack


def _run_plate(sim, cfg, args) -> int:
    """Run the constructed ``sim``: progress, the one-line stop, the files written."""
    print(f"sinking plate: {sim.lm.nodes.shape[0]} nodes, {sim.cells}, "
          f"t = {sim.lm.time:g} -> {cfg.end_time:g}; output in {args.output}")
    if not kernels_cached(dim=sim.dim):
        print(f"first run after installing: compiling the numerical kernels "
              f"({FIRST_COMPILE[sim.dim]}, once) before the first step", flush=True)
    try:
        with warnings.catch_warnings():
            warnings.showwarning = _one_line_warning
            sim.run(progress=not args.quiet, max_steps=args.max_steps)
    except KeyboardInterrupt:
        sim.checkpoint()
        print(f"interrupted at t = {sim.lm.time:g}; continue with --restart")
        return 130
    except Exception as err:
        stop = isinstance(err, (ValueError, RuntimeError, ArithmeticError,
                                np.linalg.LinAlgError))
        if _ranks(sim) > 1 and not (stop and sim.failures.all_failed()):
            _abort_rank(sim, err, args)
        if not stop:
            raise
        # the mesh and fields are those of the last completed step: keep them
        _guarded(sim, args, lambda: (sim.checkpoint(), sim.figures()))
        reason = (str(err).splitlines() or [type(err).__name__])[0]
        from .sinking_plate import StepStalled
        hint = ("--restart with a smaller --min-dt or --cfl, or a new run with more --nodes"
                if isinstance(err, StepStalled) else
                "a new run with more --nodes, or --restart with a smaller --max-dt or --cfl")
        print(f"skfem-nem: sinking-plate stopped at t = {sim.lm.time:g} (step {sim.lm.step}): "
              f"{reason}. Outputs and a checkpoint up to there are in {args.output}; try "
              f"{hint}", file=sys.stderr)
        return STOPPED
    for p in _guarded(sim, args, sim.figures):
        print("wrote", p)
    print("wrote", sim.out / "plate.pvd", "and", sim.out / "diagnostics.csv")
    retried = _retried_steps(sim.out / "diagnostics.csv") if sim.root else 0
    if retried:
        print(f"{retried} step(s) were retried with a shorter time step (column 'retries' "
              f"of diagnostics.csv)")
    return 0


def _ranks(sim) -> int:
    """The number of MPI ranks computing the run (1 unless over MPI)."""
    return getattr(sim, "ranks", 1)


def _guarded(sim, args, write):
    """``write()`` (rank 0's outputs); over MPI a failure of it ends every rank."""
    try:
        return write()
    except Exception as err:
        if _ranks(sim) > 1:
            _abort_rank(sim, err, args)
        raise


def _abort_rank(sim, err, args) -> None:
    """End every rank (over MPI) after a failure of this rank alone, in one line naming it;
    the last checkpoint stays as it was. Does not return."""
    reason = (str(err).splitlines() or [type(err).__name__])[0]
    sim.failures.abort(f"skfem-nem: sinking-plate: rank {sim.rank} of {sim.ranks} failed at "
                       f"t = {sim.lm.time:g} (step {sim.lm.step}): {type(err).__name__}: "
                       f"{reason}; every rank stopped, and the last checkpoint in "
                       f"{args.output} is kept (--restart continues from it)")


def _retried_steps(path) -> int:
    """How many steps of the run's log were retried with a shorter time step."""
    from .output import read_csv_columns
    d = read_csv_columns(path)
    return int(np.count_nonzero(d.get("retries", np.zeros(0)) > 0))


#: modules whose numba kernels every run of the 2D and of the 3D plate compiles first
#: (their on-disk cache tells whether this is the plate's first run after installing),
#: relative to the package
FIRST_KERNELS = {2: ("coordinates/area2d", "basis/smoothing", "geometry/delaunay2d"),
                 3: ("geometry/delaunay3d_build", "coordinates/watson3d",
                     "models/condensation_tet")}
#: how long the plate's first run compiles its kernels, on two cores (the 3D plate's
#: are some 150 kernels; docs/stokes_3d.md)
FIRST_COMPILE = {2: "about half a minute", 3: "about three minutes"}


def kernels_cached(root=None, dim: int = 2) -> bool:
    """Whether numba's on-disk cache holds the kernels of :data:`FIRST_KERNELS` of the
    ``dim``-D plate, i.e. whether this is not its first run after installing (``root``:
    the package folder, by default this package's)."""
    from pathlib import Path

    import numba
    root = Path(__file__).resolve().parents[1] if root is None else Path(root)
    elsewhere = numba.config.CACHE_DIR     # NUMBA_CACHE_DIR: one folder per source folder
    for module in FIRST_KERNELS[dim]:
        folder, name = (root / module).parent, (root / module).name
        found = (Path(elsewhere).rglob if elsewhere else (folder / "__pycache__").glob)
        if not any(found(f"{name}.*.nbi")):
            return False
    return True


def _restart_config(args, given, kind):
    """The configuration (of the class ``kind``) stored with the run in ``args.output``,
    with the options a restart may change; anything else is refused, naming it."""
    from .plate_config import stored_config
    if args.config:
        raise ValueError("--config cannot be combined with --restart: a restarted run "
                         "continues with the configuration stored in its checkpoint")
    fixed = [k for k in given if k not in RESTART_CHANGEABLE]
    if fixed:
        allowed = ", ".join("--" + k.replace("_", "-") for k in RESTART_CHANGEABLE)
        raise ValueError(f"--{fixed[0].replace('_', '-')} cannot change when a run is "
                         f"restarted (it continues with its stored configuration; only "
                         f"{allowed} may change)")
    cfg = stored_config(args.output, given, kind)
    for k, v in given.items():
        print(f"restart: {k} = {v:g} (was {stored_config(args.output, kind=kind).__dict__[k]:g})")
    return cfg


class _DefaultsHelp(argparse.ArgumentDefaultsHelpFormatter):
    """Shows an option's default where it says something: not for flags, nor for the
    plate's parameters, which default to None on the command line (None: not given, the
    configuration decides) and say their built-in default themselves."""

    def _get_help_string(self, action):
        if action.default is None or action.nargs == 0 or "(default" in (action.help or ""):
            return action.help
        return super()._get_help_string(action)


def _add_plate_parser(sub):
    sp = sub.add_parser(
        "sinking-plate", help="the paper's Fig. 6: an elasto-plastic plate sinking through a "
        "layered viscous fluid on an evolving natural-neighbour mesh",
        description="Run the sinking-plate showcase (Braun & Sambridge 1995, Fig. 6). Every "
        "parameter has a built-in default; a TOML file (--config, keys as below with "
        "underscores, optionally under a [sinking-plate] table) and the options below "
        "override them, the options last.",
        formatter_class=_DefaultsHelp)
    sp.add_argument("-o", "--output", default="out/sinking-plate", help="output folder")
    sp.add_argument("--config", help="TOML file with parameters")
    sp.add_argument("--restart", action="store_true",
                    help="continue the run stored in the output folder from its last "
                    "checkpoint, with its own configuration (only --end-time, "
                    "--output-interval, --checkpoint-every, --max-dt and --cfl may change)")
    sp.add_argument("--max-steps", type=int, default=None,
                    help="stop after this many steps (a checkpoint is written)")
    sp.add_argument("--quiet", action="store_true", help="no progress bar")
    sp.add_argument("--dim", type=int, choices=(2, 3), default=None,
                    help="2 (default): the paper's plate, elasto-plastic, on a mesh repaired "
                    "by flips; 3: an elasto-plastic slab in a box, on tetrahedra repaired by "
                    "flips (a restart continues the stored run's)")
    g = sp.add_argument_group("parameters (nondimensional; [3D: ...] the --dim 3 default)")
    for name, (d2, d3, text) in _plate_parameters().items():
        flag = "--" + name.replace("_", "-")
        if d2 is None:
            info = f"[3D only] (default {d3})"
        else:
            info = f"(default {d2})" + ("" if d3 is None else
                                        f" [3D: {d3}]" if d3 != d2 else " [3D: same]")
            info += " [2D only]" if d3 is None else ""
        default = d2 if d2 is not None else d3
        if isinstance(default, bool):  # --segments / --no-segments
            g.add_argument(flag, dest=name, action=argparse.BooleanOptionalAction,
                           default=None, help=f"{text} {info}")
            continue
        g.add_argument(flag, dest=name, type=type(default), default=None,
                       help=f"{text} {info}")
    return sp


def main(argv=None) -> int:
    from .. import __version__

    ap = argparse.ArgumentParser(prog="skfem-nem", description="The Natural Element Method "
                                 "(Braun & Sambridge 1995) for scikit-fem.")
    ap.add_argument("--version", action="version", version=f"skfem-nem {__version__}")
    sub = ap.add_subparsers(dest="command")
    from .interpolate_cli import add_interpolate_parser
    add_interpolate_parser(sub)
    _add_plate_parser(sub)
    args = ap.parse_args(argv)
    if args.command == "interpolate":
        return interpolate(args)
    if args.command == "sinking-plate":
        return sinking_plate(args)
    ap.print_help()
    return 0


if __name__ == "__main__":
    sys.exit(main())
