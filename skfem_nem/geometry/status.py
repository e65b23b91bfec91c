"""Status codes of a query point, shared by point location and the coordinates.

The walks and conflict regions (:mod:`skfem_nem.geometry.simplices_nd`) decide whether a
point is inside, on the hull or at a node; the coordinate kernels add their own outcomes
(a buffer overflow, an unbounded cell). One set of codes, so that both report the same thing
with the same message (:mod:`skfem_nem.coordinates.batch`).
"""
OK = 0          # coordinates computed
OUTSIDE = 1     # outside the convex hull of the nodes
OVERFLOW = 2    # a working buffer was too small: retried with larger ones
AT_NODE = 3     # the point is a node (Kronecker delta; gradients undefined)
ON_HULL = 4     # on the convex hull (limits from inside; gradients undefined)
UNBOUNDED = 5   # a cell came out unbounded (recomputed without the facet filter)

__all__ = ["OK", "OUTSIDE", "OVERFLOW", "AT_NODE", "ON_HULL", "UNBOUNDED"]
