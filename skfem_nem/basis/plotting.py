"""Natural-neighbour fields in scikit-fem's own plotting functions.

scikit-fem's ``skfem.visuals.matplotlib.plot``, ``plot3`` and ``draw`` choose what to draw by
the type of their first argument (``functools.singledispatch``) and know only scikit-fem's
bases. A natural-neighbour field is not the P1 interpolant of its nodal values: between the
nodes it is the Sibson (or Laplace) combination of them. So the natural-neighbour bases are
registered with those dispatchers (when the first one is built), and a plot evaluates the
field itself at the nodes of refined triangles (:func:`refined_values`) and hands the refined
``MeshTri`` to scikit-fem's own ``MeshTri`` plot, as scikit-fem does for its bases. A vector
basis draws arrows there (scikit-fem's behaviour), or one component at a time through
``basis.split(u)``.

scikit-fem's plotting functions ignore keywords they do not know; here a keyword that
neither scikit-fem's function for the refined mesh nor this module uses raises a
``TypeError`` naming it.
"""
from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys

import numpy as np
from skfem import MeshTri
from skfem.element import ElementVector

__all__ = ["refined_values", "install", "plot_basis", "plot3_basis", "draw_basis",
           "PLOT_KEYWORDS", "PLOT3_KEYWORDS", "DRAW_KEYWORDS", "DEFAULT_NREFS"]

#: refinements of each triangle for plotting: the field is smooth between nodes, so two
#: (16 sub-triangles) show it where scikit-fem's default of one would show kinks
DEFAULT_NREFS = 2
#: keywords of scikit-fem's ``plot`` of a ``MeshTri`` (12.x), plus the refinement
PLOT_KEYWORDS = frozenset({
    "ax", "aspect", "colorbar", "figsize", "shading", "vmin", "vmax", "edgecolors", "cmap",
    "plot_kwargs", "levels", "angles", "scale", "width", "headwidth", "headlength",
    "minshaft", "pivot", "color", "nrefs", "Nrefs"})
#: keywords of scikit-fem's ``plot3`` of a ``MeshTri``, plus the refinement
PLOT3_KEYWORDS = frozenset({"ax", "cmap", "nrefs", "Nrefs"})
#: keywords of scikit-fem's ``draw`` of a 2D mesh, plus the refinement it accepts for bases
DRAW_KEYWORDS = frozenset({
    "ax", "figsize", "aspect", "boundaries_only", "plot_kwargs", "color", "linewidth",
    "subdomain", "boundaries", "node_numbering", "facet_numbering", "element_numbering",
    "nrefs", "Nrefs"})

_REGISTERED = set()
#: the scikit-fem module whose dispatchers draw natural-neighbour fields
MATPLOTLIB_VISUALS = "skfem.visuals.matplotlib"


def _check_keywords(kwargs, allowed, who):
    unknown = sorted(set(kwargs) - allowed)
    if unknown:
        raise TypeError(f"{who}() got unexpected keyword argument(s) {', '.join(unknown)}; "
                        f"accepted: {', '.join(sorted(allowed))}")


def _nrefs(kwargs):
    """The refinement asked for (``nrefs`` or scikit-fem's older ``Nrefs``), removed."""
    nrefs, Nrefs = kwargs.pop("nrefs", None), kwargs.pop("Nrefs", None)
    if nrefs is not None and Nrefs is not None and nrefs != Nrefs:
        raise ValueError(f"nrefs={nrefs} and Nrefs={Nrefs} disagree; pass one of them")
    return DEFAULT_NREFS if nrefs is None and Nrefs is None else (
        nrefs if nrefs is not None else Nrefs)


def refined_values(basis, y, nrefs=DEFAULT_NREFS):
    """A refined ``MeshTri`` of the basis' triangles (of its ``elements`` for a subdomain
    basis) and the values of the dof vector ``y`` at its nodes: (npts,) for a scalar basis,
    component-major (dim * npts,) for a vector basis, as scikit-fem's ``refinterp``."""
    mesh = basis.mesh
    if not isinstance(mesh, MeshTri):
        raise NotImplementedError(
            f"refinterp and the plots draw triangles, not {type(mesh).__name__} cells: on "
            f"tetrahedra evaluate the field with basis.probes(x) on a slice (see "
            f"examples/ex06_poisson_3d.py) or save it with mesh.save(..., point_data=...)")
    if int(nrefs) != nrefs or nrefs < 0:
        raise ValueError(f"nrefs must be a non-negative integer, got {nrefs!r}")
    y = np.asarray(y)
    if y.shape != (basis.N,):
        raise ValueError(f"dof vector has shape {y.shape}, the basis {basis.N} dofs")
    ref = MeshTri.init_refdom().refined(int(nrefs))
    x = basis.mapping.F(ref.p, tind=basis.tind)  # (2, ne, npts)
    ne, npt = x.shape[1], x.shape[2]
    pts = x.transpose(1, 2, 0).reshape(-1, 2)
    vals = basis.probes(pts.T) @ y
    t = (ref.t[:, None, :] + npt * np.arange(ne)[None, :, None]).reshape(3, -1)
    return MeshTri(pts.T.copy(), t, sort_t=False), vals


def plot_basis(basis, z, **kwargs):
    """scikit-fem's ``plot`` for a natural-neighbour basis: the field on refined triangles
    (``nrefs``, default :data:`DEFAULT_NREFS`), Gouraud-shaded unless ``shading`` is given;
    the other keywords are those of scikit-fem's ``MeshTri`` plot."""
    from skfem.visuals.matplotlib import plot
    _check_keywords(kwargs, PLOT_KEYWORDS, "plot")
    M, v = refined_values(basis, z, _nrefs(kwargs))
    if not isinstance(basis.elem, ElementVector):
        kwargs.setdefault("shading", "gouraud")
    elif basis.elem.dim != 2:
        raise NotImplementedError("arrows are drawn for 2D vectors only")
    return plot(M, v, **kwargs)


def plot3_basis(basis, z, **kwargs):
    """scikit-fem's ``plot3`` (a surface z = u(x, y)) for a scalar natural-neighbour basis."""
    from skfem.visuals.matplotlib import plot3
    _check_keywords(kwargs, PLOT3_KEYWORDS, "plot3")
    if isinstance(basis.elem, ElementVector):
        raise NotImplementedError("plot3 draws a scalar field: plot each component, "
                                  "for c, b in basis.split(u): b.plot3(c)")
    if "ax" not in kwargs:  # scikit-fem would open a second figure for the default
        import matplotlib.pyplot as plt
        kwargs["ax"] = plt.figure().add_subplot(1, 1, 1, projection="3d")
    return plot3(*refined_values(basis, z, _nrefs(kwargs)), **kwargs)


def draw_basis(basis, **kwargs):
    """scikit-fem's ``draw`` for a natural-neighbour basis: the outline of its triangles
    (of its ``elements`` for a subdomain basis), as scikit-fem draws a basis."""
    from skfem.visuals.matplotlib import draw
    _check_keywords(kwargs, DRAW_KEYWORDS, "draw")
    _nrefs(kwargs)  # the outline does not depend on the refinement
    mesh = basis.mesh
    if not isinstance(mesh, MeshTri):
        raise NotImplementedError(f"draw of a {type(mesh).__name__} basis: draw the mesh, "
                                  f"skfem.visuals.matplotlib.draw(basis.mesh)")
    if basis.tind is not None:
        mesh = MeshTri(mesh.p, mesh.t[:, basis.tind], sort_t=False)
    kwargs.setdefault("boundaries_only", True)
    return draw(mesh, **kwargs)


def _facet_refused(basis, *args, **kwargs):
    raise NotImplementedError(
        "a facet basis holds values on facets only: plot the field with the cell basis, "
        "NaturalNeighbourBasis(basis.mesh).plot(u), or draw the mesh, "
        "skfem.visuals.matplotlib.draw(basis.mesh)")


def install(cell_basis, facet_basis):
    """Register the natural-neighbour cell and facet basis classes with scikit-fem's
    matplotlib ``plot``, ``plot3`` and ``draw`` (once): at once if
    ``skfem.visuals.matplotlib`` is imported, otherwise when it is (:class:`_OnImport`).
    Importing it imports matplotlib's pyplot, 26 MB of every MPI rank's memory and a
    few tenths of a second, which a run that draws nothing should not pay."""
    if (cell_basis, facet_basis) in _REGISTERED:
        return
    _REGISTERED.add((cell_basis, facet_basis))
    module = sys.modules.get(MATPLOTLIB_VISUALS)
    if module is not None:
        _register(module, cell_basis, facet_basis)
    elif not any(isinstance(f, _OnImport) for f in sys.meta_path):
        sys.meta_path.insert(0, _OnImport())


def _register(mpl, cell_basis, facet_basis) -> None:
    """The bases' plots in the dispatchers of ``mpl`` (``skfem.visuals.matplotlib``)."""
    mpl.plot.register(cell_basis, plot_basis)
    mpl.plot3.register(cell_basis, plot3_basis)
    mpl.draw.register(cell_basis, draw_basis)
    for dispatcher in (mpl.plot, mpl.plot3, mpl.draw):
        dispatcher.register(facet_basis, _facet_refused)


class _OnImport(importlib.abc.MetaPathFinder):
    """Registers the installed bases (:func:`_register`) once
    ``skfem.visuals.matplotlib`` has been executed, whoever imports it: the module is
    found as usual and its loader's ``exec_module`` runs the registration after the
    module's own code. Leaves ``sys.meta_path`` at the first import of the module."""

    def find_spec(self, name, path=None, target=None):
        if name != MATPLOTLIB_VISUALS:
            return None
        sys.meta_path.remove(self)
        spec = importlib.util.find_spec(name)
        if spec is None or spec.loader is None:
            return spec
        run = spec.loader.exec_module

        def exec_module(module):
            run(module)
            for bases in _REGISTERED:
                _register(module, *bases)
        spec.loader.exec_module = exec_module
        return spec


def visuals_call(basis, what, visuals, *args, **kwargs):
    """``basis.plot`` / ``plot3`` / ``draw`` with scikit-fem's ``visuals`` argument: the
    matplotlib functions through their dispatch; another ``skfem.visuals`` module gets the
    refined mesh and values (or the mesh, for ``draw``)."""
    if not isinstance(visuals, str):
        raise TypeError(f"visuals must be the name of a skfem.visuals module, got "
                        f"{type(visuals).__name__}")
    try:
        mod = importlib.import_module(f"skfem.visuals.{visuals}")
    except ImportError as err:
        raise ValueError(f"visuals={visuals!r}: no usable module skfem.visuals.{visuals} "
                         f"({err})") from err
    if not hasattr(mod, what):
        raise ValueError(f"visuals={visuals!r}: skfem.visuals.{visuals} has no {what}()")
    if visuals == "matplotlib":
        return getattr(mod, what)(basis, *args, **kwargs)
    if what == "draw":
        return mod.draw(basis.mesh, **kwargs)
    return getattr(mod, what)(*refined_values(basis, args[0], _nrefs(kwargs)), **kwargs)
