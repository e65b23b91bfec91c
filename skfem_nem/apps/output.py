"""Output in the formats other tools open: VTU files with a ParaView ``.pvd``
time-series index, and CSV logs.

A mesh whose connectivity changes every step cannot be stored as one XDMF
time series (meshio keeps one mesh for all steps), so each output step is a
VTU file of its own and the ``.pvd`` index lists them with their times. The
index is rewritten atomically after every file, so an interrupted run keeps
every completed step readable.
"""
from __future__ import annotations

import csv
import math
import os
import tempfile
from pathlib import Path
from typing import Dict, Optional
from xml.sax.saxutils import quoteattr

import numpy as np

__all__ = ["write_vtu", "PVDWriter", "CSVLog", "atomic_write_text", "read_csv_columns"]


def atomic_write_text(path, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file and a rename."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as fh:
            fh.write(text)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise


def write_vtu(path, points: np.ndarray, triangles: np.ndarray,
              point_data: Optional[Dict[str, np.ndarray]] = None,
              cell_data: Optional[Dict[str, np.ndarray]] = None) -> None:
    """Write a triangle or tetrahedron mesh with data as a VTU file (via meshio).

    Parameters
    ----------
    points
        (n, 2) node coordinates (written with z = 0), or (n, 3).
    triangles
        (nt, 3) vertex indices of triangles, or (nt, 4) of tetrahedra.
    point_data
        Named arrays (n,) or (n, k); 2-vectors are padded to 3 components so
        ParaView shows them as vectors.
    cell_data
        Named arrays (nt,) or (nt, k).
    """
    import meshio
    points = np.asarray(points, dtype=float)
    pts = np.c_[points, np.zeros(points.shape[0])] if points.shape[1] == 2 else points

    def pad(a):
        a = np.asarray(a, dtype=float)
        if a.ndim == 2 and a.shape[1] == 2:
            return np.c_[a, np.zeros(a.shape[0])]
        return a

    pd = {k: pad(v) for k, v in (point_data or {}).items()}
    cd = {k: [pad(v)] for k, v in (cell_data or {}).items()}
    for k, v in pd.items():
        if v.shape[0] != pts.shape[0]:
            raise ValueError(f"point data {k!r} has {v.shape[0]} rows, the mesh "
                             f"{pts.shape[0]} nodes")
    for k, v in cd.items():
        if v[0].shape[0] != len(triangles):
            raise ValueError(f"cell data {k!r} has {v[0].shape[0]} rows, the mesh "
                             f"{len(triangles)} triangles")
    cells = np.asarray(triangles, dtype=np.int64)
    kind = {3: "triangle", 4: "tetra"}[cells.shape[1]]
    mesh = meshio.Mesh(pts, [(kind, cells)],
                       point_data=pd, cell_data=cd)
    path = Path(path)
    tmp = path.with_name(path.stem + ".tmp" + path.suffix)
    mesh.write(tmp)
    os.replace(tmp, path)


class PVDWriter:
    """A ParaView ``.pvd`` index of VTU files over time.

    ``add(time, filename)`` appends an entry and rewrites the index
    atomically. Existing entries are read back when the index exists (so a
    restarted run continues it); entries after ``keep_until`` time are
    dropped on construction.
    """

    def __init__(self, path, keep_until: Optional[float] = None):
        self.path = Path(path)
        self.entries = []
        if self.path.exists() and keep_until is not None:
            import re
            text = self.path.read_text()
            for t, f in re.findall(r'timestep="([^"]+)"[^>]*file="([^"]+)"', text):
                if float(t) <= keep_until * (1 + 1e-12) + 1e-300:
                    self.entries.append((float(t), f))

    def add(self, time: float, filename: str) -> None:
        self.entries.append((float(time), str(filename)))
        lines = ['<?xml version="1.0"?>',
                 '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">',
                 "  <Collection>"]
        for t, f in self.entries:
            lines.append(f'    <DataSet timestep="{t:.17g}" group="" part="0" '
                         f"file={quoteattr(f)}/>")
        lines += ["  </Collection>", "</VTKFile>", ""]
        atomic_write_text(self.path, "\n".join(lines))


class CSVLog:
    """Rows of named values appended to a CSV file (header from the first row).

    Every row is flushed at once, so an interrupted run keeps all completed
    rows. With ``keep_until`` an existing file is truncated to the rows whose
    ``time`` does not exceed it (for restarts).
    """

    def __init__(self, path, keep_until: Optional[float] = None):
        self.path = Path(path)
        self.fields: Optional[list] = None
        if self.path.exists() and keep_until is not None:
            with open(self.path, newline="") as fh:
                rows = list(csv.DictReader(fh))
            rows = [r for r in rows if float(r["time"]) <= keep_until * (1 + 1e-12)]
            if rows:
                self.fields = list(rows[0].keys())
                with open(self.path, "w", newline="") as fh:
                    w = csv.DictWriter(fh, fieldnames=self.fields)
                    w.writeheader()
                    w.writerows(rows)
            else:
                self.path.unlink()
        elif self.path.exists():
            self.path.unlink()

    def append(self, row: Dict[str, float]) -> None:
        new = not self.path.exists()
        if self.fields is None:
            self.fields = list(row.keys())
        elif not new and set(row) - set(self.fields):
            self._widen([k for k in row if k not in self.fields])
        with open(self.path, "a", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=self.fields, extrasaction="ignore")
            if new:
                w.writeheader()
            w.writerow(row)
            fh.flush()


    def _widen(self, more: list) -> None:
        """Add the columns ``more`` (a run restarted from an older version's output
        reports more): the file rewritten with them, empty in the rows before."""
        with open(self.path, newline="") as fh:
            rows = list(csv.DictReader(fh))
        self.fields = self.fields + more
        with open(self.path, "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=self.fields)
            w.writeheader()
            w.writerows(rows)


def read_csv_columns(path) -> Dict[str, np.ndarray]:
    """Columns of a CSV log written by :class:`CSVLog` (an empty value is NaN)."""
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    return {k: np.array([float(r[k]) if r[k] != "" else np.nan for r in rows])
            for k in (rows[0] if rows else {})}


def next_output_time(time: float, interval: float) -> float:
    """The first multiple of ``interval`` after ``time`` (a run's next output)."""
    return (math.floor(time / interval + 1e-9) + 1) * interval


def progress_bar(end_time: float, time: float, desc: str):
    """A tqdm bar over the run's time, from ``time`` to ``end_time``."""
    from tqdm import tqdm
    return tqdm(total=end_time, initial=time, unit="t", desc=desc,
                bar_format="{l_bar}{bar}| t={n:.4g}/{total:.4g} [{elapsed}<{remaining}]"
                           "{postfix}")
