"""The ``skfem-nem`` command line.

``skfem-nem interpolate NODES QUERIES -o OUT`` interpolates scattered data with
natural-neighbour coordinates: NODES is a CSV file with columns ``x, y, value``
(more value columns allowed), QUERIES a CSV with columns ``x, y``; OUT gets
``x, y`` and the interpolated values (and with ``--gradient`` their x and y
derivatives). Lines starting with ``#`` and a non-numeric header line are
skipped.
"""
from __future__ import annotations

import argparse
import sys

import numpy as np


def _read_csv(path: str, min_cols: int, what: str) -> np.ndarray:
    try:
        with open(path) as fh:
            lines = [ln for ln in fh if ln.strip() and not ln.lstrip().startswith("#")]
    except OSError as err:
        raise SystemExit(f"skfem-nem: cannot read {what} file {path!r}: {err.strerror}")
    if lines and not _numeric(lines[0]):
        lines = lines[1:]
    rows = []
    for k, ln in enumerate(lines, 1):
        try:
            rows.append([float(v) for v in ln.replace(";", ",").split(",")])
        except ValueError:
            raise SystemExit(f"skfem-nem: {what} file {path!r}: data line {k} is not numeric: "
                             f"{ln.strip()!r}")
    if not rows:
        raise SystemExit(f"skfem-nem: {what} file {path!r} holds no data")
    ncol = {len(r) for r in rows}
    if len(ncol) != 1 or min(ncol) < min_cols:
        raise SystemExit(f"skfem-nem: {what} file {path!r} needs at least {min_cols} columns on "
                         f"every line (found {sorted(ncol)})")
    return np.array(rows)


def _numeric(line: str) -> bool:
    try:
        [float(v) for v in line.replace(";", ",").split(",")]
        return True
    except ValueError:
        return False


def interpolate(args) -> int:
    from .coordinates import natural_neighbour_coordinates

    nodes = _read_csv(args.nodes, 3, "nodes")
    queries = _read_csv(args.queries, 2, "queries")[:, :2]
    values = nodes[:, 2:]
    try:
        out = natural_neighbour_coordinates(nodes[:, :2], queries, gradient=args.gradient,
                                            kind=args.kind, undefined="nan")
    except ValueError as err:
        raise SystemExit(f"skfem-nem: {err}")
    if args.gradient:
        Phi, (Dx, Dy) = out
        cols = [Phi @ values, Dx @ values, Dy @ values]
    else:
        cols = [out @ values]
    k = values.shape[1]
    names = ["x", "y"] + [f"value{j}" for j in range(k)]
    if args.gradient:
        names += [f"d_value{j}_dx" for j in range(k)] + [f"d_value{j}_dy" for j in range(k)]
    table = np.column_stack([queries] + cols)
    np.savetxt(args.output, table, delimiter=",", header=",".join(names), comments="")
    print(f"wrote {table.shape[0]} interpolated point(s) to {args.output}")
    return 0


def main(argv=None) -> int:
    from . import __version__

    ap = argparse.ArgumentParser(prog="skfem-nem", description="The Natural Element Method "
                                 "(Braun & Sambridge 1995) for scikit-fem.")
    ap.add_argument("--version", action="version", version=f"skfem-nem {__version__}")
    sub = ap.add_subparsers(dest="command")
    ip = sub.add_parser("interpolate", help="natural-neighbour interpolation of scattered data",
                        description=__doc__.split("\n\n")[1])
    ip.add_argument("nodes", help="CSV: x, y, value[, value...] per node")
    ip.add_argument("queries", help="CSV: x, y per query point (inside the nodes' convex hull)")
    ip.add_argument("-o", "--output", default="interpolated.csv", help="output CSV file")
    ip.add_argument("--kind", choices=["sibson", "laplace"], default="sibson",
                    help="natural-neighbour coordinates to use (default: sibson)")
    ip.add_argument("--gradient", action="store_true",
                    help="also write the gradient (NaN at nodes and on the hull)")
    args = ap.parse_args(argv)
    if args.command == "interpolate":
        return interpolate(args)
    ap.print_help()
    return 0


if __name__ == "__main__":
    sys.exit(main())
