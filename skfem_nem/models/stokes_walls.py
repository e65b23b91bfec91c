"""Walls, prescribed velocities and extra linear constraints of the Stokes problem.

Kept apart from :mod:`skfem_nem.models.stokes` (spaces, forms, assembly, the solve)
because these are conditions on the velocity dofs, read from the mesh's boundary and
from the caller's outlines, and need nothing of the assembly: which dofs the walls fix
(:func:`wall_dofs`), the exact boundary term of the integration by parts of the
divergence (:func:`boundary_flux`), and the net flux through a material outline
(:func:`outline_flux`), a constraint row that keeps a region bounded by nodes
incompressible as a whole.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Optional, Sequence, Tuple, Union

import numpy as np
import scipy.sparse as sp
from numba import njit, prange

if TYPE_CHECKING:  # (only for annotations)
    from . import stokes_bases

# Gauss order on the boundary faces of a tetrahedral mesh for boundary_flux (the
# natural-neighbour functions there are piecewise rational: no rule is exact)
FACE_ORDER = 4

__all__ = ["wall_dofs", "boundary_flux", "outline_flux", "fixed_velocity",
           "walls_fix_pressure", "constraint_rows", "free_columns"]


def wall_dofs(spaces: stokes_bases.StokesSpaces,
              free_slip: Union[str, Sequence[str], None] = "all",
              no_slip: Union[str, Sequence[str], None] = None, tol: float = 1e-9) -> np.ndarray:
    """Velocity dofs fixed to zero by wall conditions.

    ``free_slip`` / ``no_slip``: ``"all"`` (every boundary facet), a list of
    boundary names of the mesh (``mesh.boundaries``; scikit-fem's
    ``mesh.with_defaults()`` names a box's faces ``left``/``right`` (x), ``bottom``/``top``
    (y) and, in 3D, ``front``/``back`` (z)), or None. Free slip fixes the normal component and
    needs axis-aligned walls (edges in 2D, triangles in 3D); a tilted boundary facet
    raises ``ValueError`` naming it.
    """
    mesh = spaces.mesh
    ub = spaces.ubasis

    def facets(spec, what):
        if spec is None:
            return np.zeros(0, dtype=np.int64)
        if isinstance(spec, str) and spec == "all":
            return mesh.boundary_facets()
        names = [spec] if isinstance(spec, str) else list(spec)
        bnd = mesh.boundaries or {}
        out = []
        for nm in names:
            if nm not in bnd:
                raise ValueError(f"{what}: the mesh has no boundary named {nm!r} "
                                 f"(it has {sorted(bnd)})")
            out.append(np.asarray(bnd[nm]))
        return np.concatenate(out) if out else np.zeros(0, dtype=np.int64)

    fixed = []
    ns = facets(no_slip, "no_slip")
    if ns.size:
        fixed.append(ub.get_dofs(ns).all())
    fs = facets(free_slip, "free_slip")
    fs = np.setdiff1d(fs, ns)
    if fs.size:
        axis = _facet_axes(mesh, fs, tol)  # wall x_k = const: fix u^(k+1)
        for k in range(mesh.dim()):
            if (axis == k).any():
                fixed.append(ub.get_dofs(fs[axis == k]).all(f"u^{k + 1}"))
    if not fixed:
        return np.zeros(0, dtype=np.int64)
    return np.unique(np.concatenate(fixed))


def _facet_axes(mesh, facets: np.ndarray, tol: float) -> np.ndarray:
    """The axis (0, 1 or 2) each boundary facet is normal to; ``ValueError`` naming the
    first facet that is tilted (normal to no axis)."""
    p = mesh.p[:, mesh.facets[:, facets]]  # (dim, dim, nf)
    if mesh.dim() == 2:
        d = p[:, 1] - p[:, 0]
        n = np.array([d[1], -d[0]])
    else:
        n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], axis=0)
    size = np.linalg.norm(n, axis=0)
    axis = np.argmax(np.abs(n), axis=0)
    rest = n.copy()
    rest[axis, np.arange(n.shape[1])] = 0.0
    off = np.linalg.norm(rest, axis=0)
    bad = off > tol * size
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise ValueError(f"free slip needs axis-aligned walls: boundary facet {int(facets[k])} "
                         f"with vertices {p[:, :, k].T.tolist()} is tilted "
                         f"({int(bad.sum())} such facet(s))")
    return axis


def boundary_flux(spaces: stokes_bases.StokesSpaces) -> sp.csr_matrix:
    """(np, nu) matrix of ``oint q_i (u . n) ds`` over the boundary facets.

    Exact in 2D: on convex-hull edges both the natural-neighbour velocity and the
    P1 pressure are linear between the edge's two nodes (Simpson weights). In 3D the
    natural-neighbour functions on a hull face are the face's own 2D natural-neighbour
    coordinates, not polynomials: there it is a Gauss rule of order 4 on the faces
    (the term acts only on normal velocities, which walls fix).
    """
    mesh, ub, pb = spaces.mesh, spaces.ubasis, spaces.pbasis
    bf = mesh.boundary_facets()
    if spaces.elements is not None:  # restricted spaces: their triangles' facets
        bf = bf[np.isin(mesh.f2t[0, bf], spaces.elements)]
    if mesh.dim() == 3:
        return _face_flux(spaces, bf)
    a, b = mesh.facets[:, bf]
    d = mesh.p[:, b] - mesh.p[:, a]
    mid = 0.5 * (mesh.p[:, a] + mesh.p[:, b])
    c = mesh.p[:, mesh.t[:, mesh.f2t[0, bf]]].mean(axis=1)
    n = np.array([d[1], -d[0]])                       # normal times length
    n *= np.where(np.einsum("ij,ij->j", n, mid - c) < 0, -1.0, 1.0)  # outward
    pn = pb.dofs.nodal_dofs[0]
    un = ub.dofs.nodal_dofs
    rows, cols, vals = [], [], []
    for qi, qj in ((a, a), (a, b), (b, a), (b, b)):
        w = np.where(qi == qj, 1.0 / 3.0, 1.0 / 6.0)   # int phi_i phi_j ds / length
        for comp in (0, 1):
            rows.append(pn[qi])
            cols.append(un[comp, qj])
            vals.append(w * n[comp])
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                         shape=(pb.N, ub.N))


def _face_flux(spaces: stokes_bases.StokesSpaces, faces: np.ndarray) -> sp.csr_matrix:
    """:func:`boundary_flux` on the boundary triangles ``faces`` of a tetrahedral mesh:
    ``sum_q w_q q_i(x_q) phi_j(x_q) n_c(x_q)`` at the faces' Gauss points."""
    from skfem import FacetBasis

    from ..basis import ElementNaturalNeighbour, NaturalNeighbourFacetBasis

    mesh, ub, pb = spaces.mesh, spaces.ubasis, spaces.pbasis
    nb = NaturalNeighbourFacetBasis(mesh, ElementNaturalNeighbour(), facets=faces,
                                    intorder=FACE_ORDER, coordinates=ub.coordinates)
    fb = FacetBasis(mesh, pb.elem, facets=faces, intorder=FACE_ORDER)
    nf, nq = fb.dx.shape
    corners = mesh.facets[:, faces]                              # (3, nf) the faces' nodes
    lam, n = _face_frames(mesh, corners, np.asarray(fb.global_coordinates()))
    points = np.arange(nf * nq).reshape(nf, nq)
    pn = np.asarray(pb.dofs.nodal_dofs[0])
    Q = sp.csr_matrix(((lam * fb.dx).ravel(), (np.repeat(pn[corners], nq, axis=1).ravel(),
                                               np.tile(points, (3, 1)).ravel())),
                      shape=(pb.N, nf * nq))
    Phi = nb.values_matrix                                       # (nf nq, n nodes)
    nd = ub.dofs.nodal_dofs
    out = sp.csr_matrix((pb.N, ub.N))
    for c in range(3):
        Fc = (Q @ sp.diags(np.repeat(n[c], nq)) @ Phi).tocoo()
        out = out + sp.csr_matrix((Fc.data, (Fc.row, nd[c, Fc.col])), shape=(pb.N, ub.N))
    return out.tocsr()


def _face_frames(mesh, corners: np.ndarray, x: np.ndarray) -> tuple:
    """The barycentric coordinates (3, nf, nq) of the points x (3, nf, nq) in their boundary
    faces ``corners`` (3, nf) -- the P1 pressure's trace there -- and the faces' outward
    unit normals (3, nf), from the faces alone. Not from the tetrahedra behind them:
    a mesh of Qhull's has flat tetrahedra of nodes on one wall (zero volume), whose inverse mapping
    (and so scikit-fem's facet normals and trace values) is NaN. A hull is convex: the
    mean of the nodes lies inside every face's plane. Faces without area (three collinear
    nodes on a wall) get zeros: they carry no weight."""
    a, b, c = (mesh.p[:, corners[k]] for k in range(3))
    e1, e2 = b - a, c - a
    n = np.cross(e1, e2, axis=0)
    length = np.linalg.norm(n, axis=0)
    # a face of three collinear wall nodes has no area, so no weight and no normal: zeros
    face = length > 0
    n = np.where(face, n / np.where(face, length, 1.0), 0.0)
    n *= np.where(np.einsum("ij,ij->j", n, a - mesh.p.mean(axis=1)[:, None]) < 0, -1.0, 1.0)
    # x - a = s e1 + t e2 (the 2 x 2 normal equations of the face's frame)
    r = x - a[:, :, None]
    g11, g12, g22 = (np.einsum("ij,ij->j", u, v) for u, v in ((e1, e1), (e1, e2), (e2, e2)))
    r1, r2 = np.einsum("ij,ijk->jk", e1, r), np.einsum("ij,ijk->jk", e2, r)
    det = np.where(face, g11 * g22 - g12 ** 2, 1.0)[:, None]
    s = np.where(face[:, None], (g22[:, None] * r1 - g12[:, None] * r2) / det, 0.0)
    t = np.where(face[:, None], (g11[:, None] * r2 - g12[:, None] * r1) / det, 0.0)
    return np.stack([np.where(face[:, None], 1.0 - s - t, 0.0), s, t]), n


def outline_flux(spaces: stokes_bases.StokesSpaces, outline: np.ndarray) -> sp.csr_matrix:
    """(1, nu) row: the flux of the nodal velocities out of a closed polygon.

    ``outline`` (k,) node indices in order around the polygon (either
    orientation). The flux is that of the velocity interpolated linearly
    between the outline nodes, i.e. the rate of change of the polygon's
    area when its nodes move with their velocities; constraining it to zero
    keeps a material region bounded by nodes incompressible as a whole. 2D only.
    """
    if spaces.dim != 2:
        raise ValueError(f"outline_flux takes a polygon of nodes: a 2D mesh, got a "
                         f"{spaces.dim}D one")
    outline = np.asarray(outline, dtype=np.int64)
    P = spaces.mesh.p.T[outline]
    Q = np.roll(P, -1, axis=0)
    orient = np.sign(0.5 * np.sum(P[:, 0] * Q[:, 1] - Q[:, 0] * P[:, 1]))
    d = Q - P
    n = orient * np.c_[d[:, 1], -d[:, 0]]          # outward normal times length
    nd = spaces.ubasis.dofs.nodal_dofs
    nxt = np.roll(outline, -1)
    cols = np.concatenate([nd[0, outline], nd[1, outline], nd[0, nxt], nd[1, nxt]])
    vals = 0.5 * np.concatenate([n[:, 0], n[:, 1], n[:, 0], n[:, 1]])
    return sp.csr_matrix((vals, (np.zeros(cols.size, dtype=np.int64), cols)),
                         shape=(1, spaces.n_velocity))


def fixed_velocity(spaces: stokes_bases.StokesSpaces, free_slip, no_slip,
                    prescribed: Optional[tuple]) -> Tuple[np.ndarray, np.ndarray]:
    """Velocity dofs fixed by the walls and ``prescribed``, and their values."""
    nu = spaces.n_velocity
    D = wall_dofs(spaces, free_slip, no_slip)
    uD = np.zeros(nu)
    if prescribed is not None:
        pd_, pv = prescribed
        pd_ = np.asarray(pd_, dtype=np.int64).ravel()
        pv = np.broadcast_to(np.asarray(pv, dtype=float), pd_.shape)
        if pd_.size and (pd_.min() < 0 or pd_.max() >= nu):
            raise ValueError(f"prescribed dof {int(pd_[(pd_ < 0) | (pd_ >= nu)][0])} is not a "
                             f"velocity dof (0..{nu - 1})")
        if not np.isfinite(pv).all():
            raise ValueError(f"prescribed velocity of dof {int(pd_[~np.isfinite(pv)][0])} is "
                             f"not finite")
        D = np.union1d(D, pd_)
        uD[pd_] = pv
    return D, uD


def walls_fix_pressure(spaces: stokes_bases.StokesSpaces, D: np.ndarray) -> bool:
    """True if every boundary node has a fixed velocity component (no open
    boundary: the pressure is then determined only up to a constant)."""
    nd = spaces.ubasis.dofs.nodal_dofs
    bn = np.unique(spaces.mesh.facets[:, spaces.mesh.boundary_facets()])
    fixed_ = np.zeros(spaces.n_velocity, dtype=bool)
    fixed_[D] = True
    return bool(np.all(fixed_[nd[:spaces.dim, bn]].any(axis=0)))


def constraint_rows(constraints, nu: int) -> Tuple[sp.csr_matrix, np.ndarray]:
    """``(C, c)`` of the extra constraints ``C u = c`` given as a (k, nu) sparse
    matrix C (then c = 0) or a pair ``(C, c)``; ``ValueError`` naming what is wrong."""
    if isinstance(constraints, tuple):
        if len(constraints) != 2:
            raise ValueError(f"constraints must be a matrix C or a pair (C, c), got a "
                             f"tuple of {len(constraints)}")
        C, c = sp.csr_matrix(constraints[0]), np.asarray(constraints[1], dtype=float)
    else:
        C = sp.csr_matrix(constraints)
        c = np.zeros(C.shape[0])
    if C.shape[1] != nu:
        raise ValueError(f"constraints have {C.shape[1]} columns, the velocity {nu} dofs")
    c = c.reshape(-1) if c.ndim else np.full(C.shape[0], float(c))
    if c.shape != (C.shape[0],) or not np.isfinite(c).all():
        raise ValueError(f"the constraints' right side must be {C.shape[0]} finite "
                         f"value(s), got {c.tolist()}")
    return C, c


@njit(cache=True, parallel=True)
def _select(indptr, indices, data, rows, new_col):
    """CSR arrays of the rows ``rows`` and the columns with ``new_col >= 0`` (renumbered
    to it) of a CSR matrix: one pass to count, one to copy (column order kept), rows on
    all threads (a 3D viscous block of 10,000 nodes: 80 ms a call on one)."""
    nr = rows.shape[0]
    count = np.zeros(nr, np.int64)
    for r in prange(nr):
        c = 0
        for k in range(indptr[rows[r]], indptr[rows[r] + 1]):
            if new_col[indices[k]] >= 0:
                c += 1
        count[r] = c
    out_ptr = np.zeros(nr + 1, np.int64)
    for r in range(nr):
        out_ptr[r + 1] = out_ptr[r] + count[r]
    out_idx = np.empty(out_ptr[nr], indices.dtype)
    out_data = np.empty(out_ptr[nr], data.dtype)
    for r in prange(nr):
        o = out_ptr[r]
        for k in range(indptr[rows[r]], indptr[rows[r] + 1]):
            j = new_col[indices[k]]
            if j >= 0:
                out_idx[o] = j
                out_data[o] = data[k]
                o += 1
    return out_ptr, out_idx, out_data


@njit(cache=True)
def _select_in_place(indptr, indices, data, keep_row, new_col):
    """:func:`_select` written over the matrix's own arrays: an entry only moves to a
    lower position, so one serial pass in order reads each entry before it is written
    over. Returns the new row pointer."""
    n = indptr.shape[0] - 1
    ptr = np.zeros(n + 1, np.int64)
    r, o = 0, 0
    for i in range(n):
        if not keep_row[i]:
            continue
        for k in range(indptr[i], indptr[i + 1]):
            j = new_col[indices[k]]
            if j >= 0:
                indices[o] = j
                data[o] = data[k]
                o += 1
        r += 1
        ptr[r] = o
    return ptr[:r + 1]


def free_columns(A: sp.csr_matrix, free: np.ndarray, rows: bool = False,
                 overwrite: bool = False) -> sp.csr_matrix:
    """``A[:, free]`` (``A[free][:, free]`` if ``rows``) for sorted dof indices ``free``,
    in one pass over A (scipy's fancy indexing makes two, each with a sort: 0.8 s a
    Picard iteration at 88,000 nodes). ``overwrite`` (a CSR ``A`` only): written over
    A's own index and value arrays, which A may no longer be used with; the 3D viscous
    block's reduction then needs no second copy of its entries (1.8 GB at 100,000
    nodes)."""
    new_col = np.full(A.shape[1], -1, dtype=np.int64)
    new_col[free] = np.arange(free.size)
    pick = free if rows else np.arange(A.shape[0])
    if overwrite:
        if not (sp.issparse(A) and A.format == "csr"):
            raise ValueError(f"free_columns(overwrite=True) needs a CSR matrix, got "
                             f"{type(A).__name__}")
        keep = np.zeros(A.shape[0], dtype=bool)
        keep[pick] = True
        ptr = _select_in_place(A.indptr, A.indices, A.data, keep, new_col)
        nnz = int(ptr[-1])
        return sp.csr_matrix((A.data[:nnz], A.indices[:nnz], ptr.astype(A.indices.dtype)),
                             shape=(pick.size, free.size))
    A = sp.csr_matrix(A)
    ptr, idx, data = _select(A.indptr, A.indices, A.data, pick.astype(np.int64), new_col)
    return sp.csr_matrix((data, idx, ptr), shape=(pick.size, free.size))
