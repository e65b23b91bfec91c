"""The evolving mesh with segments: they move with their nodes, stay edges through flips,
relocation and injection, are split where stretched, and survive checkpoints and failed
steps exactly."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree

from helpers import square_nodes, vortex
from skfem_nem import LagrangianMesh
from skfem_nem.geometry.meshes import triangulation_of

LINE_Y = 0.7


def outlined_square(n=400, seed=0, m=40, centre=(0.5, 0.3), radius=(0.2, 0.12), k=25):
    """Random nodes in the unit square (away from the lines), a closed polygon of m nodes
    on an ellipse and an open polyline of k nodes along y = LINE_Y; returns the nodes, the
    segments (polygon first) and the polygon's and the polyline's node indices."""
    th = np.linspace(0, 2 * np.pi, m, endpoint=False)
    ring = np.c_[centre[0] + radius[0] * np.cos(th), centre[1] + radius[1] * np.sin(th)]
    xs = np.linspace(0.1, 0.9, k)
    line = np.c_[xs, np.full(k, LINE_Y)]
    p = square_nodes(n, 16, seed, jitter=0.3, margin=0.01)
    d, _ = cKDTree(np.r_[ring, line]).query(p)
    p = p[(d > 0.02) | (np.arange(p.shape[0]) < 64)]  # the square's corners and sides stay
    k0 = p.shape[0]
    poly, pl = k0 + np.arange(m), k0 + m + np.arange(k)
    segs = np.r_[np.c_[poly, np.roll(poly, -1)], np.c_[pl[:-1], pl[1:]]]
    return np.r_[p, ring, line], segs, poly, pl


def check_constrained(lm):
    tri = lm.triangulation
    assert tri.missing_segments().size == 0          # every segment is an edge
    assert tri.non_delaunay_edges() == 0             # constrained Delaunay
    assert np.all(tri.orientation() > 0)
    used = np.zeros(tri.npoints, bool)
    used[tri.triangles.ravel()] = True
    assert used.all()


def check_chain(lm, nodes, closed):
    """The polyline through ``nodes`` (with the nodes inserted since) runs along segments
    and takes every piece of its segments."""
    chain = lm.polyline(nodes, closed=closed)
    pairs = np.c_[chain, np.roll(chain, -1)] if closed else np.c_[chain[:-1], chain[1:]]
    keys = (np.minimum(*pairs.T) << 32) | np.maximum(*pairs.T)
    assert np.isin(keys, lm.triangulation.segment_keys).all()
    assert len(set(keys.tolist())) == len(keys)
    return chain


def shear(x):
    return np.c_[0.6 * np.sin(np.pi * x[:, 0]) * (x[:, 1] - 0.5), 0 * x[:, 1]]


@settings(max_examples=4, deadline=None)
@given(seed=st.integers(0, 2 ** 16), m=st.integers(24, 48),
       cx=st.floats(0.4, 0.6), cy=st.floats(0.28, 0.34))
def test_segments_stay_edges_in_shear_and_vortex(seed, m, cx, cy):
    nodes, segs, poly, pl = outlined_square(300, seed, m, centre=(cx, cy))
    lm = LagrangianMesh(nodes, segments=segs, node_fields={"x0": nodes},
                        ip_fields={"s": np.ones(3)})
    check_constrained(lm)
    nseg0 = lm.triangulation.segment_keys.size
    for k in range(70):
        r = lm.advance(shear if k < 10 else vortex, 0.03 if k < 10 else 0.012, inject=2.0)
        check_constrained(lm)
    split = sum(h["segments_split"] for h in lm.history)
    assert split > 0                                  # the lines were stretched and split
    assert lm.triangulation.segment_keys.size == nseg0 + split
    assert r["injected"] >= r["segments_split"]
    ring = check_chain(lm, poly, closed=True)
    line = check_chain(lm, pl, closed=False)
    pieces = np.bincount(lm.triangulation.segment_source, minlength=len(segs))
    assert len(ring) == pieces[:m].sum() and len(line) == pieces[m:].sum() + 1
    # nodes inserted on the straight polyline carry initial positions on it (the mean
    # of its ends: linear along the segment), and a constant ip field keeps its integral
    np.testing.assert_array_equal(lm.node_fields["x0"][line, 1], LINE_Y)
    np.testing.assert_allclose(lm.ip_integral("s"), 1.0, atol=1e-12)
    # the mesh and basis see the segments (constrained coordinates)
    tri = triangulation_of(lm.mesh)
    np.testing.assert_array_equal(tri.segment_keys, lm.triangulation.segment_keys)
    assert lm.basis().nelems == lm.triangles.shape[0]


def test_a_long_segment_is_split_at_its_midpoint():
    nodes, segs, poly, pl = outlined_square(200, 1)
    lm = LagrangianMesh(nodes, segments=segs, ip_fields={"s": np.arange(3.0)})
    a, b = segs[len(poly) + 3]
    # stretch the polyline along itself: its nodes move apart, the rest stands
    right = nodes[:, 0] > nodes[b, 0] - 1e-12
    x = lm.nodes.copy()
    x[right & (np.abs(nodes[:, 1] - LINE_Y) < 1e-12), 0] += 0.06
    lm.triangulation.move_nodes(x)
    lm.triangulation.make_delaunay(on_flips=lambda log: None)
    n = lm.triangulation.npoints
    assert lm.split_segments(2.0) == 1
    tri = lm.triangulation
    np.testing.assert_array_equal(tri.nodes[n], 0.5 * (tri.nodes[a] + tri.nodes[b]))
    keys = tri.segment_keys
    assert (a << 32 | b) not in keys and (a << 32 | n) in keys and (b << 32 | n) in keys
    src = tri.segment_source[np.searchsorted(keys, [a << 32 | n, b << 32 | n])]
    assert (src == len(poly) + 3).all()               # both halves: the same given segment
    check_constrained(lm)
    assert lm.split_segments(2.0) == 0                # the halves are short enough


def test_checkpoint_keeps_segments_and_continues_bit_identically(tmp_path):
    nodes, segs, poly, _ = outlined_square(300, 2)
    a = LagrangianMesh(nodes, segments=segs, node_fields={"x0": nodes},
                       ip_fields={"s": np.arange(3.0)})
    for _ in range(30):
        a.advance(vortex, 0.012, inject=1.5)
    assert sum(h["segments_split"] for h in a.history) > 0
    a.save(tmp_path / "ck.npz")
    b = LagrangianMesh.load(tmp_path / "ck.npz")
    for name in ("segment_keys", "segment_source"):
        np.testing.assert_array_equal(getattr(a.triangulation, name),
                                      getattr(b.triangulation, name))
    for _ in range(10):
        a.advance(vortex, 0.012, inject=1.5)
        b.advance(vortex, 0.012, inject=1.5)
    for name in ("nodes", "triangles", "segment_keys", "segment_source"):
        np.testing.assert_array_equal(getattr(a.triangulation, name),
                                      getattr(b.triangulation, name))
    np.testing.assert_array_equal(a.ip_fields["s"], b.ip_fields["s"])
    assert a.history == b.history
    np.testing.assert_array_equal(a.polyline(poly, closed=True), b.polyline(poly, closed=True))


def saved_state(lm, path):
    lm.save(path)
    with np.load(path) as z:
        return {k: z[k].copy() for k in z.files}


def assert_same_state(a, b):
    assert a.keys() == b.keys()
    assert "segments" in a
    for k in a:
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)


def test_a_segment_node_pushed_through_the_polygon_fails_the_step_cleanly(tmp_path):
    nodes, segs, poly, _ = outlined_square(300, 3)
    lm = LagrangianMesh(nodes, segments=segs, ip_fields={"s": np.arange(3.0)})
    lm.advance(vortex, 0.01, inject=2.0)
    before = saved_state(lm, tmp_path / "before.npz")
    i, j = poly[0], poly[len(poly) // 2]              # opposite nodes of the polygon
    target = nodes[j] + 0.3 * (nodes[j] - nodes[i])   # beyond the far side, in the box

    def push(x):
        v = np.zeros_like(x)
        v[i] = target - nodes[i]
        return v

    with pytest.raises(ValueError, match="would cross segment .* reduce dt"):
        lm.advance(push, 1.0, max_substeps=4, inject=2.0)
    assert_same_state(saved_state(lm, tmp_path / "after.npz"), before)
    lm.advance(vortex, 0.01, inject=2.0)              # and the mesh goes on
    check_constrained(lm)


@pytest.mark.parametrize("stage", ["split_segments", "_recover_segments"])
def test_a_failing_stage_restores_the_segments_exactly(stage, tmp_path, monkeypatch):
    nodes, segs, _, _ = outlined_square(300, 4)
    lm = LagrangianMesh(nodes, segments=segs, ip_fields={"s": np.arange(3.0)})
    for _ in range(25):
        lm.advance(vortex, 0.012, inject=1.5)
    before = saved_state(lm, tmp_path / "before.npz")
    calls = []

    def failing(original):
        def f(*args, **kwargs):
            original(*args, **kwargs)
            calls.append(1)
            raise RuntimeError(f"{stage} failed")
        return f

    monkeypatch.setattr(lm, stage, failing(getattr(lm, stage)))
    if stage == "split_segments":
        with pytest.raises(RuntimeError, match="failed"):
            lm.advance(vortex, 0.03, inject=1.2)
    else:  # random jumps invert triangles with segment nodes: relocation
        for seed in range(30):
            before = saved_state(lm, tmp_path / "before.npz")
            try:
                lm.advance(jumps(seed), 1.0, max_substeps=4)
            except ValueError:
                continue                              # "reduce dt": restored as well
            except RuntimeError:
                break
    assert calls
    assert_same_state(saved_state(lm, tmp_path / "after.npz"), before)


def jumps(seed, amplitude=0.006):
    """Random displacements (vanishing at the walls): triangles invert."""
    def v(x):
        bump = 16 * x[:, 0] * (1 - x[:, 0]) * x[:, 1] * (1 - x[:, 1])
        return amplitude * bump[:, None] * np.random.default_rng(seed).standard_normal(x.shape)
    return v


def test_relocation_of_segment_nodes_keeps_the_segments():
    """Random jumps: each step either keeps every segment (segment nodes relocated and
    their segments flipped back) or fails with "reduce dt" and leaves the mesh as it was."""
    nodes, segs, _, _ = outlined_square(300, 5)
    lm = LagrangianMesh(nodes, segments=segs, ip_fields={"s": np.arange(3.0)})
    recovered, failed = [], 0
    original = lm.triangulation.recover_segments

    def spy():
        original()
        recovered.append(1)

    lm.triangulation.recover_segments = spy
    for seed in range(30):
        snap = lm.triangulation.snapshot()
        try:
            lm.advance(jumps(seed), 1.0, max_substeps=4)
        except ValueError as err:
            assert "reduce dt" in str(err)
            failed += 1
            for k in ("nodes", "triangles", "segment_keys", "segment_source"):
                np.testing.assert_array_equal(getattr(lm.triangulation, k), snap[k])
            continue
        check_constrained(lm)
    assert recovered                                  # segment nodes were relocated
    assert failed < 30


def test_segment_rows_find_segments_by_their_nodes():
    """Each segment's node pair, in either order, gives its row; a pair that is not a
    segment gives -1, as does any pair on a mesh without segments."""
    nodes, segs, poly, _ = outlined_square(300, 2)
    tri = LagrangianMesh(nodes, segments=segs).triangulation
    S = tri.segments
    np.testing.assert_array_equal(tri.segment_rows(S), np.arange(S.shape[0]))
    np.testing.assert_array_equal(tri.segment_rows(S[:, ::-1]), np.arange(S.shape[0]))
    assert tri.segment_rows([[poly[0], poly[5]]]).tolist() == [-1]
    assert LagrangianMesh(nodes).triangulation.segment_rows(S[:2]).tolist() == [-1, -1]


@pytest.mark.parametrize("m", [3, 4, 40])
def test_a_loop_of_one_source_is_walked_the_short_way(m):
    """A closed polygon whose segments all carry one source (as after cuts and closures
    of a loop) is a loop of that source: each of its sides is walked the short way, so
    the polyline through its nodes lists each node once, in either direction."""
    nodes, segs, _, _ = outlined_square(300, 3, m=m)
    lm = LagrangianMesh(nodes, segments=segs)
    tri = lm.triangulation
    poly = nodes.shape[0] - 25 - m + np.arange(m)
    tri.set_segments(tri.segments, np.where(np.arange(len(segs)) < m, 7, tri.segment_source))
    for order in (poly, poly[::-1]):
        np.testing.assert_array_equal(lm.polyline(order, closed=True), order)
