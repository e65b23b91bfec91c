"""The first run after installing: seconds until ``skfem-nem sinking-plate`` has done its
first step, with numba's cache empty (cold: every kernel compiles) and full (warm).

The checkout is installed, not editable, into a fresh virtual environment made with
``--python`` (numba then keeps its cache in the installed package's ``__pycache__``
folders, as for a user's ``pip install .``). A cold run deletes the package's cache files
(``*.nbi``, ``*.nbc``) first; a warm run follows a cold one. Each run is
``skfem-nem sinking-plate --max-steps 1 --quiet``: start-up, mesh, one step and the
outputs (the warm time is the part that is not compilation). Best of ``--repeat``.

Prints a markdown table. Takes about two minutes per repeat::

    python benchmarks/first_run.py --out out/first_run --repeat 2
"""
import argparse
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def make_venv(folder: Path, python: str) -> Path:
    """A fresh virtual environment in ``folder`` with this checkout installed; its python."""
    subprocess.run([python, "-m", "venv", "--clear", str(folder)], check=True)
    py = folder / "bin" / "python"
    subprocess.run([str(py), "-m", "pip", "install", "-q", str(ROOT)], check=True)
    return py


def package_folder(py: Path) -> Path:
    """Where the environment's python imports skfem_nem from."""
    out = subprocess.run([str(py), "-c", "import os, skfem_nem; "
                          "print(os.path.dirname(skfem_nem.__file__))"],
                         check=True, capture_output=True, text=True)
    return Path(out.stdout.strip())


def clear_cache(package: Path) -> int:
    """Delete numba's cache files of the installed package; how many there were."""
    files = [f for pattern in ("*.nbi", "*.nbc") for f in package.rglob(pattern)]
    for f in files:
        f.unlink()
    return len(files)


def first_step_seconds(py: Path, out: Path) -> float:
    """Wall seconds of ``skfem-nem sinking-plate --max-steps 1`` in the environment."""
    cmd = [str(py), "-m", "skfem_nem.apps.cli", "sinking-plate", "-o", str(out),
           "--max-steps", "1", "--quiet"]
    t = time.perf_counter()
    subprocess.run(cmd, check=True, capture_output=True)
    return time.perf_counter() - t


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="out/first_run",
                    help="folder for the virtual environment and the runs' outputs")
    ap.add_argument("--python", default=sys.executable,
                    help="the interpreter the virtual environment is made with")
    ap.add_argument("--repeat", type=int, default=2)
    a = ap.parse_args(argv)
    out = Path(a.out).resolve()
    py = make_venv(out / "venv", a.python)
    package = package_folder(py)
    cold, warm, nfiles = [], [], 0
    for _ in range(a.repeat):
        clear_cache(package)
        cold.append(first_step_seconds(py, out / "run"))
        nfiles = len(list(package.rglob("*.nbi")))
        warm.append(first_step_seconds(py, out / "run"))
    print(f"First step of `skfem-nem sinking-plate` (--max-steps 1), seconds, best of "
          f"{a.repeat}; the cold run wrote {nfiles} cache index files (one per kernel)\n")
    print("| numba cache | seconds | runs |")
    print("|---|---|---|")
    for name, ts in (("cold (empty)", cold), ("warm (full)", warm)):
        print(f"| {name} | {min(ts):.1f} | {', '.join(f'{t:.1f}' for t in ts)} |")
    print(f"| compilation (cold - warm) | {min(cold) - min(warm):.1f} | |")


if __name__ == "__main__":
    main()
