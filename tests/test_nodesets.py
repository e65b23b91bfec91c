"""Node numbering along a Hilbert curve (``geometry.nodesets.hilbert_order``)."""
import doctest

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from skfem_nem.geometry import nodesets
from skfem_nem.geometry.nodesets import hilbert_order


def test_docstring_example():
    finder = doctest.DocTestFinder(recurse=False)
    tests = finder.find(hilbert_order, "hilbert_order",
                        globs={"np": np, "hilbert_order": hilbert_order})
    runner = doctest.DocTestRunner()
    for t in tests:
        runner.run(t)
    assert sum(len(t.examples) for t in tests) and runner.failures == 0


@settings(max_examples=30, deadline=None)
@given(st.integers(1, 6), st.floats(-1e3, 1e3), st.floats(1e-3, 1e3), st.integers(0, 2**31 - 1))
def test_a_grid_is_walked_one_cell_at_a_time(level, origin, size, seed):
    """A 2^k x 2^k grid of points, anywhere and of any size, given in random order: the
    order is a permutation that steps from each point to a grid neighbour."""
    m = 2 ** level
    i, j = np.meshgrid(np.arange(m), np.arange(m), indexing="ij")
    g = np.c_[i.ravel(), j.ravel()]
    perm = np.random.default_rng(seed).permutation(m * m)
    P = origin + size / m * (g[perm] + 0.5)
    o = hilbert_order(P)
    np.testing.assert_array_equal(np.sort(o), np.arange(m * m))
    steps = np.abs(np.diff(g[perm][o], axis=0)).sum(axis=1)
    assert (steps == 1).all()


@settings(max_examples=20, deadline=None)
@given(st.integers(2, 3000), st.integers(0, 2**31 - 1))
def test_random_points_get_nearby_neighbours(n, seed):
    """Random points: a permutation; from 500 points on, consecutive points along it
    are on average five times closer than in the given (random) order."""
    P = np.random.default_rng(seed).random((n, 2))
    o = hilbert_order(P)
    np.testing.assert_array_equal(np.sort(o), np.arange(n))
    walk = np.hypot(*np.diff(P[o], axis=0).T).mean()
    given_order = np.hypot(*np.diff(P, axis=0).T).mean()
    assert n < 500 or walk < 0.2 * given_order


def test_bad_points_are_refused_by_shape():
    with pytest.raises(ValueError, match=r"\(n, 2\) array, got shape \(4, 3\)"):
        hilbert_order(np.zeros((4, 3)))
    with pytest.raises(ValueError, match="finite"):
        hilbert_order(np.array([[0.0, np.nan]]))
    assert hilbert_order(np.zeros((0, 2))).size == 0
    assert hilbert_order(np.zeros((3, 2))).tolist() == [0, 1, 2]   # one point, repeated
    assert nodesets.HILBERT_BITS == 16
