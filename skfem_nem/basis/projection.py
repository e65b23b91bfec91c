"""Subsets of cells and facets, and L2 projections onto natural-neighbour bases.

scikit-fem names a subset of a mesh's elements or facets in many ways: indices, a name of
``mesh.subdomains`` / ``mesh.boundaries``, a callable of the midpoints, a list of any of
these; here also a boolean mask, which scikit-fem would take for indices. The subsets are
turned into sorted, unique, checked indices once (a bad index or mask raises, naming it).

A projection restricted to some cells or facets of a P1 basis keeps the dofs of their
vertices. A natural-neighbour function is non-zero wherever its node is a natural neighbour
of a point, so the dofs kept are those of the cells' or facets' *stencils*, less the
functions that vanish at every quadrature point of the basis (with smoothed gradients a
stencil also holds nodes that enter the gradients only; on a facet or subdomain basis their
rows of the mass matrix would be empty). The others are zero, as in scikit-fem.
"""
from __future__ import annotations

import numpy as np
from skfem.element import DiscreteField

__all__ = ["normalize_elements", "normalize_facets", "positions_in", "stencil_dofs",
           "value_dofs", "projection_dofs", "field_values", "l2_project"]


def _checked(idx, n, what):
    idx = np.asarray(idx)
    if idx.dtype == bool:
        if idx.shape != (n,):
            raise ValueError(f"a {what} mask must have {n} entries, got shape {idx.shape}")
        return np.flatnonzero(idx)
    if idx.size and not np.issubdtype(idx.dtype, np.integer):
        raise TypeError(f"{what} indices must be integers, got dtype {idx.dtype}")
    idx = idx.astype(np.int64).ravel()
    if idx.size and (idx.min() < 0 or idx.max() >= n):
        raise ValueError(f"{what} indices must lie in [0, {n}), got {int(idx.min())}.."
                         f"{int(idx.max())}")
    return np.unique(idx)


def normalize_elements(mesh, elements) -> np.ndarray:
    """Sorted unique element indices of ``elements`` (indices, a boolean mask, a callable
    of the midpoints, a name in ``mesh.subdomains``, or a list/tuple/set of these)."""
    if isinstance(elements, str):
        if not mesh.subdomains or elements not in mesh.subdomains:
            raise ValueError(f"elements={elements!r}: no such subdomain in the mesh (it has "
                             f"{sorted(mesh.subdomains or {})})")
        elements = mesh.subdomains[elements]
    elif callable(elements):
        elements = mesh.elements_satisfying(elements)
    elif isinstance(elements, (list, tuple, set)) and any(
            isinstance(e, str) or callable(e) for e in elements):
        parts = [normalize_elements(mesh, e) for e in elements]
        elements = np.unique(np.concatenate(parts or [np.zeros(0, np.int64)]))
    elif isinstance(elements, (bool, np.bool_)):
        raise TypeError("elements=True/False: pass element indices, a mask, a callable or a "
                        "subdomain name (elements=None for all elements)")
    return _checked(list(elements) if isinstance(elements, set) else elements,
                    mesh.nelements, "element")


def normalize_facets(mesh, facets) -> np.ndarray:
    """Sorted unique facet indices of ``facets`` (indices, a boolean mask, a callable of
    the facet midpoints, a name in ``mesh.boundaries``, or a list of these)."""
    if isinstance(facets, str) and (not mesh.boundaries or facets not in mesh.boundaries):
        raise ValueError(f"facets={facets!r}: no such boundary in the mesh (it has "
                         f"{sorted(mesh.boundaries or {})})")
    if isinstance(facets, np.ndarray) and facets.dtype == bool:
        return _checked(facets, mesh.nfacets, "facet")
    return _checked(np.asarray(mesh.normalize_facets(facets)), mesh.nfacets, "facet")


def positions_in(own, idx, what) -> np.ndarray:
    """Positions of the mesh indices ``idx`` in a basis' index set ``own`` (its elements or
    facets); an index the basis does not hold raises, naming it."""
    idx = np.asarray(idx, dtype=np.int64)
    order = np.argsort(own, kind="stable")
    srt = own[order]
    pos = np.searchsorted(srt, idx)
    ok = pos < srt.size
    ok[ok] = srt[pos[ok]] == idx[ok]
    if not ok.all():
        raise ValueError(f"{what} {int(idx[~ok][0])} is not one of the basis' {what}s "
                         f"({int(np.count_nonzero(~ok))} such)")
    return order[pos]


def stencil_dofs(basis, positions) -> np.ndarray:
    """The dofs (every component) of the nodes in the stencils of the basis' cells or
    facets at ``positions`` (indices into the basis' own element axis)."""
    ptr, sten = basis.stencil_ptr, basis.stencil_nodes
    positions = np.asarray(positions, dtype=np.int64)
    if positions.size:
        take = np.concatenate([np.arange(ptr[k], ptr[k + 1]) for k in positions])
        nodes = np.unique(sten[take])
    else:
        nodes = np.zeros(0, np.int64)
    return np.sort(basis.function_dofs[:, nodes].ravel())


def value_dofs(basis, positions) -> np.ndarray:
    """The dofs (every component) of the functions whose value is non-zero at a quadrature
    point of the basis' cells or facets at ``positions``: the unknowns of a projection on
    them (a stencil may also hold nodes that enter only the smoothed gradients)."""
    Phi = basis.values_matrix
    nq = basis.dx.shape[1]
    rows = (np.asarray(positions, dtype=np.int64)[:, None] * nq + np.arange(nq)).ravel()
    sub = Phi[rows]
    nodes = np.unique(sub.indices[sub.data != 0.0])
    return np.sort(basis.function_dofs[:, nodes].ravel())


def projection_dofs(basis, positions) -> np.ndarray:
    """The unknowns of a projection restricted to the cells or facets at ``positions``:
    the dofs of their stencils whose functions are non-zero somewhere on the basis'
    quadrature points (the mass matrix has no empty row for them)."""
    return np.intersect1d(stencil_dofs(basis, positions),
                          value_dofs(basis, np.arange(basis.nelems)))


def field_values(basis, interp):
    """``interp`` (callable of the global quadrature points, DiscreteField, array, tuple or
    list of components, or a number) as an array (..., nelems, nq)."""
    if callable(interp):
        interp = interp(basis.global_coordinates())
    if isinstance(interp, (tuple, list)):
        interp = np.stack([np.asarray(c) + np.zeros(basis.dx.shape) for c in interp])
    f = np.asarray(interp)
    if np.iscomplexobj(f):
        raise ValueError("natural-neighbour projections are real; project the real and "
                         "imaginary parts separately")
    f = f.astype(float) + np.zeros(basis.dx.shape)
    comps = basis.elem.dim if hasattr(basis.elem, "elem") else None
    want = basis.dx.shape if comps is None else (comps,) + basis.dx.shape
    if f.shape != want:
        raise ValueError(f"the projected field has shape {f.shape} at the quadrature points, "
                         f"the basis needs {want}")
    return f


def l2_project(basis, interp, keep=None, dtype=None) -> np.ndarray:
    """L2 projection of ``interp`` onto the basis on its quadrature points; the dofs not in
    ``keep`` (all if None) are zero. ``dtype``: real floating types only."""
    from skfem.assembly import BilinearForm, LinearForm
    from skfem.helpers import inner
    from skfem.utils import condense, solve
    if dtype is not None and not np.issubdtype(np.dtype(dtype), np.floating):
        raise ValueError(f"project(dtype={np.dtype(dtype)}): natural-neighbour "
                         f"projections are real")
    f = field_values(basis, interp)
    M = BilinearForm(lambda u, v, w: inner(u, v)).assemble(basis)
    b = LinearForm(lambda v, w: inner(w["f"], v)).assemble(basis, f=DiscreteField(f))
    x = solve(M, b) if keep is None else solve(*condense(M, b, I=keep))
    return x if dtype is None else x.astype(dtype)
