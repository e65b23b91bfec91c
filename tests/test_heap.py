"""parallel.heap: with glibc's mmap threshold fixed, arrays freed between live ones are
given back to the system (a fresh process per case, as the setting is process-wide)."""
import subprocess
import sys

import pytest

from skfem_nem.parallel.heap import map_large_blocks

# glibc's mmap of large blocks off, as Open MPI sets it when MPI starts (case "mpi"), or
# its threshold raised to 20 MB by a 20 MB array freed (case "grown"): then 1 MB arrays
# come from the heap, and every other one freed leaves holes that the resident memory
# keeps; map_large_blocks after either (cases "mpi fixed", "grown fixed")
SCRIPT = """
import ctypes, sys
import numpy as np
from skfem_nem.parallel.heap import map_large_blocks
if "mpi" in sys.argv[1]:
    assert ctypes.CDLL("libc.so.6").mallopt(-4, 0)
big = np.ones(20 * 2**17)
del big
if "fixed" in sys.argv[1]:
    assert map_large_blocks()
arrays = [np.ones(2**17) for _ in range(200)]   # 200 arrays of 1 MB
del arrays[::2]                                  # 100 MB freed between 100 MB kept
with open("/proc/self/status") as fh:
    print(next(int(l.split()[1]) for l in fh if l.startswith("VmRSS")) // 1024)
"""


def _resident_mb(case: str) -> int:
    out = subprocess.run([sys.executable, "-c", SCRIPT, case], capture_output=True,
                         text=True, check=True)
    return int(out.stdout)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's malloc")
@pytest.mark.parametrize("case", ["grown", "mpi"])
def test_freed_arrays_go_back_to_the_system(case):
    kept, fixed = _resident_mb(case), _resident_mb(case + " fixed")
    assert kept - fixed > 60, (kept, fixed)


def test_a_bad_threshold_is_named():
    for bad in (0, -1, 2**30, 1.5):
        with pytest.raises(ValueError, match=f"threshold must be .* got {bad!r}"):
            map_large_blocks(bad)
