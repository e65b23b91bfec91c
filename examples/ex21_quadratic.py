"""Quadratic natural-neighbour functions: P2's unknowns and rates, with natural neighbours.

``ElementNaturalNeighbour2`` makes the natural-neighbour coordinates the variables of a
quadratic Bernstein polynomial, with one unknown per node and one per edge, P2's. The
functions reproduce quadratic fields, and linear smoothed gradients on each triangle keep
that order in the Galerkin solution. Poisson's equation with u = sin(2x + 1) cos(3y) + xy on
jittered nodes of the unit square, Dirichlet data on the whole boundary, four levels:
NEM (linear), NEM2, P1 and P2 on the same triangles.

``visualize()`` draws a node's function and an edge's function of NEM2 (they reach as
far as the node's natural neighbours, and are negative in places, as P2's are), and the
L2 and H1 errors against the number of unknowns.
"""
from pathlib import Path

import numpy as np
from skfem import (Basis, BilinearForm, ElementTriP1, ElementTriP2, Functional, LinearForm,
                   condense, solve)
from skfem.helpers import dot, grad

from skfem_nem import ElementNaturalNeighbour2, NaturalNeighbourBasis, delaunay_mesh

LEVELS = (8, 16, 32, 64)
METHODS = ("NEM", "NEM2", "P1", "P2")


def exact(x, y):
    return np.sin(2 * x + 1) * np.cos(3 * y) + x * y


def exact_grad(x, y):
    return np.stack([2 * np.cos(2 * x + 1) * np.cos(3 * y) + y,
                     -3 * np.sin(2 * x + 1) * np.sin(3 * y) + x])


@BilinearForm
def laplace(u, v, w):
    return dot(grad(u), grad(v))


@LinearForm
def load(v, w):
    return 13 * np.sin(2 * w.x[0] + 1) * np.cos(3 * w.x[1]) * v


@Functional
def l2_error(w):
    return (w["u"] - exact(*w.x)) ** 2


@Functional
def h1_error(w):
    return ((w["u"].grad - exact_grad(*w.x)) ** 2).sum(axis=0)


def jittered_mesh(k, seed=0):
    """A (k + 1)^2 grid of the unit square, interior nodes jittered by 0.3 / k."""
    g = np.linspace(0, 1, k + 1)
    p = np.stack(np.meshgrid(g, g), axis=-1).reshape(-1, 2)
    inner = (p > 0).all(axis=1) & (p < 1).all(axis=1)
    p[inner] += np.random.default_rng(seed).uniform(-0.3, 0.3, (inner.sum(), 2)) / k
    return delaunay_mesh(p)


def bases(mesh, method):
    """(basis to solve with, basis of the errors: 7 points, exact gradients)."""
    if method.startswith("NEM"):
        elem = ElementNaturalNeighbour2() if method == "NEM2" else None
        return NaturalNeighbourBasis(mesh, elem), NaturalNeighbourBasis(mesh, elem, npoints=7)
    elem = ElementTriP2() if method == "P2" else ElementTriP1()
    return Basis(mesh, elem), Basis(mesh, elem, intorder=5)


def solve_poisson(mesh, method):
    basis, ebasis = bases(mesh, method)
    D = basis.get_dofs().all()
    u = solve(*condense(laplace.assemble(basis), load.assemble(basis),
                        x=exact(*basis.doflocs), D=D))
    field = ebasis.interpolate(u)
    return dict(method=method, dofs=basis.N, basis=basis, u=u,
                l2=np.sqrt(l2_error.assemble(ebasis, u=field)),
                h1=np.sqrt(h1_error.assemble(ebasis, u=field)))


rows = [solve_poisson(jittered_mesh(k), m) for k in LEVELS for m in METHODS]


def rates(method, key):
    """Observed orders in h (h^2 ~ 1 / unknowns) between consecutive levels."""
    r = [x for x in rows if x["method"] == method]
    d, e = np.array([x["dofs"] for x in r]), np.array([x[key] for x in r])
    return -2 * np.log(e[1:] / e[:-1]) / np.log(d[1:] / d[:-1])


FIGURE = "out/ex21_quadratic.png"


def visualize(path=FIGURE):
    """Draw a node's and an edge's function and the errors; returns the Figure."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    mesh = jittered_mesh(6, seed=2)
    basis = NaturalNeighbourBasis(mesh, ElementNaturalNeighbour2())
    node = int(np.argmin(((mesh.p.T - 0.5) ** 2).sum(axis=1)))
    edge = int(np.flatnonzero((mesh.facets == node).any(axis=0))[0])
    g = np.linspace(0, 1, 161)
    X, Y = np.meshgrid(g, g)
    P = basis.probes(np.stack([X.ravel(), Y.ravel()]))
    fig, ax = plt.subplots(1, 3, figsize=(16, 4.8), constrained_layout=True)
    for a, dof, name in ((ax[0], node, f"node {node}"),
                         (ax[1], mesh.p.shape[1] + edge, f"edge {edge}")):
        e = np.zeros(basis.N)
        e[dof] = 1.0
        Z = (P @ e).reshape(X.shape)
        lim = np.abs(Z).max()
        c = a.pcolormesh(X, Y, Z, cmap="RdBu_r", vmin=-lim, vmax=lim, shading="auto")
        a.triplot(mesh.p[0], mesh.p[1], mesh.t.T, lw=0.4, color="0.4")
        a.plot(*basis.doflocs[:, dof], "k*", ms=10)
        a.set(aspect="equal", title=f"NEM2 function of {name}")
        fig.colorbar(c, ax=a)
    for method, mk in zip(METHODS, "os^v"):
        r = [x for x in rows if x["method"] == method]
        d = [x["dofs"] for x in r]
        ax[2].loglog(d, [x["l2"] for x in r], mk + "-", label=f"{method} L2")
        ax[2].loglog(d, [x["h1"] for x in r], mk + "--", label=f"{method} H1")
    ax[2].set(xlabel="unknowns", ylabel="error", title="Poisson on jittered nodes")
    ax[2].legend(fontsize=8, ncol=2)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return fig


if __name__ == "__main__":
    for x in rows:
        print(f"{x['method']:5s} {x['dofs']:6d} unknowns  L2 {x['l2']:.3e}  H1 {x['h1']:.3e}")
    for m in METHODS:
        print(f"{m}: L2 rates {np.round(rates(m, 'l2'), 2)}, "
              f"H1 rates {np.round(rates(m, 'h1'), 2)}")
    visualize()
    print("figure written to", FIGURE)
