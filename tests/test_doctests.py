"""The examples in the docstrings of the main public names run and print what they show.

Each object is taken from the top-level ``skfem_nem`` namespace, so the test follows the
object wherever its module moves. An object whose docstring has no examples fails: the
examples are part of its documentation.
"""
import doctest

import pytest

import skfem_nem

DOCUMENTED = ["delaunay_mesh", "NaturalNeighbourBasis", "sibson_coordinates", "Triangulation",
              "LagrangianMesh", "ElementNaturalNeighbour2", "NaturalNeighbourInterpolator",
              "estimate_gradients", "natural_neighbour_to_grid", "natural_neighbour_solver"]


def _own_tests(name):
    """The doctests of the object's own docstring (not of its methods)."""
    obj = getattr(skfem_nem, name)
    finder = doctest.DocTestFinder(recurse=False)
    return [t for t in finder.find(obj, name, globs={}) if t.examples]


@pytest.mark.parametrize("name", DOCUMENTED)
def test_docstring_examples(name):
    tests = _own_tests(name)
    assert tests, f"skfem_nem.{name} has no examples in its docstring"
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    report = []
    for test in tests:
        runner.run(test, out=report.append)
    assert runner.failures == 0, "".join(report)
