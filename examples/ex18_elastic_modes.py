"""Eigenmodes of an elastic beam: NEM against P1 and P2.

The free vibrations of a clamped 4 x 1 plate in plane strain (E = 1, nu = 0.3,
density 1): the generalized eigenproblem K x = omega^2 M x with scikit-fem's
``linear_elasticity`` and a vector mass form, on
``ElementVector(ElementNaturalNeighbour())`` in place of
``ElementVector(ElementTriP1())``. The left side is clamped. The reference is
P2 on a finer mesh; NEM and P1 use the same random nodes, P2 a coarser set
with about as many unknowns. Linear triangles lock in bending, so P1's
frequencies come out high; the natural-neighbour functions, smooth across the
triangles, much less so.
"""
from pathlib import Path

import numpy as np
from scipy.sparse.linalg import eigsh
from skfem import Basis, BilinearForm, ElementTriP1, ElementTriP2, ElementVector, condense
from skfem.helpers import dot
from skfem.models.elasticity import lame_parameters, linear_elasticity

from skfem_nem import ElementNaturalNeighbour, NaturalNeighbourBasis, delaunay_mesh
from skfem_nem.geometry.nodesets import box_nodes

LENGTH, HEIGHT = 4.0, 1.0
MODES = 4
stiffness = linear_elasticity(*lame_parameters(1.0, 0.3))


@BilinearForm
def mass(u, v, w):
    return dot(u, v)


def frequencies(basis, k=MODES):
    """The k lowest angular frequencies and the first mode shape."""
    K, M = stiffness.assemble(basis), mass.assemble(basis)
    D = basis.get_dofs(lambda x: np.isclose(x[0], 0.0)).all()
    Kc, Mc, _, I = condense(K, M, D=D)
    lam, X = eigsh(Kc, k=k, M=Mc, sigma=0.0)
    mode = basis.zeros()
    mode[I] = X[:, 0]
    return np.sqrt(lam), mode


def beam(n, seed=5):
    return delaunay_mesh(box_nodes(n, width=LENGTH, height=HEIGHT, seed=seed))


mesh = beam(700)
coarse = beam(160)
cases = {"NEM": NaturalNeighbourBasis(mesh, ElementVector(ElementNaturalNeighbour())),
         "P1": Basis(mesh, ElementVector(ElementTriP1())),
         "P2": Basis(coarse, ElementVector(ElementTriP2()))}
results = {name: frequencies(b) for name, b in cases.items()}
reference, _ = frequencies(Basis(beam(3000), ElementVector(ElementTriP2())))
errors = {name: np.abs(w / reference - 1) for name, (w, _) in results.items()}
dofs = {name: int(b.N) for name, b in cases.items()}

FIGURE = "out/ex18_elastic_modes.png"


def visualize(path=FIGURE):
    """Draw the first NEM mode (deformed nodes) and the frequency errors; returns the
    Figure."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(13, 4.2), constrained_layout=True,
                           gridspec_kw={"width_ratios": [1.6, 1]})
    basis = cases["NEM"]
    _, mode = results["NEM"]
    (ux, bx), (uy, _) = basis.split(mode)
    scale = 0.3 / np.abs(mode).max()
    bx.draw(ax=ax[0], color="0.6")
    ax[0].triplot(mesh.p[0] + scale * ux, mesh.p[1] + scale * uy, mesh.t.T, lw=0.4)
    ax[0].set(aspect="equal", title=f"first NEM mode, omega = {results['NEM'][0][0]:.4f}")
    x = np.arange(1, MODES + 1)
    for i, name in enumerate(cases):
        ax[1].bar(x + 0.25 * (i - 1), errors[name], width=0.25,
                  label=f"{name} ({dofs[name]} dofs)")
    ax[1].set(yscale="log", xlabel="mode", ylabel="|omega_h / omega - 1|", xticks=x,
              title="frequency errors (reference: fine P2)")
    ax[1].legend(fontsize=8)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return fig


if __name__ == "__main__":
    print("| mode | reference | " + " | ".join(f"{n} error" for n in cases) + " |")
    print("|---|---|" + "---|" * len(cases))
    for m in range(MODES):
        print(f"| {m + 1} | {reference[m]:.5f} | "
              + " | ".join(f"{errors[n][m]:.2e}" for n in cases) + " |")
    visualize()
    print("figure written to", FIGURE)
