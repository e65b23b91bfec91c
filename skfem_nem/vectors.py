"""Products of vectors shared by every layer's iterative methods: BLAS-free dot and norm.

Why BLAS-free: inside the app a threaded BLAS waited for cores held by numba's threads
(docs/stokes.md); ``einsum`` does not. The Krylov methods of the Stokes solvers
(:mod:`skfem_nem.models.krylov`) and the multigrid cycles of the bases
(:mod:`skfem_nem.basis.multigrid`) both take them from here.
"""
from __future__ import annotations

import numpy as np

__all__ = ["dot", "norm"]


def dot(a: np.ndarray, b: np.ndarray) -> float:
    """``a . b`` without BLAS."""
    return float(np.einsum("i,i->", a, b))


def norm(a: np.ndarray) -> float:
    """Euclidean norm without BLAS (see :func:`dot`)."""
    return float(np.sqrt(dot(a, a)))
