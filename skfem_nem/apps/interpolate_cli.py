"""The ``skfem-nem interpolate`` command: scattered data from a CSV file, interpolated at
the points of another CSV file or on a regular grid, written as CSV.

A command of its own (not a script around :class:`~skfem_nem.NaturalNeighbourInterpolator`)
because the everyday use of scattered-data interpolation is a file in, a file out: the
input's column names must reach the output, a query outside the data's convex hull must not
stop the run (it gets the fill value and is counted), and every mistake in the input must
come back as one line naming it. This module reads and checks the files, builds the grid and
the output table; every problem is an :class:`InputError`, which the command line
(:mod:`skfem_nem.apps.cli`) prints as one line with exit status 2.
"""
from __future__ import annotations

import numpy as np

__all__ = ["InputError", "add_interpolate_parser", "run_interpolate", "read_table",
           "grid_points"]

#: the coordinate names of files without a header line
AXES = ("x", "y", "z")

DESCRIPTION = (
    "Interpolate scattered data with natural-neighbour (and other) interpolants. NODES is "
    "a CSV file with the coordinates and one or more value columns per data point (x, y, "
    "value... in 2D; x, y, z, value... with --dim 3); the values are interpolated at the "
    "points of the CSV file QUERIES (its first 2 or 3 columns) or, with --grid, on a "
    "regular grid. A first line that is not numeric names the columns: the output keeps "
    "those names (without one: x, y[, z], value0, value1, ...). Lines starting with # are "
    "skipped. Queries outside the data's convex hull get --fill-value.")


class InputError(ValueError):
    """A problem with the command's input (files, options), naming it."""


def add_interpolate_parser(sub):
    """The ``interpolate`` subcommand's parser on the subparsers ``sub``."""
    from ..coordinates.interpolator import METHODS

    ip = sub.add_parser("interpolate", help="interpolate scattered data (CSV) at query "
                        "points or on a grid", description=DESCRIPTION)
    ip.add_argument("nodes", help="CSV: x, y[, z], value[, value...] per data point")
    ip.add_argument("queries", nargs="?", default=None,
                    help="CSV: x, y[, z] per query point (or use --grid)")
    ip.add_argument("-o", "--output", default="interpolated.csv",
                    help="output CSV file (default: interpolated.csv)")
    ip.add_argument("--method", "--kind", dest="method", default="sibson",
                    help=f"one of {', '.join(METHODS)} (default: sibson; laplace is 2D "
                    "only; sibson1 and farin estimate the data's gradients)")
    ip.add_argument("--dim", default="2", help="2 (default) or 3: the number of coordinate "
                    "columns")
    ip.add_argument("--fill-value", default="nan",
                    help="the value at queries outside the data's convex hull (default: nan)")
    ip.add_argument("--grid", nargs="+", metavar="N",
                    help="NX NY (3D: NX NY NZ) grid points instead of a QUERIES file; the "
                    "output lists them with x varying fastest")
    ip.add_argument("--bounds", nargs="+", metavar="B",
                    help="XMIN XMAX YMIN YMAX (3D: ... ZMIN ZMAX) of --grid (default: the "
                    "data's bounding box)")
    ip.add_argument("--gradient", action="store_true",
                    help="also write the interpolant's gradient, columns d<name>/dx, "
                    "d<name>/dy (NaN where it is undefined: outside and on the hull, and "
                    "at the data points for sibson and laplace)")
    return ip


def run_interpolate(args) -> int:
    """Run the command for the parsed ``args``; raises :class:`InputError`."""
    from .. import NaturalNeighbourInterpolator

    d = _dimension(args.dim)
    fill = _number(args.fill_value, "--fill-value")
    method = _method(args.method, d)
    names, nodes = read_table(args.nodes, d + 1, "nodes")
    queries = _queries(args, nodes[:, :d], d)
    coords, values = _names(names, d, nodes.shape[1] - d)
    try:
        itp = NaturalNeighbourInterpolator(nodes[:, :d], nodes[:, d:], method=method,
                                           fill_value=fill)
    except ValueError as err:
        raise InputError(f"nodes file {args.nodes!r}: {_first_line(err)}") from None
    outside = queries.shape[0] - _inside_count(nodes[:, :d], queries)
    table, header = _table(itp, queries, coords, values, args.gradient)
    _write(args.output, table, header)
    print(f"wrote {table.shape[0]} interpolated point(s) to {args.output} (method {method}; "
          f"{outside} outside the data's convex hull, set to {fill:g})")
    return 0


def _first_line(err) -> str:
    return (str(err).splitlines() or [type(err).__name__])[0]


def _dimension(text) -> int:
    if str(text) not in ("2", "3"):
        raise InputError(f"--dim must be 2 or 3, got {text!r}")
    return int(text)


def _number(text: str, flag: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise InputError(f"{flag} must be a number (or nan), got {text!r}") from None


def _method(method: str, d: int) -> str:
    from ..coordinates.interpolator import METHODS
    if method not in METHODS:
        raise InputError(f"unknown --method {method!r}: one of {', '.join(METHODS)}")
    if d not in METHODS[method]:
        valid = [m for m, dims in METHODS.items() if d in dims]
        raise InputError(f"--method {method!r} works in 2D only; in 3D: {', '.join(valid)}")
    return method


def read_table(path: str, min_cols: int, what: str):
    """``(names, rows)``: the column names of the CSV file ``path`` (its first line if that
    is not numeric, else None) and its data lines as an (m, k) array, k >= ``min_cols``;
    lines starting with ``#`` and empty lines are skipped, ``;`` separates as ``,`` does."""
    try:
        with open(path) as fh:
            lines = [ln for ln in fh if ln.strip() and not ln.lstrip().startswith("#")]
    except OSError as err:
        raise InputError(f"cannot read {what} file {path!r}: {err.strerror}") from None
    names = None
    if lines and not _numeric(lines[0]):
        names = [n.strip().strip("\"'").strip() for n in _fields(lines[0])]
        lines = lines[1:]
    rows = [_row(ln, k, path, what) for k, ln in enumerate(lines, 1)]
    if not rows:
        raise InputError(f"{what} file {path!r} holds no data")
    ncol = {len(r) for r in rows}
    if len(ncol) != 1 or min(ncol) < min_cols:
        raise InputError(f"{what} file {path!r} needs at least {min_cols} columns on every "
                         f"line (found {sorted(ncol)})")
    if names is not None and len(names) != len(rows[0]):
        raise InputError(f"{what} file {path!r}: the header names {len(names)} column(s), "
                         f"the data lines have {len(rows[0])}")
    return names, np.array(rows)


def _fields(line: str):
    return line.replace(";", ",").split(",")


def _numeric(line: str) -> bool:
    try:
        [float(v) for v in _fields(line)]
        return True
    except ValueError:
        return False


def _row(line: str, k: int, path: str, what: str):
    try:
        row = [float(v) for v in _fields(line)]
    except ValueError:
        raise InputError(f"{what} file {path!r}: data line {k} is not numeric: "
                         f"{line.strip()!r}") from None
    if not np.isfinite(row).all():
        raise InputError(f"{what} file {path!r}: data line {k} holds a value that is not "
                         f"finite: {line.strip()!r}")
    return row


def _names(names, d: int, k: int):
    """The coordinate names and the value names of the output."""
    if names is None:
        return list(AXES[:d]), [f"value{j}" for j in range(k)]
    names = [n or f"column{j}" for j, n in enumerate(names)]
    return names[:d], names[d:]


def _queries(args, nodes, d: int) -> np.ndarray:
    """The query points: the QUERIES file's first d columns, or the grid."""
    if args.queries is not None and args.grid is not None:
        raise InputError("give either a QUERIES file or --grid, not both")
    if args.grid is None:
        if args.bounds is not None:
            raise InputError("--bounds needs --grid")
        if args.queries is None:
            raise InputError("give a QUERIES file or --grid NX NY")
        return read_table(args.queries, d, "queries")[1][:, :d]
    counts = _grid_counts(args.grid, d)
    bounds = (_bounds(args.bounds, d) if args.bounds is not None
              else np.c_[nodes.min(axis=0), nodes.max(axis=0)])
    return grid_points(counts, bounds)


def _grid_counts(texts, d: int):
    want = "NX NY" if d == 2 else "NX NY NZ"
    try:
        counts = [int(t) for t in texts]
    except ValueError:
        counts = []
    if len(counts) != d or min(counts) < 1:
        raise InputError(f"--grid needs {d} positive integers {want} for {d}D data, got "
                         f"{' '.join(texts)!r}")
    return counts


def _bounds(texts, d: int) -> np.ndarray:
    want = "XMIN XMAX YMIN YMAX" + ("" if d == 2 else " ZMIN ZMAX")
    try:
        b = np.array([float(t) for t in texts])
    except ValueError:
        b = np.zeros(0)
    if b.size != 2 * d or not np.isfinite(b).all():
        raise InputError(f"--bounds needs {2 * d} finite numbers {want}, got "
                         f"{' '.join(texts)!r}")
    b = b.reshape(d, 2)
    bad = np.flatnonzero(~(b[:, 0] < b[:, 1]))
    if bad.size:
        a = AXES[bad[0]]
        raise InputError(f"--bounds: {a.upper()}MIN must be below {a.upper()}MAX, got "
                         f"{b[bad[0], 0]:g} and {b[bad[0], 1]:g}")
    return b


def grid_points(counts, bounds) -> np.ndarray:
    """The (prod(counts), d) points of the regular grid with ``counts[k]`` points from
    ``bounds[k, 0]`` to ``bounds[k, 1]`` along axis k, x varying fastest."""
    axes = [np.linspace(lo, hi, n) for n, (lo, hi) in zip(counts, bounds)]
    mesh = np.meshgrid(*axes[::-1], indexing="ij")
    return np.stack([m.ravel() for m in mesh[::-1]], axis=1)


def _inside_count(p: np.ndarray, q: np.ndarray) -> int:
    """How many queries the interpolator evaluates: inside the hull or on it (its test)."""
    from ..coordinates.interp_hull import HullTest
    return int(HullTest(p).inside(q)[0].size)


def _table(itp, q, coords, values, gradient: bool):
    """The output table (queries, values[, gradients by coordinate]) and its header."""
    cols = [q, itp(q)]
    names = coords + values
    if gradient:
        g = itp.gradient(q)                  # (m, K, d)
        for k, c in enumerate(coords):
            cols.append(g[:, :, k])
            names += [f"d{v}/d{c}" for v in values]
    return np.column_stack(cols), ",".join(names)


def _write(path: str, table: np.ndarray, header: str):
    try:
        np.savetxt(path, table, delimiter=",", header=header, comments="")
    except OSError as err:
        raise InputError(f"cannot write output file {path!r}: {err.strerror}") from None
