"""Integration-point fields of a moving 3D mesh, carried across the repaired tetrahedra.

Why: a solid's stress history lives at integration points, and the paper could not keep it
in 3D ("there is no 3D equivalent of the 2D averaging and splitting strategy"). Here each
tetrahedron carries one value per vertex cell, a quarter of its volume each, at the point of
the degree-2 four-point rule nearest that vertex (barycentric ``(a, b, b, b)``, ``a = (5 +
3 sqrt 5) / 20``): the quadrature points of the 3D Stokes spaces, so that a stress history
passes to :func:`~skfem_nem.models.rheology.vep_step` and back without interpolation
(:func:`to_quadrature`, :func:`from_quadrature`: scikit-fem lists the same points in
another order).

A step's repair (flips, relocated nodes) replaces some tetrahedra by others over the same
region. Tetrahedra that survive keep their values (a value belongs to a vertex of its
tetrahedron, whatever the vertex order). The changed tetrahedra are grouped into regions
(connected through shared vertices); in each region a new vertex cell takes

* ``"average"``: the mean of the old cells of that region at the same vertex (the paper's
  averaging, generalised from the flipped pair to any region; the mean of the region's old
  cells for a vertex that had none): values stay within the old ones' range;
* ``"conservative"``: the same, plus one constant per region so that the region's integral
  (values times cell volumes, at the new positions) is what it was, to round-off.
"""
from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from ..geometry.entities import unique_ints

__all__ = ["REMAP_RULES", "cell_points", "cell_volumes", "check_ip_fields", "remap_fields",
           "to_quadrature", "from_quadrature", "match_rows"]

REMAP_RULES = ("conservative", "average")
CELL_POINT = (5.0 + 3.0 * np.sqrt(5.0)) / 20.0  # barycentric weight of a cell's own vertex
_REST = (1.0 - CELL_POINT) / 3.0
#: scikit-fem's four-point tetrahedron rule lists the point of vertex k as point RULE_ORDER[k]
RULE_ORDER = np.array([1, 0, 3, 2])


def cell_volumes(p, t):
    """(m,) a quarter of each tetrahedron's (signed) volume: the volume of each vertex cell."""
    e = p[t[:, 1:]] - p[t[:, :1]]
    return np.linalg.det(e) / 24.0


def cell_points(p, t):
    """(m, 4, 3) the points of the vertex cells (the four-point rule's, vertex by vertex)."""
    x = p[t]                                            # (m, 4, 3)
    return _REST * x.sum(axis=1, keepdims=True) + (CELL_POINT - _REST) * x


def to_quadrature(f):
    """An ip field (m, 4, *shape) in the layout of the Stokes spaces' quadrature values
    (*shape, m, 4), points in scikit-fem's order (e.g. a stress for ``vep_step``), in C
    order: the stress update's products over its leading axes take 3.4 times as long on
    the strided view (0.45 s against 0.13 s for a rotation at 190,000 tetrahedra)."""
    f = np.asarray(f)
    out = np.empty(f.shape[2:] + f.shape[:2], dtype=f.dtype)
    out[..., RULE_ORDER] = np.moveaxis(f, (0, 1), (-2, -1))
    return out


def from_quadrature(q):
    """The inverse of :func:`to_quadrature`: (*shape, m, 4) -> (m, 4, *shape)."""
    g = np.moveaxis(np.asarray(q), (-2, -1), (0, 1))
    return np.ascontiguousarray(g[:, RULE_ORDER])


def check_ip_fields(ip_fields, m):
    """Float copies of named arrays of shape (m, 4, ...), checked finite (naming the field)."""
    out = {}
    for name, a in (ip_fields or {}).items():
        a = np.array(a, dtype=float, copy=True)
        if a.shape[:2] != (m, 4):
            raise ValueError(f"ip field {name!r} has shape {a.shape}, expected ({m}, 4, ...) "
                             "(one value per vertex cell of each tetrahedron)")
        if not np.isfinite(a).all():
            bad = np.argwhere(~np.isfinite(a))[0]
            raise ValueError(f"ip field {name!r} has non-finite values (first at tetrahedron "
                             f"{bad[0]}, cell {bad[1]})")
        out[name] = a
    return out


def _keys(t: np.ndarray, n: np.int64) -> tuple[np.ndarray, np.ndarray]:
    """Two int64 keys of each tetrahedron of t (m, 4) of nodes below n: its sorted vertices
    a < b < c < d as ``a n + b`` and ``c n + d``."""
    s = np.sort(np.asarray(t, dtype=np.int64), axis=1)
    return s[:, 0] * n + s[:, 1], s[:, 2] * n + s[:, 3]


def match_rows(old_t, new_t):
    """For each new tetrahedron, whether it was an old one (same vertices) and which row
    (0 where it was not). Old and new keys are sorted together (:func:`_keys`, two integer
    keys: 0.8 s against 2.7 s as 32-byte records at 100,000 nodes), and an old and a new
    tetrahedron of the same vertices end up side by side, the old first."""
    mo, mn = len(old_t), len(new_t)
    n = np.int64(max(np.max(old_t, initial=0), np.max(new_t, initial=0)) + 1)
    (ho, lo), (hn, ln) = _keys(old_t, n), _keys(new_t, n)
    hi, low = np.concatenate([ho, hn]), np.concatenate([lo, ln])
    order = np.lexsort((low, hi))
    h, w = hi[order], low[order]
    k = np.flatnonzero((h[1:] == h[:-1]) & (w[1:] == w[:-1]))
    a, b = order[k], order[k + 1]
    pair = (a < mo) & (b >= mo)
    kept, src = np.zeros(mn, bool), np.zeros(mn, np.int64)
    kept[b[pair] - mo] = True
    src[b[pair] - mo] = a[pair]
    return kept, src


def _regions(n, t):
    """Region label of each tetrahedron of t (connected through shared vertices)."""
    rows = np.repeat(t[:, 0], 3)
    cols = t[:, 1:].ravel()
    g = coo_matrix((np.ones(rows.size), (rows, cols)), shape=(n, n))
    _, label = connected_components(g, directed=False)
    return label[t[:, 0]]


def remap_fields(p, old_t, new_t, fields, rule):
    """The fields (name -> (m_old, 4, ...)) on the new tetrahedra (m_new, 4) of nodes p.
    Returns the new fields and the number of new tetrahedra whose values were remapped."""
    if rule not in REMAP_RULES:
        raise ValueError(f"remap must be one of {REMAP_RULES}, got {rule!r}")
    kept, src = match_rows(old_t, new_t)
    made = np.flatnonzero(~kept)
    unmatched = np.ones(old_t.shape[0], bool)
    unmatched[src[kept]] = False
    gone = np.flatnonzero(unmatched)
    # slot in the old tet of each new tet's vertex (kept rows)
    slot = np.argmax(old_t[src][:, None, :] == new_t[:, :, None], axis=2)
    label = _regions(p.shape[0], np.concatenate([old_t[gone], new_t[made]]))
    lo, ln = label[:gone.size], label[gone.size:]
    vo, vn = cell_volumes(p, old_t[gone]), cell_volumes(p, new_t[made])
    out = {}
    for name, f in fields.items():
        g = np.empty((new_t.shape[0],) + f.shape[1:])
        g[kept] = f[src[kept][:, None], slot[kept]]
        if made.size:
            g[made] = _region_values(new_t[made], ln, vn, old_t[gone], lo, vo, f[gone], rule)
        out[name] = g
    return out, int(made.size)


def _region_values(tn, ln, vn, to, lo, vo, fo, rule):
    """Values of the new cells (k, 4, ...) from the old cells of their regions."""
    comp = fo.shape[2:]
    flat = fo.reshape(fo.shape[0] * 4, -1)
    reg_o, reg_n = np.repeat(lo, 4), np.repeat(ln, 4)
    nreg = int(max(lo.max(initial=-1), ln.max(initial=-1))) + 1
    base = int(max(to.max(initial=0), tn.max(initial=0))) + 1
    pair_o = reg_o * base + to.ravel()
    pair_n = reg_n * base + tn.ravel()
    w = np.abs(np.repeat(vo, 4))                        # region means: positive weights
    reg_sum = np.zeros((nreg, flat.shape[1]))
    np.add.at(reg_sum, reg_o, flat * w[:, None])
    reg_vol = np.bincount(reg_o, weights=w, minlength=nreg)[:, None]
    vals = (reg_sum / np.where(reg_vol > 0, reg_vol, 1.0))[reg_n]
    uniq, inv = unique_ints(pair_o, return_inverse=True)
    if uniq.size:
        sums = np.zeros((uniq.size, flat.shape[1]))
        np.add.at(sums, inv, flat)
        counts = np.bincount(inv, minlength=uniq.size)
        where = np.searchsorted(uniq, pair_n).clip(0, uniq.size - 1)
        hit = uniq[where] == pair_n
        vals[hit] = sums[where[hit]] / counts[where[hit], None]
    if rule == "conservative":
        signed = np.repeat(vo, 4)
        before = np.zeros((nreg, flat.shape[1]))
        np.add.at(before, reg_o, flat * signed[:, None])
        wn = np.repeat(vn, 4)
        after = np.zeros((nreg, flat.shape[1]))
        np.add.at(after, reg_n, vals * wn[:, None])
        vol_n = np.bincount(reg_n, weights=wn, minlength=nreg)[:, None]
        vals = vals + ((before - after) / np.where(vol_n != 0, vol_n, 1.0))[reg_n]
    return vals.reshape((tn.shape[0], 4) + comp)
