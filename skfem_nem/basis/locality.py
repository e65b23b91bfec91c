"""Dof orders that keep a matrix row's entries near each other in memory, and renumbering.

Why: a product with a natural-neighbour matrix is bound by memory, and its cost depends on
where a row's columns lie. A scikit-fem basis numbers the nodal dofs first and the edge dofs
after them, and the nodes come in the order they were given (random nodes: at random), so a
row of the quadratic Poisson matrix (111 entries) reads ``x`` all over the vector. Numbered
along a Hilbert curve through the nodes, each node followed by its edges' dofs, the same
product at 127,961 unknowns took 5.7 ms against 9.2 ms (docs/quadratic.md, "Products in a
local order"). :func:`renumbered` applies such an order to a matrix with one copy of its
rows; the distributed assembly (:mod:`skfem_nem.parallel.petsc`) renumbers its rows with it
too.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numba import njit, prange

from ..geometry.nodesets import hilbert_order, morton_order

__all__ = ["dof_locality_order", "inverse_order", "renumbered"]


def inverse_order(order: np.ndarray) -> np.ndarray:
    """The new number of each old unknown under ``order`` (new ``i`` is old
    ``order[i]``).

    >>> inverse_order(np.array([2, 0, 1])).tolist()
    [1, 2, 0]
    """
    order = np.asarray(order)
    new = np.empty_like(order)
    new[order] = np.arange(order.size, dtype=order.dtype)
    return new


def renumbered(A: sp.csr_matrix, rows: np.ndarray, new: np.ndarray,
               sort: bool = True) -> sp.csr_matrix:
    """The rows ``rows`` of ``A`` (old numbers, in their new order) with the columns
    renumbered by ``new`` (:func:`inverse_order`): ``A[order][:, order]`` restricted to
    those rows, made as one copy of the rows (scipy's two fancy indexings make two of the
    whole matrix). ``sort``: each row's columns sorted, as PETSc's preallocation wants; a
    product does not need it (at 127,961 unknowns and 14 million entries the sort took
    0.1 s, the copy 0.03 s, and a product took 5.6 ms unsorted against 6.2 ms sorted)."""
    A = sp.csr_matrix(A)
    rows = np.asarray(rows, dtype=np.int64)
    lengths = np.diff(A.indptr)[rows]
    ptr = np.zeros(rows.size + 1, np.int64)
    np.cumsum(lengths, out=ptr[1:])
    indices, data = np.empty(ptr[-1], A.indices.dtype), np.empty(ptr[-1], A.data.dtype)
    _renumbered_rows(A.indptr, A.indices, A.data, rows, np.asarray(new), ptr, indices, data)
    out = sp.csr_matrix((data, indices, ptr), shape=(rows.size, A.shape[1]))
    out.has_sorted_indices = False
    if sort:
        out.sort_indices()
    return out


@njit(cache=True, parallel=True)
def _renumbered_rows(indptr, indices, data, rows, new, ptr, out_indices, out_data):
    """Row ``r`` of the result: row ``rows[r]`` of the CSR arrays, columns through
    ``new``."""
    for r in prange(rows.shape[0]):
        s, o = indptr[rows[r]], ptr[r]
        for k in range(ptr[r + 1] - o):
            out_indices[o + k] = new[indices[s + k]]
            out_data[o + k] = data[s + k]


def dof_locality_order(basis, free: np.ndarray) -> np.ndarray:
    """An order of the dofs ``free`` of ``basis`` (positions in ``free``) in which each
    node's dofs come together along a Hilbert curve through the nodes (a Z-order curve in
    3D): a node's dof of every component, then the dofs of the edges it is the first node
    of (along the curve). Scalar or vector (``ElementVector``), nodal and edge dofs (the
    edge dofs of the quadratic basis; a basis without them orders its nodes)."""
    free = np.asarray(free, dtype=np.int64)
    mesh = basis.mesh
    nodal = np.atleast_2d(basis.nodal_dofs)
    facet = np.atleast_2d(basis.facet_dofs)
    curve = hilbert_order if mesh.p.shape[0] == 2 else morton_order
    rank = inverse_order(curve(mesh.p.T))
    ncomp, slot = nodal.shape[0], np.full(basis.N, -1, np.int64)
    kind = np.zeros(basis.N, np.int64)
    comp = np.zeros(basis.N, np.int64)
    for c in range(ncomp):
        slot[nodal[c]], comp[nodal[c]] = rank, c
    if facet.size:
        ends = rank[np.asarray(mesh.facets)]
        first = ends.min(axis=0)
        second = 1 + inverse_order(np.argsort(ends.max(axis=0), kind="stable"))
        for c in range(facet.shape[0]):
            slot[facet[c]], comp[facet[c]], kind[facet[c]] = first, c, second
    if (slot[free] < 0).any():
        raise ValueError("free holds dofs that are neither nodal nor edge dofs of the basis")
    return np.lexsort((comp[free], kind[free], slot[free])).astype(np.int64)
