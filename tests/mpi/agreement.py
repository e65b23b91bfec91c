"""What the MPI tests compare: a rank's result against the serial one."""
import numpy as np


def rel(a, b) -> float:
    """The relative difference ``|a - b| / |b|`` in the 2-norm."""
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))
