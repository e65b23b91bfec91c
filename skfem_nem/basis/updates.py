"""Local updates of a natural-neighbour basis after the mesh has changed a little.

After a few flips, an injected node or a node moved, most triangles keep their quadrature
points and their natural neighbours, so their coordinates and gradients are those of the
previous basis. The paper says it for injection ("only those elements of the matrix that
correspond to the new nodes and their neighbours need be recomputed"); this module finds
those triangles and splices the recomputed rows into the kept ones.

Which triangles keep their functions
------------------------------------
The coordinates at a point x depend only on its *conflict set* S(x), the Delaunay triangles
whose circumcircle holds x, and on the positions of their vertices (the natural neighbours
of x): the area method builds the stolen Voronoi areas from those circumcentres. S(x) is
found by a walk from the triangle holding x through neighbours whose circumcircle holds x.
Call a triangle *removed* if it is no longer in its slot with the same vertices at the same
positions (flipped, split, a vertex moved or taken out). If no removed triangle is in S(x)
or next to a triangle of S(x), the walk in the new mesh visits the same triangles with the
same neighbours and finds the same S(x): the coordinates at x are unchanged. A removed
triangle in S(x) has all three vertices among x's natural neighbours, one next to S(x)
shares an edge with it, so two. Hence a triangle whose slot and vertices are unchanged keeps
its functions unless its stencil (the natural neighbours of all its points) holds two or
more vertices of removed or new triangles: a test on the stencils alone, conservative, and
exact in what it keeps. On a constrained triangulation the walk does not cross segments:
the ends of an edge that became or ceased to be a segment count as such vertices too.
"""
import numpy as np
import scipy.sparse as sp
from numba import njit
from skfem import MeshTri

from ..geometry.constrained import segments_of
from ..geometry.meshes import adopt, own_triangulation

__all__ = ["changed_triangles", "gather_rows", "kept_elements", "obstacle",
           "segment_change", "splice_rows", "updated_matrix"]


def changed_triangles(p_old, t_old, p_new, t_new):
    """Which triangles of the old and of the new mesh are not kept (``(old, new)`` boolean
    masks over their slots), and ``marked`` (n,) the nodes that are vertices of any of them.

    ``p`` (n, 2) nodes and ``t`` (nt, 3) triangles. A node moved (or past the end of the
    other node array) changes every triangle it is a vertex of; a slot whose vertices
    differ (or that the other mesh does not have) is changed in both."""
    n = max(p_old.shape[0], p_new.shape[0])
    m = min(p_old.shape[0], p_new.shape[0])
    moved = np.ones(n, dtype=bool)
    moved[:m] = (p_old[:m] != p_new[:m]).any(axis=1)
    k = min(t_old.shape[0], t_new.shape[0])
    same = (t_old[:k] == t_new[:k]).all(axis=1)
    old = np.ones(t_old.shape[0], dtype=bool)
    new = np.ones(t_new.shape[0], dtype=bool)
    old[:k] = new[:k] = ~same
    old |= moved[t_old].any(axis=1)
    new |= moved[t_new].any(axis=1)
    marked = np.zeros(n, dtype=bool)
    marked[t_old[old].ravel()] = True
    marked[t_new[new].ravel()] = True
    return old, new, marked


def kept_elements(stencil_ptr, stencil_nodes, old_changed, new_changed, marked):
    """(nt_new,) True for the new mesh's triangles whose functions are the old basis' in
    the same slot: unchanged in both meshes, with fewer than two marked stencil nodes."""
    keep = ~new_changed
    k = min(old_changed.size, new_changed.size)
    keep[:k] &= ~old_changed[:k]
    _drop_marked(stencil_ptr, stencil_nodes, marked, keep)
    return keep


@njit(cache=True)
def _drop_marked(ptr, sten, marked, keep):
    """keep[e] = False where e's stencil holds two or more marked nodes."""
    for e in range(keep.shape[0]):
        if not keep[e]:
            continue
        c = 0
        for k in range(ptr[e], ptr[e + 1]):
            if marked[sten[k]]:
                c += 1
        if c >= 2:
            keep[e] = False


def obstacle(basis, mesh):
    """Why ``basis.updated(mesh)`` cannot be (a sentence), or None."""
    if basis.tind is not None or basis.mesh.dim() != 2 or basis.method != "area":
        return ("updated() needs a 2D basis on all of its mesh's triangles with the area "
                "method; build a new basis")
    if not isinstance(mesh, MeshTri):
        return f"updated() needs a MeshTri, got {type(mesh).__name__}"
    if basis.order != 1:
        return ("updated() keeps the functions of unchanged triangles, but the quadratic "
                "functions' dofs are numbered by the mesh's edges, which change: build a "
                "new basis")
    for what, m in (("this basis' mesh", basis.mesh), ("the new mesh", mesh)):
        if not own_triangulation(m, adopt(m, basis.method)):
            return (f"{what} is not its own (constrained) Delaunay triangulation (a "
                    f"non-convex boundary, holes or other triangles): build a new basis")
    return None


def segment_change(old_tri, new_tri) -> np.ndarray:
    """The nodes of the segments that are constrained in one triangulation and not in the
    other: the walks for conflict sets cross an edge unless it is a segment, so a
    triangle next to such an edge counts as changed."""
    return segments_of(np.setxor1d(old_tri.segment_keys, new_tri.segment_keys)).ravel()


def updated_matrix(form, A, old, new):
    """The bilinear ``form`` assembled on the basis ``new`` (``old.updated(mesh)``), from
    ``A``, the same form assembled on ``old``: the contributions of the triangles that
    ``new`` recomputed replace those ``old`` had in their slots, so the cost is the
    assembly on those triangles plus one sparse sum. Equal to ``form.assemble(new)`` to
    round-off, for forms whose coefficients are the quadrature points (``w.x``) and
    constants: nothing else is passed to the form."""
    keep = getattr(new, "kept_elements", None)
    if keep is None:
        raise ValueError("the new basis is not an update (old.updated(mesh)): assemble it")
    if new.update_source() is not old:
        raise ValueError("the new basis is an update of another basis than old: pass the "
                         "basis it was updated from")
    if A.shape != (old.N, old.N):
        raise ValueError(f"A has shape {A.shape}, the old basis {old.N} dofs")
    nto = old.nelems
    kept_old = np.zeros(nto, dtype=bool)
    kept_old[:min(nto, keep.size)] = keep[:nto]
    out = _padded(A.tocsr(), new.N)
    for basis, elems, sign in ((old, np.flatnonzero(~kept_old), -1.0),
                               (new, np.flatnonzero(~keep), 1.0)):
        if elems.size:
            out = out + sign * _padded(form.assemble(basis.subset(elems)).tocsr(), new.N)
    return out.tocsr()


def _padded(A, N):
    """The CSR matrix A (n, n) as an (N, N) one (new dofs last, rows and columns empty)."""
    ptr = np.r_[A.indptr, np.full(N - A.shape[0], A.indptr[-1])]
    return sp.csr_matrix((A.data, A.indices, ptr), shape=(N, N))


def gather_rows(elems, nq, V, G):
    """Values (CSR) and gradients (dim, nnz) of the elements ``elems``' rows of ``V`` and
    ``G`` (``nq`` rows per element), in that order."""
    first = V.indptr[elems * nq]
    length = V.indptr[elems * nq + nq] - first
    pos = np.repeat(first - np.cumsum(length) + length, length) + np.arange(length.sum())
    rows = (elems[:, None] * nq + np.arange(nq)).ravel()
    ptr = np.r_[0, np.cumsum(np.diff(V.indptr)[rows])]
    return sp.csr_matrix((V.data[pos], V.indices[pos], ptr),
                         shape=(rows.size, V.shape[1])), G[:, pos]


def splice_rows(keep, nq, old, part, ncols):
    """Values (CSR) and gradients (dim, nnz) of the new basis: element e's ``nq`` rows
    from the old basis where ``keep[e]`` (same slot), else the next ones of the
    recomputed elements (in slot order).

    ``old`` and ``part`` (None if nothing was recomputed) are (CSR values, gradients on
    their pattern); ``ncols`` the new number of nodes."""
    keep = np.ascontiguousarray(keep)
    V, G = old
    old = (V.indptr, V.indices, V.data, G)
    if part is None:
        new = (np.zeros(1, np.int64), np.zeros(0, np.int64), np.zeros(0), G[:, :0])
    else:
        new = (part[0].indptr, part[0].indices, part[0].data, part[1])
    count = np.zeros(keep.size * nq + 1, np.int64)
    _row_lengths(keep, nq, old[0], new[0], count)
    ptr = np.cumsum(count)
    nnz = int(ptr[-1])
    idx = np.empty(nnz, old[1].dtype)
    new = (new[0], new[1].astype(old[1].dtype, copy=False), new[2], new[3])
    val = np.empty(nnz)
    grad = np.empty((old[3].shape[0], nnz))
    _copy_rows(keep, nq, *old, *new, ptr, idx, val, grad)
    return sp.csr_matrix((val, idx, ptr), shape=(keep.size * nq, ncols)), grad


@njit(cache=True)
def _row_lengths(keep, nq, ip_old, ip_new, count):
    j = 0
    for e in range(keep.shape[0]):
        for q in range(nq):
            if keep[e]:
                r = e * nq + q
                count[r + 1] = ip_old[r + 1] - ip_old[r]
            else:
                s = j * nq + q
                count[e * nq + q + 1] = ip_new[s + 1] - ip_new[s]
        if not keep[e]:
            j += 1


@njit(cache=True)
def _copy_rows(keep, nq, ip_old, ix_old, v_old, g_old, ip_new, ix_new, v_new, g_new,
               ptr, idx, val, grad):
    """An element's rows are one contiguous block in each array: copied as such."""
    j = 0
    for e in range(keep.shape[0]):
        p = ptr[e * nq]
        if keep[e]:
            a, b = ip_old[e * nq], ip_old[e * nq + nq]
            _block(ix_old, v_old, g_old, a, b, p, idx, val, grad)
        else:
            a, b = ip_new[j * nq], ip_new[j * nq + nq]
            _block(ix_new, v_new, g_new, a, b, p, idx, val, grad)
            j += 1


@njit(cache=True, inline="always")
def _block(ix, v, g, a, b, p, idx, val, grad):
    idx[p:p + b - a] = ix[a:b]
    val[p:p + b - a] = v[a:b]
    for c in range(grad.shape[0]):
        grad[c, p:p + b - a] = g[c, a:b]
