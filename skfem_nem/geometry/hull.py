"""The hull policy: when a query point is on the convex hull of the nodes, in every dimension.

The 2D area method and Lasserre's method decide "on the hull" by the same rule: a point whose
distance to the line (2D) or plane (3D, 4D) of a hull edge or facet is below
``HULL_TOLERANCE`` times a local length (the edge's length in 2D; the point's distance to the
facet's nodes in n-D) lies on that edge or facet. Such a point gets the limits of the
coordinates from inside (linear interpolation along a hull edge; the facet's own weights) and
no gradients (they are one-sided there). One number, so that the two methods agree on which
points those are; 1e-12 is far above the round-off of the distance (a few ulps of the local
length) and far below any distance at which the one-sided limit would be a visible error.

Points further outside are outside, except by round-off: a point outside the domain by
less than ``OUTSIDE_ROUNDOFF`` times the diagonal of the nodes' bounding box is taken to be
on its boundary. The 2D coordinates move such points outside the convex hull onto it (their
``hull_tol`` option); the basis on a non-convex domain moves them from a void sliver just
inside the nearest boundary facet (``basis.domain.into_domain``). Queries computed from the
nodes land a few ulps outside: a mapped quadrature point on a hull edge, the midpoint of a
refined circle's chord, the side of a mapped mesh that is straight only to round-off. One
number for both, 1e-10: far above those few ulps, far below any gap a mesh resolves.
"""
HULL_TOLERANCE = 1e-12
OUTSIDE_ROUNDOFF = 1e-10
# Hull nodes lie on a facet's plane within this times the nodes' diameter when queries are
# grouped by facet (n-D): far above the round-off of the fitted plane, far below a real gap.
FACET_PLANE = 1e-9

__all__ = ["HULL_TOLERANCE", "OUTSIDE_ROUNDOFF", "FACET_PLANE"]
