"""Integration-point fields of the 3D evolving mesh: carried across the repaired tetrahedra
by the conservative rule (each step's integral kept to round-off) and the averaging rule
(values within range), surviving tetrahedra unchanged, bad input refused, failed steps
leaving the fields as they were."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from skfem_nem import LagrangianMesh3D
from skfem_nem.evolution import lagrangian3d
from skfem_nem.evolution.remap3d import cell_volumes, from_quadrature, match_rows, to_quadrature
from skfem_nem.geometry.nodesets3d import box_nodes_3d
from skfem_nem.models.stokes import stokes_spaces


def swirl(x):
    a, b, c = np.pi * x.T
    return np.c_[np.sin(a) * np.cos(b), -np.cos(a) * np.sin(b) + np.sin(b) * np.cos(c),
                 -np.cos(b) * np.sin(c)]


def mesh_with_fields(rule, n=500, seed=0):
    p = box_nodes_3d(n, seed=seed)
    m = LagrangianMesh3D(p, remap=rule)
    x = m.ip_points()
    rng = np.random.default_rng(seed)
    fields = {"scalar": rng.random(x.shape[:2]),
              "tensor": rng.standard_normal(x.shape[:2] + (3, 3)),
              "smooth": np.sin(3 * x[..., 0]) * x[..., 1] + x[..., 2],
              "constant": np.full(x.shape[:2], 2.5)}
    return LagrangianMesh3D(p, ip_fields=fields, remap=rule), fields


def integral_before_repair(m, name, x_new, old_t):
    """The pre-repair field on the old tetrahedra at the moved nodes."""
    return np.einsum("t,tk...->...", cell_volumes(x_new, old_t), m.ip_fields[name])


def test_conservative_keeps_each_steps_integral():
    m, _ = mesh_with_fields("conservative")
    dt = 0.15 * 500 ** (-1 / 3)
    remapped = 0
    for _ in range(5):
        old_t, old = m.mesh.t.T.copy(), dict(m.ip_fields)
        m.advance(swirl, dt)
        remapped += m.history[-1]["remapped"]
        for name in old:
            before = np.einsum("t,tk...->...", cell_volumes(m.nodes, old_t), old[name])
            scale = np.abs(old[name]).max() * cell_volumes(m.nodes, old_t).sum()
            assert np.abs(m.ip_integral(name) - before).max() <= 1e-12 * scale, name
    assert remapped > 0, "the flow must change tetrahedra"


def test_average_stays_in_range_and_constants_stay_exact():
    for rule in ("average", "conservative"):
        m, f = mesh_with_fields(rule)
        for _ in range(4):
            m.advance(swirl, 0.15 * 500 ** (-1 / 3))
        assert np.abs(m.ip_fields["constant"] - 2.5).max() < 1e-12
        if rule == "average":
            for name in ("scalar", "tensor", "smooth"):
                g = m.ip_fields[name]
                assert g.min() >= f[name].min() and g.max() <= f[name].max(), name


def test_surviving_tetrahedra_keep_their_values_by_vertex():
    m, _ = mesh_with_fields("conservative")
    before = {tuple(t): dict(zip(t, v)) for t, v in
              zip(np.sort(m.mesh.t.T, axis=1).tolist(), _by_sorted_vertex(m, "scalar"))}
    m.advance(swirl, 0.15 * 500 ** (-1 / 3))
    kept = 0
    for t, v in zip(np.sort(m.mesh.t.T, axis=1).tolist(), _by_sorted_vertex(m, "scalar")):
        if tuple(t) in before:
            assert dict(zip(t, v)) == before[tuple(t)]
            kept += 1
    assert 0 < kept < m.mesh.t.shape[1]


def _by_sorted_vertex(m, name):
    t = m.mesh.t.T
    f = m.ip_fields[name]
    order = np.argsort(t, axis=1).reshape(t.shape + (1,) * (f.ndim - 2))
    return np.take_along_axis(f, order, axis=1).tolist()


def test_ip_points_are_the_stokes_quadrature_points():
    """One point per vertex, a quarter of the volume each, and the same points (in
    scikit-fem's order) as the 3D Stokes spaces, so stresses pass to vep_step unchanged."""
    m, f = mesh_with_fields("average", n=200)
    x = m.ip_points()
    t = m.mesh.t.T
    v = m.nodes[t]                                   # barycentric coordinates of each point
    A = np.concatenate([v.transpose(0, 2, 1), np.ones((t.shape[0], 1, 4))], axis=1)
    rhs = np.concatenate([x.transpose(0, 2, 1), np.ones((t.shape[0], 1, 4))], axis=1)
    lam = np.linalg.solve(A, rhs)                    # (m, 4 coordinates, 4 points)
    a, b = (5 + 3 * np.sqrt(5)) / 20, (5 - np.sqrt(5)) / 20
    assert np.abs(lam - (np.full((4, 4), b) + np.eye(4) * (a - b))).max() < 1e-9
    q = stokes_spaces(m.mesh).quadrature_points      # (3, m, 4)
    assert np.abs(to_quadrature(x) - q).max() < 1e-14
    tau = m.ip_fields["tensor"]
    assert np.array_equal(from_quadrature(to_quadrature(tau)), tau)
    assert to_quadrature(tau).shape == (3, 3) + tau.shape[:2]


@pytest.mark.parametrize("fields, match", [
    ({"s": np.zeros((3, 4))}, r"ip field 's' has shape \(3, 4\)"),
    ("nan", r"ip field 'bad' has non-finite values \(first at tetrahedron 7, cell 2\)"),
])
def test_bad_ip_fields_are_named(fields, match):
    p = box_nodes_3d(200, seed=0)
    if fields == "nan":
        m = LagrangianMesh3D(p)
        f = np.zeros((m.mesh.t.shape[1], 4))
        f[7, 2] = np.nan
        fields = {"bad": f}
    with pytest.raises(ValueError, match=match):
        LagrangianMesh3D(p, ip_fields=fields)


def test_unknown_remap_rule_is_refused():
    with pytest.raises(ValueError, match=r"remap must be one of .* got 'flat'"):
        LagrangianMesh3D(box_nodes_3d(100, seed=0), remap="flat")


def test_a_failed_remap_leaves_the_state_as_it_was(monkeypatch):
    """The last stage of a step fails: mesh, fields, time and history stay."""
    m, _ = mesh_with_fields("conservative")
    m.advance(swirl, 0.1 * 500 ** (-1 / 3))
    state = (m.mesh.t.copy(), np.array(m.nodes), {k: v.copy() for k, v in m.ip_fields.items()},
             m.time, len(m.history))

    def broken(*args):
        raise RuntimeError("remap failed")

    monkeypatch.setattr(lagrangian3d, "remap_fields", broken)
    with pytest.raises(RuntimeError, match="remap failed"):
        m.advance(swirl, 0.3 * 500 ** (-1 / 3))
    assert np.array_equal(m.mesh.t, state[0]) and np.array_equal(m.nodes, state[1])
    assert all(np.array_equal(m.ip_fields[k], v) for k, v in state[2].items())
    assert (m.time, len(m.history)) == state[3:]


def test_save_and_load_carry_the_fields(tmp_path):
    """A checkpoint mid-run: the loaded mesh has the same nodes, tetrahedra, fields (each
    value on its tetrahedron and vertex), clock and history, and the next step agrees."""
    m, _ = mesh_with_fields("conservative")
    dt = 0.15 * 500 ** (-1 / 3)
    m.advance(swirl, dt)
    m.save(tmp_path / "mesh3d.npz")
    back = LagrangianMesh3D.load(tmp_path / "mesh3d.npz")
    assert np.array_equal(back.nodes, m.nodes) and (back.time, back.step) == (m.time, m.step)
    assert back.history == m.history and back.remap == m.remap
    for mesh in (m, back):
        mesh.advance(swirl, dt)
    key = {tuple(t): i for i, t in enumerate(np.sort(m.mesh.t.T, axis=1).tolist())}
    rows = [key[tuple(t)] for t in np.sort(back.mesh.t.T, axis=1).tolist()]
    assert np.array_equal(back.nodes, m.nodes)
    for name in m.ip_fields:
        a = _by_sorted_vertex(m, name)
        b = _by_sorted_vertex(back, name)
        assert np.allclose(np.array(b), np.array(a)[rows], rtol=0, atol=1e-12), name


def test_ip_at_nodes_keeps_constants_and_the_integral():
    lm = LagrangianMesh3D(box_nodes_3d(300, seed=2))
    m = lm.mesh.nelements
    rng = np.random.default_rng(3)
    lm.ip_fields = {"c": np.full((m, 4, 2), [1.5, -2.0]), "r": rng.random((m, 4))}
    np.testing.assert_allclose(lm.ip_at_nodes("c"), np.tile([1.5, -2.0], (lm.nodes.shape[0], 1)),
                               rtol=1e-14)
    # the nodal means times the volume of each node's cells give back the integral
    t = lm.mesh.t.T
    w = np.bincount(t.ravel(), np.repeat(cell_volumes(lm.nodes, t), 4), lm.nodes.shape[0])
    r = lm.ip_at_nodes("r")
    assert r.shape == (lm.nodes.shape[0],)
    np.testing.assert_allclose(w @ r, lm.ip_integral("r"), rtol=1e-13)
    assert r.min() >= lm.ip_fields["r"].min() and r.max() <= lm.ip_fields["r"].max()


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2 ** 31), st.integers(1, 60), st.integers(0, 60))
def test_match_rows_finds_each_kept_tetrahedron(seed, m_old, m_new):
    """Old and new tetrahedra of the same vertices in any order and vertex order are
    matched to their row; the others are not, whatever their keys' neighbours."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(4, 12))
    combos = {tuple(sorted(rng.choice(n, 4, replace=False))) for _ in range(m_old + m_new)}
    combos = sorted(combos)
    rng.shuffle(combos)
    old = np.array(combos[:m_old], dtype=np.int64).reshape(-1, 4)
    pool = combos[:m_old // 2] + combos[m_old:]
    new = np.array([rng.permutation(c) for c in pool], dtype=np.int64).reshape(-1, 4)
    kept, src = match_rows(old, new)
    row = {tuple(sorted(c)): i for i, c in enumerate(old)}
    want = np.array([tuple(sorted(c)) in row for c in new], dtype=bool)
    assert np.array_equal(kept, want)
    for j in np.flatnonzero(kept):
        assert row[tuple(sorted(new[j]))] == src[j]
    assert (src[~kept] == 0).all()
