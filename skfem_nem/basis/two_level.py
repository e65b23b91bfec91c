"""A two-level solver for the matrices of the quadratic natural-neighbour functions.

Why a solver of its own: the quadratic natural-neighbour functions are smooth and wide (about
110 matrix entries a row against P2's 11), so oscillating dof patterns cost little energy and
smoothed aggregation on the whole matrix needs two to three times P2's iterations (105 against
45 at 8,000 unknowns, 146 against 53 at 32,000: ``benchmarks/quadratic_solvers.py``). The
nodes make a coarse level that costs no new basis: :func:`nested_prolongation` maps nodal
values to the quadratic function with those nodal values and the edge values at the averages
of their two nodes. It interpolates the nodal values and reproduces linear fields exactly, as
a coarse space must; it is not the linear natural-neighbour function of the values (pairs of
natural neighbours without an edge take their polar values through a triangle, which only
for a linear field gives the average). The Galerkin product ``P^T A P`` is the coarse
matrix. The smoother must take what Jacobi leaves: a node's edge dofs can oscillate at
little cost in energy, so each node's star (its dof and its edges' dofs) is solved as one
block (:func:`star_smoother`, overlapping additive Schwarz) inside Chebyshev.
:class:`TwoLevelPreconditioner` combines the two, with a smoothed-aggregation V-cycle or
K-cycle on the coarse matrix. As CG's preconditioner it takes fewer iterations than P2 with
pyamg (docs/quadratic.md). Its products are bound by memory, so it works in the order of
:func:`~skfem_nem.basis.locality.dof_locality_order` (a node's dofs together, the nodes along
a Hilbert curve) and multiplies on the matrix's upper triangle on numba's threads.
:func:`skfem_nem.basis.solvers.natural_neighbour_solver` makes it a solver for scikit-fem's
``solve``.
"""
from __future__ import annotations

from typing import Optional

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numba import njit

from .locality import dof_locality_order, inverse_order, renumbered
from .multigrid import k_cycle, smoothed_aggregation, v_cycle
from .rigid_modes import rigid_modes
from .symmetric_rows import SymmetricRows

__all__ = ["nested_prolongation", "star_dofs", "star_smoother", "TwoLevelPreconditioner",
           "TwoLevelSpace", "CHEBYSHEV_DEGREE", "SOLVER_COARSE_SMOOTHER"]

# degree of the Chebyshev smoother on the quadratic matrix, preconditioned by the node stars
# (star_smoother). With Jacobi in place of the stars, degree 5 took 34 / 44 / 67 CG
# iterations at 8,000 / 32,000 / 128,000 unknowns (3: 46 / 61 / 83): the cheap oscillating
# patterns of a node's edge dofs are what Jacobi leaves and the stars take
CHEBYSHEV_DEGREE = 3
# the smoother's interval, relative to the spectral radius of the Jacobi-scaled matrix
# (pyamg's own Chebyshev bounds)
CHEBYSHEV_BOUNDS = (1.0 / 30.0, 1.1)
# strength of connection and smoother of the smoothed aggregation on the coarse matrix (its
# coarsest level: basis.multigrid.MAX_COARSE, solved by sparse LU): the coarse matrix has
# some 42 entries a row, and keeping them all coarsened 31,812 nodes to 1,679 in one level
# and took 36 CG iterations at 128,000 unknowns; theta 0.1 coarsens to 6,856 and took 26
# (0.25: 112); Chebyshev as for the viscous blocks (models.stokes_amg)
COARSE_STRENGTH = ("symmetric", {"theta": 0.1})
# (a vector basis' coarse matrix reaches the aggregation in blocks of a node's components,
# where every coarse node has all of them free, so that the strength is a node's and the
# aggregates hold whole nodes: SolCx with the quadratic velocity at 16,000 nodes took 66
# FGMRES iterations and 9.7 s in the solver, against 97 and 18.2 s with components
# aggregated apart)
COARSE_SMOOTHER = ("chebyshev", {"degree": 2})
# the coarse level's smoother in natural_neighbour_solver, whose K-cycles (basis.multigrid)
# take what a V-cycle's coarse levels leave: symmetric Gauss-Seidel. Poisson at 127,961
# unknowns, flexible CG to 1e-8: 20 iterations against 26 with the Chebyshev smoother above
# (V-cycles: 22 and 26)
SOLVER_COARSE_SMOOTHER = ("gauss_seidel", {"sweep": "symmetric"})
# prolongator smoothing of the coarse aggregation (pyamg's default)
COARSE_PROLONGATOR = ("jacobi", {"omega": 4.0 / 3.0})
# the relative difference between a product on the upper triangle and the matrix's own (a
# random vector) above which a matrix is refused as not symmetric: assembled symmetric
# forms differ by round-off, 1e-16 to 1e-14
SYMMETRY_TOL = 1e-10
# Lanczos steps of the spectral-radius estimate of the star-preconditioned matrix (one product
# with the matrix and one with the stars each): at 31,969 unknowns 15 steps gave 5.31 (20: 5.39,
# converged), where 30 power iterations, twice the products, gave 5.24; the set-up at 127,961
# unknowns spent 2.2 s of its 8.3 s in those power iterations
LANCZOS_STEPS = 15


def nested_prolongation(basis) -> sp.csr_matrix:
    """``P`` (N, components x nodes): nodal values to the quadratic natural-neighbour dofs
    of ``basis`` (scalar or ``ElementVector``) with those nodal values and each edge's value
    the average of its nodes', component by component (column ``c n + i``: node i, component
    c): the function interpolates the values and reproduces linear fields. ``ValueError`` for
    any other basis."""
    from .elements import ElementNaturalNeighbour2
    elem = getattr(basis.elem, "elem", basis.elem)     # ElementVector's element
    if not isinstance(elem, ElementNaturalNeighbour2):
        raise ValueError(f"the two-level solver needs the quadratic natural-neighbour "
                         f"element (ElementNaturalNeighbour2), got {type(elem).__name__}")
    nodal, facet = np.atleast_2d(basis.nodal_dofs), np.atleast_2d(basis.facet_dofs)
    ends = np.asarray(basis.mesh.facets)
    n, nf, ncomp = nodal.shape[1], ends.shape[1], nodal.shape[0]
    rows, cols, vals = [], [], []
    for c in range(ncomp):
        rows += [nodal[c], facet[c], facet[c]]
        cols += [c * n + np.arange(n), c * n + ends[0], c * n + ends[1]]
        vals += [np.ones(n), np.full(nf, 0.5), np.full(nf, 0.5)]
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                         shape=(basis.N, ncomp * n))


def star_dofs(basis, free: np.ndarray) -> tuple:
    """``(ptr, idx)``: the star of node i, ``idx[ptr[i]:ptr[i + 1]]``, holds the free dofs
    (positions in ``free``) of node i and of the edges at i, every component; stars with no
    free dof are left out."""
    nodal, facet = np.atleast_2d(basis.nodal_dofs), np.atleast_2d(basis.facet_dofs)
    ends = np.asarray(basis.mesh.facets)
    n = nodal.shape[1]
    where = np.full(basis.N, -1, np.int64)
    where[free] = np.arange(free.size)
    owner = np.concatenate([np.tile(np.arange(n), nodal.shape[0]),
                            np.tile(ends[0], facet.shape[0]), np.tile(ends[1], facet.shape[0])])
    dofs = where[np.concatenate([nodal.ravel(), facet.ravel(), facet.ravel()])]
    keep = dofs >= 0
    owner, dofs = owner[keep], dofs[keep]
    order = np.argsort(owner, kind="stable")
    counts = np.bincount(owner, minlength=n)
    counts = counts[counts > 0]
    ptr = np.zeros(counts.size + 1, np.int64)
    np.cumsum(counts, out=ptr[1:])
    return ptr, dofs[order]


@njit(cache=True)
def _star_inverses(ptr, idx, indptr, indices, data, n, rows, cols, vals):
    """The inverse of A's block on each star, written as COO entries (star after star)."""
    at = np.full(n, -1, np.int64)
    o = 0
    for s in range(ptr.shape[0] - 1):
        m = ptr[s + 1] - ptr[s]
        for a in range(m):
            at[idx[ptr[s] + a]] = a
        block = np.zeros((m, m))
        for a in range(m):
            r = idx[ptr[s] + a]
            for k in range(indptr[r], indptr[r + 1]):
                b = at[indices[k]]
                if b >= 0:
                    block[a, b] = data[k]
        inv = np.linalg.inv(block)
        for a in range(m):
            for b in range(m):
                rows[o] = idx[ptr[s] + a]
                cols[o] = idx[ptr[s] + b]
                vals[o] = 0.5 * (inv[a, b] + inv[b, a])
                o += 1
        for a in range(m):
            at[idx[ptr[s] + a]] = -1


def star_smoother(A: sp.spmatrix, ptr: np.ndarray, idx: np.ndarray) -> sp.csr_matrix:
    """``B = sum_s R_s^T (A_ss)^-1 R_s`` over the stars ``(ptr, idx)`` (:func:`star_dofs`):
    the additive Schwarz preconditioner of the overlapping node stars, symmetric."""
    A = sp.csr_matrix(A)
    nnz = int(np.sum(np.diff(ptr) ** 2))
    rows, cols = np.empty(nnz, np.int64), np.empty(nnz, np.int64)
    vals = np.empty(nnz)
    _star_inverses(ptr, idx, A.indptr, A.indices, A.data.astype(np.float64, copy=False),
                   A.shape[0], rows, cols, vals)
    return sp.csr_matrix((vals, (rows, cols)), shape=A.shape)


def _symmetric_products(A: sp.csr_matrix) -> SymmetricRows:
    """``A`` for products on its upper triangle (:class:`SymmetricRows`: 3.5 ms against
    scipy's 5.7 ms for the quadratic Poisson matrix at 127,961 unknowns on two cores),
    once a product with a random vector is ``A``'s own (``ValueError`` otherwise: the
    matrix is not symmetric, and its lower triangle would be ignored)."""
    S = SymmetricRows(A)
    x = np.random.default_rng(0).normal(size=A.shape[0])
    ax = A @ x
    if not np.linalg.norm(S @ x - ax) <= SYMMETRY_TOL * np.linalg.norm(ax):
        raise ValueError("the matrix is not symmetric: the two-level solver is for "
                         "symmetric positive definite ones")
    return S


def _spectral_radius(A, B) -> float:
    """Largest eigenvalue of ``B A`` (both symmetric positive definite), the largest
    eigenvalue of the Lanczos matrix of :data:`LANCZOS_STEPS` conjugate-gradient steps
    preconditioned by ``B`` from a fixed random right side (an estimate from below)."""
    from scipy.linalg import eigvalsh_tridiagonal
    r = np.random.default_rng(0).normal(size=A.shape[0])
    z = B @ r
    p, rz = z.copy(), float(r @ z)
    alpha, beta = np.empty(LANCZOS_STEPS), np.empty(LANCZOS_STEPS)
    for k in range(LANCZOS_STEPS):
        Ap = A @ p
        alpha[k] = rz / float(p @ Ap)
        r = r - alpha[k] * Ap
        z = B @ r
        rz_new = float(r @ z)
        beta[k], rz = rz_new / rz, rz_new
        p = z + beta[k] * p
    diagonal = 1.0 / alpha
    diagonal[1:] += beta[:-1] / alpha[:-1]
    return float(eigvalsh_tridiagonal(diagonal, np.sqrt(beta[:-1]) / alpha[:-1]).max())


class TwoLevelPreconditioner:
    """Chebyshev smoothing (``degree``) preconditioned by ``smoother`` (a sparse ``B``, e.g.
    :func:`star_smoother`; None: Jacobi), the coarse correction with ``P^T A P``
    (``coarse``: ``"sa"``, pyamg's smoothed aggregation with ``modes`` as its near null
    space and ``coarse_smoother`` on its levels, or ``"direct"``, a sparse LU), smoothing
    again. ``cycle``: the aggregation's ``"V"``-cycle (a symmetric map, for CG) or its
    ``"K"``-cycle (:func:`~skfem_nem.basis.multigrid.k_cycle`, for flexible methods).
    ``blocksize``: the coarse unknowns come in runs of one node's components of this
    length, and the aggregation takes the coarse matrix in such blocks.

    ``A``, ``P`` and ``smoother`` are numbered in one order, which is the caller's order
    ``order`` (new ``i`` is the caller's ``order[i]``; None: the same): called on a
    residual in the caller's order the preconditioner answers in it, and
    :meth:`renumbered` works in its own. ``A`` is kept for products on its upper triangle
    (``A``, a :class:`~skfem_nem.basis.symmetric_rows.SymmetricRows`), so a matrix whose
    lower triangle differs is refused."""

    def __init__(self, A: sp.spmatrix, P: sp.spmatrix, degree: int = CHEBYSHEV_DEGREE,
                 coarse: str = "sa", smoother: Optional[sp.spmatrix] = None,
                 modes: Optional[np.ndarray] = None, order: Optional[np.ndarray] = None,
                 cycle: str = "V", coarse_smoother=COARSE_SMOOTHER, blocksize: int = 1):
        from pyamg.relaxation.chebyshev import chebyshev_polynomial_coefficients
        if coarse not in ("sa", "direct"):
            raise ValueError(f"coarse must be 'sa' or 'direct', got {coarse!r}")
        if cycle not in ("V", "K"):
            raise ValueError(f"cycle must be 'V' or 'K', got {cycle!r}")
        if blocksize < 1 or P.shape[1] % blocksize:
            raise ValueError(f"blocksize must divide the {P.shape[1]} coarse unknowns, got "
                             f"{blocksize!r}")
        self.blocksize = int(blocksize)
        self.A, self.P = sp.csr_matrix(A), sp.csr_matrix(P)
        if order is not None and np.asarray(order).shape != (self.A.shape[0],):
            raise ValueError(f"order must number the matrix's {self.A.shape[0]} rows, got "
                             f"shape {np.asarray(order).shape}")
        self.order = None if order is None else np.asarray(order, dtype=np.int64)
        self.R = self.P.T.tocsr()
        d = self.A.diagonal()
        if not (d > 0).all():
            raise ValueError(f"the matrix has {int((d <= 0).sum())} diagonal entries <= 0: "
                             f"the two-level solver is for symmetric positive definite ones")
        self.B = sp.diags(1.0 / d).tocsr() if smoother is None else sp.csr_matrix(smoother)
        Ac = (self.R @ self.A @ self.P).tocsr()
        # the products: the upper triangle on numba's threads, the CSR copy let go
        self.A = _symmetric_products(self.A)
        rho = _spectral_radius(self.A, self.B)
        lo, hi = CHEBYSHEV_BOUNDS
        self.coef = -chebyshev_polynomial_coefficients(lo * rho, hi * rho, degree)[:-1]
        self.levels = 2
        if coarse == "direct":
            self.coarse = spla.splu(Ac.tocsc()).solve
        else:
            self.coarse = self._coarse_cycle(Ac, modes, cycle, coarse_smoother)

    def _coarse_cycle(self, Ac: sp.csr_matrix, modes: Optional[np.ndarray], cycle: str,
                      smoother):
        """A cycle of smoothed aggregation on the coarse matrix (``modes``: its near null
        space, None for the constants); counts its levels in ``levels``."""
        if self.blocksize > 1:      # aggregates of whole nodes (see COARSE_STRENGTH)
            Ac = Ac.tobsr(blocksize=(self.blocksize, self.blocksize))
        ml = smoothed_aggregation(Ac, modes, strength=COARSE_STRENGTH, presmoother=smoother,
                                  postsmoother=smoother, smooth=COARSE_PROLONGATOR)
        self.levels = 1 + len(ml.levels)
        if cycle == "K":
            return lambda r: k_cycle(ml, r)
        return lambda r: v_cycle(ml, r)

    def smooth(self, x: Optional[np.ndarray], b: np.ndarray) -> np.ndarray:
        """One Chebyshev step for ``A x = b`` from ``x`` (None: from zero), both in the
        renumbered order (``b[order]``)."""
        r = self.B @ (b if x is None else b - self.A @ x)
        h = self.coef[0] * r
        for c in self.coef[1:]:
            h = c * r + self.B @ (self.A @ h)
        return h if x is None else x + h

    def __call__(self, b: np.ndarray) -> np.ndarray:
        return self.in_basis_order(self.renumbered, b)

    def renumbered(self, b: np.ndarray) -> np.ndarray:
        """The preconditioner on a residual in the renumbered order (``b[order]``)."""
        x = self.smooth(None, b)
        x = x + self.P @ self.coarse(self.R @ (b - self.A @ x))
        return self.smooth(x, b)

    def in_basis_order(self, f, b: np.ndarray) -> np.ndarray:
        """``f`` (a map of vectors in the renumbered order) on ``b`` in the basis's order."""
        return self.to_callers_order(f(self.to_own_order(b)))

    def to_own_order(self, b: np.ndarray) -> np.ndarray:
        """``b``, numbered in the caller's order, in the preconditioner's (``b[order]``)."""
        return b if self.order is None else b[self.order]

    def to_callers_order(self, x: np.ndarray) -> np.ndarray:
        """``x``, numbered in the preconditioner's order, in the caller's."""
        if self.order is None:
            return x
        out = np.empty_like(x)
        out[self.order] = x
        return out


class TwoLevelSpace:
    """What the two-level method takes from the quadratic natural-neighbour ``basis`` (scalar
    or vector) with only the dofs ``free`` unknown, in the order of
    :func:`~skfem_nem.basis.locality.dof_locality_order` (``order``, new ``i`` is the free
    dof at position ``order[i]``): the nested prolongation from the nodal values of the free
    nodal dofs (``prolongation``), the node stars (``stars``) and, for a vector basis, the
    coarse level's near null space (``modes``: translations and rotations of the nodal
    values; None for a scalar basis) and the size of the blocks in which the coarse
    unknowns come, whole nodes first (``blocksize``: the components of a vector basis, 1
    where the nodes with some fixed components leave a remainder). :meth:`preconditioner`
    builds
    :class:`TwoLevelPreconditioner` for a matrix on those dofs; the space is kept while the
    matrix changes (Picard iterations, new viscosities)."""

    def __init__(self, basis, free: np.ndarray, degree: int = CHEBYSHEV_DEGREE):
        P = nested_prolongation(basis)
        self.free, self.degree = np.asarray(free, dtype=np.int64), degree
        self.order = dof_locality_order(basis, self.free)
        self.new = inverse_order(self.order)
        nodal = np.atleast_2d(basis.nodal_dofs).ravel()      # column c n + i's nodal dof
        where = np.full(basis.N, -1, np.int64)
        where[self.free] = np.arange(self.free.size)
        # the free nodal dofs, the coarse level's unknowns, in the fine level's order, the
        # nodes with every component free first (see _node_blocks)
        coarse = nodal[where[nodal] >= 0]
        columns = np.full(basis.N, -1, np.int64)
        columns[nodal] = np.arange(nodal.size)
        ncomp, nn = np.atleast_2d(basis.nodal_dofs).shape[0], basis.mesh.p.shape[1]
        whole = np.bincount(columns[coarse] % nn, minlength=nn)[columns[coarse] % nn] == ncomp
        coarse = coarse[np.lexsort((self.new[where[coarse]], ~whole))]
        self.prolongation = P[self.free[self.order]][:, columns[coarse]].tocsr()
        ptr, idx = star_dofs(basis, self.free)
        self.stars = (ptr, self.new[idx])
        # column j of the prolongation is the nodal dof coarse[j]: its rigid modes
        self.modes = rigid_modes(basis, coarse) if ncomp > 1 else None
        self.blocksize = _node_blocks(columns[coarse] % nn, ncomp)

    @property
    def size(self) -> int:
        """Number of free dofs."""
        return self.free.size

    def preconditioner(self, A: sp.spmatrix, cycle: str = "V",
                       coarse_smoother=COARSE_SMOOTHER,
                       node_blocks: bool = True) -> TwoLevelPreconditioner:
        """The two-level preconditioner of ``A`` (on the free dofs, in their order) with
        ``cycle`` and ``coarse_smoother`` on its coarse level, whose aggregation takes a
        vector basis' nodes whole with ``node_blocks`` (where :attr:`blocksize` allows)
        (:class:`TwoLevelPreconditioner`, numbered in ``order``)."""
        if A.shape != (self.size, self.size):
            raise ValueError(f"the matrix is {A.shape[0]} x {A.shape[1]}, the basis has "
                             f"{self.size} free dofs: condense it with the same D")
        A = renumbered(A, self.order, self.new, sort=False)
        return TwoLevelPreconditioner(A, self.prolongation, self.degree,
                                      smoother=star_smoother(A, *self.stars),
                                      modes=self.modes, order=self.order, cycle=cycle,
                                      coarse_smoother=coarse_smoother,
                                      blocksize=self.blocksize if node_blocks else 1)


def _node_blocks(nodes: np.ndarray, ncomp: int) -> int:
    """The block size of the coarse unknowns of the nodes ``nodes`` (one per unknown, in
    the coarse order: the nodes with every component free first, a node's components
    together, then the unknowns of nodes with some components fixed, a free-slip wall's):
    ``ncomp`` where the whole nodes come in runs of ``ncomp`` and the rest are a multiple of
    it (blocks of neighbouring wall nodes' free components), else 1."""
    if ncomp == 1 or nodes.size % ncomp:
        return 1
    counts = np.bincount(nodes)[nodes]
    k = int(np.count_nonzero(counts == ncomp))
    runs = nodes[:k].reshape(-1, ncomp)
    return ncomp if (runs == runs[:, :1]).all() and (counts[k:] < ncomp).all() else 1
