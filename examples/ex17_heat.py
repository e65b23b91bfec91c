"""The heat equation, implicit Euler in time: NEM against P1 and P2.

u_t = Laplace(u) on the unit square, u = 0 on the sides, from
u0 = sin(pi x) sin(pi y); the exact solution decays as exp(-2 pi^2 t). The
scikit-fem recipe (mass and stiffness matrices, one factorisation, a loop of
backward-Euler steps) runs unchanged on the natural-neighbour basis. The
initial field is the L2 projection (``basis.project``). u0 is an eigenfunction
of the Laplacian, so backward Euler in time without space discretisation gives
u0 (1 + 2 pi^2 dt)^(-n): the errors at t = 0.1 are measured against that, which
leaves the error of the space discretisation alone. Random nodes: NEM and P1 on
the same nodes, P2 on a coarser mesh with about as many unknowns.
"""
from pathlib import Path

import numpy as np
from scipy.sparse.linalg import splu
from skfem import Basis, BilinearForm, ElementTriP1, ElementTriP2, Functional, condense
from skfem.helpers import dot, grad

from skfem_nem import NaturalNeighbourBasis, delaunay_mesh
from skfem_nem.geometry.nodesets import box_nodes

T_END = 0.1
STEPS = 200
DT = T_END / STEPS


def exact(x, y, t):
    return np.exp(-2 * np.pi ** 2 * t) * np.sin(np.pi * x) * np.sin(np.pi * y)


@BilinearForm
def laplace(u, v, w):
    return dot(grad(u), grad(v))


@BilinearForm
def mass(u, v, w):
    return u * v


#: backward Euler's decay of the eigenfunction u0 over the STEPS steps
EULER_DECAY = (1.0 + DT * 2 * np.pi ** 2) ** (-STEPS)


def time_discrete(x, y):
    return EULER_DECAY * exact(x, y, 0.0)


@Functional
def l2_error(w):
    return (w["u"] - time_discrete(*w.x)) ** 2


def evolve(basis):
    """Backward Euler from the projection of u0 to T_END; the solution at each step's
    end is kept at the interior dofs."""
    M, A = mass.assemble(basis), laplace.assemble(basis)
    D = basis.get_dofs()
    I = basis.complement_dofs(D)
    B = condense(M + DT * A, D=D, expand=False)
    lu = splu(B.tocsc())
    MI = M[I][:, I]
    u = basis.project(lambda x: exact(*x, 0.0))
    u[D] = 0.0
    for _ in range(STEPS):
        u[I] = lu.solve(MI @ u[I])
    return u


mesh = delaunay_mesh(box_nodes(1100, seed=7))
coarse = delaunay_mesh(box_nodes(250, seed=7))
cases = {"NEM": NaturalNeighbourBasis(mesh),
         "P1": Basis(mesh, ElementTriP1()),
         "P2": Basis(coarse, ElementTriP2())}
solutions = {name: evolve(b) for name, b in cases.items()}
# errors with a 7-point rule (for NEM: exact values, no smoothing needed)
error_bases = {"NEM": NaturalNeighbourBasis(mesh, npoints=7),
               "P1": Basis(mesh, ElementTriP1(), intorder=5),
               "P2": Basis(coarse, ElementTriP2(), intorder=5)}
errors = {name: float(np.sqrt(l2_error.assemble(error_bases[name], u=solutions[name])))
          for name in cases}
dofs = {name: int(b.N) for name, b in cases.items()}

FIGURE = "out/ex17_heat.png"


def visualize(path=FIGURE):
    """Draw the NEM solution at t = 0.1 and its error along the diagonal; returns the
    Figure."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(12, 4.8), constrained_layout=True)
    cases["NEM"].plot(solutions["NEM"], ax=ax[0], colorbar=True)
    ax[0].set_title(f"NEM at t = {T_END} ({dofs['NEM']} nodes, L2 error "
                    f"{errors['NEM']:.2e})")
    ax[0].set_aspect("equal")
    s = np.linspace(0.01, 0.99, 200)
    line = np.array([s, s])
    for name, b in cases.items():
        ax[1].plot(s, b.probes(line) @ solutions[name] - time_discrete(s, s),
                   label=f"{name}: {dofs[name]} dofs, L2 error {errors[name]:.2e}")
    ax[1].set(xlabel="x = y", ylabel="u_h - u",
              title="error along the diagonal")
    ax[1].legend(fontsize=8)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return fig


if __name__ == "__main__":
    print("| method | dofs | L2 error at t = 0.1 |\n|---|---|---|")
    for name in cases:
        print(f"| {name} | {dofs[name]} | {errors[name]:.3e} |")
    visualize()
    print("figure written to", FIGURE)
