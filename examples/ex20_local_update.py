"""A stirred patch in a standing mesh: the basis and the matrix recomputed only where it moved.

Braun & Sambridge (1995) note that where nodes are injected "only those elements of the
matrix that correspond to the new nodes and their neighbours need be recomputed". Here
most of a mesh stands still while a vortex stirs a disc of radius 0.2 in its middle
(angular speed ``(1 - r / 0.2)^2``, zero outside) and thinned-out places get new nodes.
After every step a heat-source problem ``-div grad u = 1``, ``u = 0`` on the walls, is
solved on the new mesh: :meth:`LagrangianMesh.basis` updates the last basis
(:meth:`~skfem_nem.NaturalNeighbourBasis.updated`: coordinates recomputed only in the
triangles whose natural-neighbour stencils may have changed), and
:func:`~skfem_nem.basis.updates.updated_matrix` replaces those triangles' contributions to
the stiffness matrix instead of assembling it again. Both equal the rebuilt ones to
round-off (checked at the last step here, at every step in the tests). The figure shows the
triangles recomputed at the last step over the solution, and how many were recomputed at
each step against the mesh's triangles. Timings against rebuilt bases:
``benchmarks/basis_update.py``.
"""
from pathlib import Path

import numpy as np
from skfem import BilinearForm, LinearForm, condense, solve
from skfem.helpers import dot, grad

from skfem_nem import LagrangianMesh, NaturalNeighbourBasis
from skfem_nem.basis.updates import updated_matrix
from skfem_nem.geometry.nodesets import box_nodes

N_NODES = 3000
N_STEPS = 20
DT = 0.4
RADIUS = 0.2
INJECT = 1.5
SEED = 1
FIGURE = "out/ex20_local_update.png"


@BilinearForm
def laplace(u, v, w):
    return dot(grad(u), grad(v))


@LinearForm
def source(v, w):
    return 1.0 * v


def stir(x):
    """A rotation about the centre whose angular speed falls to zero at RADIUS."""
    dx, dy = x[:, 0] - 0.5, x[:, 1] - 0.5
    s = np.clip(1.0 - np.hypot(dx, dy) / RADIUS, 0.0, None) ** 2
    return np.c_[-dy * s, dx * s]


def heat(basis, A):
    """The solution of -div grad u = 1, u = 0 on the walls, with the stiffness matrix A."""
    return solve(*condense(A, source.assemble(basis), D=basis.get_dofs()))


def run(n_nodes=N_NODES, n_steps=N_STEPS):
    """Stir, update basis and matrix, solve; the last step's basis, matrix and solution."""
    lm = LagrangianMesh(box_nodes(n_nodes, seed=SEED))
    basis = lm.basis()
    A = laplace.assemble(basis)
    steps = []
    for _ in range(n_steps):
        report = lm.advance(stir, DT, inject=INJECT)
        new = lm.basis()
        A, basis = updated_matrix(laplace, A, basis, new), new
        steps.append({**report, **new.update_report, "triangles": new.nelems})
    return {"mesh": lm, "basis": basis, "A": A, "u": heat(basis, A), "steps": steps}


result = run()
steps = result["steps"]
# the same problem on a basis and a matrix built from scratch on the last mesh
rebuilt = NaturalNeighbourBasis(result["mesh"].mesh)
u_rebuilt = heat(rebuilt, laplace.assemble(rebuilt))
difference = float(np.abs(result["u"] - u_rebuilt).max() / np.abs(u_rebuilt).max())


def visualize(path=FIGURE, res=None):
    """The solution with the last step's recomputed triangles, and the recomputed
    triangles per step; returns the Figure."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    res = result if res is None else res
    lm, basis = res["mesh"], res["basis"]
    P, T = lm.nodes, lm.triangles
    redo = ~basis.kept_elements
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(13, 5.6), constrained_layout=True)
    tpc = ax.tripcolor(P[:, 0], P[:, 1], T, res["u"], shading="gouraud", cmap="viridis")
    ax.triplot(P[:, 0], P[:, 1], T, lw=0.15, color="w", alpha=0.5)
    ax.tripcolor(P[:, 0], P[:, 1], T[redo], np.ones(redo.sum()), cmap="autumn", alpha=0.55)
    ax.set_title(f"u and the {redo.sum()} of {T.shape[0]} triangles recomputed at step "
                 f"{len(res['steps'])}")
    ax.set_aspect("equal")
    fig.colorbar(tpc, ax=ax, shrink=0.8, label="u")
    s = np.arange(1, len(res["steps"]) + 1)
    ax2.plot(s, [r["triangles"] for r in res["steps"]], "k-", label="triangles")
    ax2.plot(s, [r["recomputed"] for r in res["steps"]], "o-", color="C3",
             label="recomputed by the update")
    ax2.plot(s, [r["injected"] for r in res["steps"]], "s-", color="C0",
             label="nodes injected")
    ax2.set_yscale("symlog", linthresh=1.0)
    ax2.set_xlabel("step")
    ax2.legend()
    ax2.set_title("what each step recomputes")
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return fig


if __name__ == "__main__":
    share = [r["recomputed"] / r["triangles"] for r in steps]
    print(f"{len(steps)} steps, {sum(r['flips'] for r in steps)} flips, "
          f"{sum(r['injected'] for r in steps)} nodes injected")
    print(f"recomputed per step: {min(share):.1%} to {max(share):.1%} of the triangles")
    print(f"solution against a rebuilt basis and matrix: {difference:.1e} (relative)")
    visualize()
    print("figure written to", FIGURE)
