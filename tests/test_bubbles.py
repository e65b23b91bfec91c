"""The Stokes bubbles held as one scalar function give scikit-fem's vector-basis numbers."""
import doctest

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from helpers import cube_nodes, square_nodes
from skfem_nem import delaunay_mesh
from skfem_nem.models import bubbles as bubbles_module
from skfem_nem.models.stokes import body_force, divergence, stress_load, weak_divergence
from skfem_nem.models.stokes_bases import stokes_spaces


def _spaces(dim, n, seed):
    nodes = square_nodes(n, seed=seed, jitter=0.3) if dim == 2 else cube_nodes(n, seed=seed)
    return stokes_spaces(delaunay_mesh(nodes))


def _coefficients(spaces, seed):
    rng = np.random.default_rng(seed)
    d, (ne, nq) = spaces.dim, spaces.pbasis.dx.shape
    return rng.normal(size=(d, ne, nq)), rng.normal(size=(d, d, ne, nq))


def _small_slices(monkeypatch):
    # several slices of cells, the last one short
    monkeypatch.setattr(bubbles_module, "CELLS_AT_A_TIME", 7)


@settings(max_examples=6, deadline=None)
@given(dim=st.sampled_from([2, 3]), seed=st.integers(0, 10_000))
def test_loads_divergence_and_gradient_are_the_vector_basis_bit_for_bit(dim, seed):
    spaces = _spaces(dim, 60 if dim == 2 else 40, seed)
    b, vb, pb = spaces.bubbles, spaces.bubbles.vector_basis(), spaces.pbasis
    f, tau = _coefficients(spaces, seed)
    assert b.N == vb.N == dim * spaces.mesh.nelements
    assert np.array_equal(b.element_dofs, vb.element_dofs)
    assert np.array_equal(b.linear(body_force, f=f), body_force.assemble(vb, f=f))
    assert np.array_equal(b.linear(stress_load, tau=tau), stress_load.assemble(vb, tau=tau))
    for form in (weak_divergence, divergence):
        mine, ref = b.bilinear(form, pb), form.assemble(vb, pb).tocsr()
        assert mine.shape == ref.shape and (mine != ref).nnz == 0
    x = np.random.default_rng(seed).normal(size=b.N)
    assert np.array_equal(b.gradient_of(x), np.asarray(vb.interpolate(x).grad))
    assert np.array_equal(b.gradient(), np.asarray(vb.basis[0][0].grad)[0])


def test_slices_of_cells_and_restricted_cells_give_the_same_numbers(monkeypatch):
    spaces = _spaces(3, 40, 1)
    f, tau = _coefficients(spaces, 1)
    whole = spaces.bubbles
    ref = (whole.linear(stress_load, tau=tau), whole.bilinear(weak_divergence, spaces.pbasis))
    _small_slices(monkeypatch)
    assert whole.dx.shape[0] > 7
    assert np.array_equal(whole.linear(stress_load, tau=tau), ref[0])
    assert (whole.bilinear(weak_divergence, spaces.pbasis) != ref[1]).nnz == 0
    # the cells split in two: the shares add up to the whole, on the whole numbering
    cells = np.arange(spaces.mesh.nelements)
    parts = [spaces.restricted(cells[::2]), spaces.restricted(cells[1::2])]
    loads = [p.bubbles.linear(body_force, f=f[:, p.elements]) for p in parts]
    assert np.array_equal(loads[0] + loads[1], whole.linear(body_force, f=f))
    assert all(p.bubbles.N == whole.N for p in parts)
    assert np.array_equal(parts[1].bubbles.element_dofs, whole.element_dofs[:, 1::2])
    B = sum(p.bubbles.bilinear(weak_divergence, p.pbasis) for p in parts)
    assert abs(B - ref[1]).max() == 0


def test_the_bubbles_hold_a_ninth_of_the_vector_basis():
    """The scalar bubble's values and gradients: 4 numbers a point on tetrahedra, where
    scikit-fem's vector basis holds 36."""
    b = _spaces(3, 40, 2).bubbles

    def held(basis):
        return sum(np.asarray(a).nbytes for fields in basis.basis for field in fields
                   for a in field.astuple if a is not None)

    assert held(b.vector_basis()) == 9 * held(b.basis)


def test_bad_input_is_named():
    b = _spaces(2, 40, 3).bubbles
    with pytest.raises(ValueError, match=r"bubble dofs x must have shape \(%d,\)" % b.N):
        b.gradient_of(np.zeros(b.N + 1))
    with pytest.raises(ValueError, match="coefficient 'f' must be a number or have the"):
        b.linear(body_force, f=np.zeros((2, 5)))
    ne = b.dx.shape[0]
    with pytest.raises(ValueError, match=rf"blocks must have shape \({ne}, 2, 2\), got "
                                         rf"\({ne}, 3, 3\)"):
        b.block_diagonal(np.zeros((ne, 3, 3)))


def test_the_docstring_example_runs():
    finder = doctest.DocTestFinder(recurse=False)
    tests = [t for t in finder.find(bubbles_module.Bubbles, "Bubbles", globs={}) if t.examples]
    assert tests
    runner = doctest.DocTestRunner()
    for test in tests:
        runner.run(test)
    assert runner.failures == 0
