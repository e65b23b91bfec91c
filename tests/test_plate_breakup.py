"""A plate that necks through breaks in two: segments reconnected in one transaction,
the outline loop cut at the neck (and not where the plate folds onto itself or two pieces
meet), and the sinking plate going on with both pieces."""
import numpy as np
import pytest
from scipy.spatial import cKDTree

from helpers import square_nodes
from test_evolution_segments import (assert_same_state, check_chain, check_constrained,
                                     outlined_square, saved_state)
from skfem_nem import LagrangianMesh
from skfem_nem.apps.plate_outlines import (FOLD_AREA_TOLERANCE, PINCH_FRACTION, WELD_FRACTION,
                                           PlateOutlines, polygon_area_centroid)
from skfem_nem.apps.plate_time_step import ClosingFilm
from skfem_nem.apps.sinking_plate import PlateConfig, SinkingPlate
from skfem_nem.geometry.nodesets import polyline_nodes

SPACING = 0.025


def pair_rows(lm, pairs):
    seg = lm.triangulation.segments
    return [int(np.flatnonzero(((seg == p) | (seg == p[::-1])).all(axis=1))[0]) for p in pairs]


def ellipse_mesh(seed=5):
    nodes, segs, poly, line = outlined_square(300, seed)
    lm = LagrangianMesh(nodes, segments=segs, ip_fields={"one": np.ones(3)})
    lm.ip_fields["rand"] = np.random.default_rng(seed).normal(size=(lm.triangles.shape[0], 3))
    return lm, poly, line


def test_reconnect_segments_cuts_a_polygon_in_two():
    """The ellipse's segments (4, 5) and (25, 26) replaced by (25, 5) and (4, 26): two
    loops of segments sharing no node, every segment an edge, the mesh constrained
    Delaunay, integrals of the ip fields kept."""
    lm, poly, _ = ellipse_mesh()
    before = {k: lm.ip_integral(k) for k in ("one", "rand")}
    k = lm.triangulation.segments.shape[0]
    rows = pair_rows(lm, [poly[[4, 5]], poly[[25, 26]]])
    source = lm.triangulation.segment_source[rows]
    new = lm.reconnect_segments(rows, [poly[[25, 5]], poly[[4, 26]]], source)
    np.testing.assert_array_equal(new, np.arange(lm.nodes.shape[0]))
    check_constrained(lm)
    assert lm.triangulation.segments.shape[0] == k
    a = check_chain(lm, poly[5:26], closed=True)
    b = check_chain(lm, np.r_[poly[26:], poly[:5]], closed=True)
    assert not set(a) & set(b) and len(a) + len(b) == len(poly)
    for name, value in before.items():
        np.testing.assert_allclose(lm.ip_integral(name), value, rtol=1e-13, atol=1e-13)


@pytest.mark.parametrize("stage", ["source", "crossing", "removal", "flips"])
def test_a_failing_reconnection_leaves_the_mesh_unchanged(stage, tmp_path):
    """Each stage made to fail in turn (a bad source, two new segments that cross, a
    node whose segments cannot merge, the last flips): ValueError or the flips' error,
    and the whole state as before."""
    lm, poly, _ = ellipse_mesh()
    rows = pair_rows(lm, [poly[[4, 5]], poly[[25, 26]]])
    source = lm.triangulation.segment_source[rows]
    add, remove = [poly[[25, 5]], poly[[4, 26]]], []
    if stage == "source":
        source = [0, lm.triangulation.segments.shape[0] + 5]
    elif stage == "crossing":
        add = [poly[[25, 5]], poly[[4, 14]]]        # chords whose ends interleave: cross
    elif stage == "removal":
        remove = [poly[26]]            # (4, 26, 27) holds the polygon's inner nodes
    before = saved_state(lm, tmp_path / "before.npz")
    tri = lm.triangulation
    if stage == "flips":
        calls, original = [], tri.make_delaunay

        def failing(*args, **kwargs):
            calls.append(1)
            if len(calls) == 2:          # after the segments were recovered and refilled
                raise RuntimeError("flips failed")
            return original(*args, **kwargs)
        tri.make_delaunay = failing
    with pytest.raises((ValueError, RuntimeError)):
        lm.reconnect_segments(rows, add, source, remove=remove)
    if stage == "flips":
        del tri.make_delaunay
    assert_same_state(saved_state(lm, tmp_path / "after.npz"), before)
    lm.reconnect_segments(rows, [poly[[25, 5]], poly[[4, 26]]],
                          lm.triangulation.segment_source[rows])
    check_constrained(lm)


def dumbbell(neck, gap=None, seed=0):
    """Two lobes 0.25 x 0.3 joined by a neck 0.1 long and ``neck`` thick, or (``gap``) a
    U: the lobes joined at the bottom with a gap between their tops; random nodes around.
    Returns the mesh with the outline as segments and the outline's loop."""
    y0, y1 = 0.5 - neck / 2, 0.5 + neck / 2
    if gap is None:
        corners = [[0.2, 0.35], [0.45, 0.35], [0.45, y0], [0.55, y0], [0.55, 0.35],
                   [0.8, 0.35], [0.8, 0.65], [0.55, 0.65], [0.55, y1], [0.45, y1],
                   [0.45, 0.65], [0.2, 0.65]]
    else:
        corners = [[0.2, 0.35], [0.8, 0.35], [0.8, 0.65], [0.5 + gap / 2, 0.65],
                   [0.5 + gap / 2, 0.45], [0.5 - gap / 2, 0.45], [0.5 - gap / 2, 0.65],
                   [0.2, 0.65]]
    return outlined(corners, seed)


def outlined(corners, seed=0):
    """The polygon of ``corners`` as a loop of segments, random nodes around; the mesh
    and the loop."""
    ring = polyline_nodes(corners, SPACING, closed=True)
    p = square_nodes(300, 16, seed, jitter=0.3, margin=0.01)
    d, _ = cKDTree(ring).query(p)
    p = p[(d > 0.03) | (np.arange(p.shape[0]) < 64)]
    loop = p.shape[0] + np.arange(len(ring))
    lm = LagrangianMesh(np.r_[p, ring], segments=np.c_[loop, np.roll(loop, -1)],
                        ip_fields={"one": np.ones(3)})
    return lm, loop


def facing(lm, loop, x, inside_y):
    """The loop's two segments that cross the vertical x = ``x``, nearest ``inside_y``."""
    P = lm.nodes[loop]
    Q = np.roll(P, -1, axis=0)
    cross = np.flatnonzero((P[:, 0] - x) * (Q[:, 0] - x) < 0)
    cross = cross[np.argsort(np.abs(0.5 * (P[cross, 1] + Q[cross, 1]) - inside_y))][:2]
    return pair_rows(lm, [loop[[i, (i + 1) % len(loop)]] for i in cross])


@pytest.mark.parametrize("neck", [0.02, 0.2 * SPACING])
def test_a_plate_is_cut_in_two_at_its_neck(neck):
    """The cut gives two loops of segments sharing no node, one per lobe, their reference
    areas the whole's split in proportion; the outlines cross nowhere; a neck thinner than
    PINCH_FRACTION of the spacing loses one node on each side (they had met), a thicker
    one none."""
    lm, loop = dumbbell(neck)
    A0 = abs(polygon_area_centroid(lm.nodes[loop])[0])
    outlines = PlateOutlines([loop], [A0])
    n, area = lm.nodes.shape[0], lm.ip_integral("one")
    assert outlines.pinch(lm, *facing(lm, loop, 0.5, 0.5), SPACING) is None
    check_constrained(lm)
    assert len(outlines.loops) == 2
    a, b = outlines.loops
    assert not set(a.tolist()) & set(b.tolist())
    for o in outlines.loops:
        check_chain(lm, o, closed=True)
    assert sum(outlines.areas0) == pytest.approx(A0, rel=1e-14)
    assert outlines.crossings(lm.nodes) == 0
    P = lm.nodes
    assert outlines.inside(P, np.array([[0.3, 0.5], [0.7, 0.5]])).all()
    lobes = sorted(polygon_area_centroid(P[o])[1][0] for o in outlines.loops)
    assert lobes[0] < 0.45 < 0.55 < lobes[1]
    assert 0 <= outlines.deficits(P).sum() <= 2 * neck * SPACING   # the slivers cut off
    removed = 2 if neck < PINCH_FRACTION * SPACING else 0
    assert lm.nodes.shape[0] == n - removed
    assert len(a) + len(b) == len(loop) - removed
    np.testing.assert_allclose(lm.ip_integral("one"), area, rtol=1e-13)


@pytest.mark.parametrize("case", ["much fluid", "plate above its area"])
def test_no_cut_where_the_plate_folds_around_much_fluid_or_two_pieces_meet(case, tmp_path):
    """Faces meeting from outside (the arms of a U) half way up, around fluid of 1.3% of
    the plate's area; or lower down, around 0.6%, where the plate is already 0.8% above
    its reference area; or segments of two pieces: the reason comes back, nothing
    changes."""
    lm, loop = dumbbell(0.0, gap=0.02)
    A0 = abs(polygon_area_centroid(lm.nodes[loop])[0])
    y, areas0 = (0.55, [A0]) if case == "much fluid" else (0.4875, [A0 / 1.008])
    outlines = PlateOutlines([loop], areas0)
    before = saved_state(lm, tmp_path / "before.npz")
    rows = pair_rows(lm, [loop[[i, (i + 1) % len(loop)]] for i in _arms(lm, loop, y)])
    why = outlines.pinch(lm, *rows, SPACING)
    assert "folds onto itself" in why and "more than FOLD_AREA_TOLERANCE" in why
    assert_same_state(saved_state(lm, tmp_path / "after.npz"), before)
    assert len(outlines.loops) == 1 and outlines.areas0 == areas0
    if case == "plate above its area":      # the same fold closes at the reference area
        assert PlateOutlines([loop], [A0]).pinch(lm, *rows, SPACING) is None
        return
    lm, loop = dumbbell(0.02)
    outlines = PlateOutlines([loop], [1.0])
    assert outlines.pinch(lm, *facing(lm, loop, 0.5, 0.5), SPACING) is None
    first = pair_rows(lm, [outlines.loops[0][:2]])[0]
    second = pair_rows(lm, [outlines.loops[1][:2]])[0]
    before = saved_state(lm, tmp_path / "before2.npz")
    assert "two pieces" in outlines.pinch(lm, first, second, SPACING)
    assert_same_state(saved_state(lm, tmp_path / "after2.npz"), before)


def two_blocks(gap, seed=0):
    """Two blocks 0.3 high side by side, ``gap`` apart, each outlined by its own loop of
    segments turning the same way; random nodes around. The mesh and the two loops."""
    x0, x1 = 0.5 - gap / 2, 0.5 + gap / 2
    left = polyline_nodes([[0.2, 0.35], [x0, 0.35], [x0, 0.65], [0.2, 0.65]], SPACING, True)
    right = polyline_nodes([[x1, 0.35], [0.8, 0.35], [0.8, 0.65], [x1, 0.65]], SPACING, True)
    p = square_nodes(300, 16, seed, jitter=0.3, margin=0.01)
    d, _ = cKDTree(np.r_[left, right]).query(p)
    p = p[(d > 0.03) | (np.arange(p.shape[0]) < 64)]
    a = p.shape[0] + np.arange(len(left))
    b = a[-1] + 1 + np.arange(len(right))
    segs = np.r_[np.c_[a, np.roll(a, -1)], np.c_[b, np.roll(b, -1)]]
    lm = LagrangianMesh(np.r_[p, left, right], segments=segs, ip_fields={"one": np.ones(3)})
    return lm, a, b


def _facing_sides(lm, a, b):
    """Rows of the two segments facing each other across the gap, nearest y = 0.5."""
    rows = []
    for loop, x in ((a, lm.nodes[a, 0].max()), (b, lm.nodes[b, 0].min())):
        P, Q = lm.nodes[loop], lm.nodes[np.roll(loop, -1)]
        side = np.flatnonzero((np.abs(P[:, 0] - x) < 1e-12) & (np.abs(Q[:, 0] - x) < 1e-12))
        i = side[np.argmin(np.abs(0.5 * (P[side, 1] + Q[side, 1]) - 0.5))]
        rows.append(pair_rows(lm, [[loop[i], loop[(i + 1) % len(loop)]]])[0])
    return rows


def test_two_pieces_that_meet_are_joined_into_one():
    """Two pieces whose facing sides meet across a film: one loop of both pieces' nodes,
    turning the same way, its reference area theirs together; the film joins the plate,
    every segment an edge, the mesh constrained Delaunay, the ip integrals kept."""
    lm, a, b = two_blocks(gap=0.004)
    P = lm.nodes
    areas = [polygon_area_centroid(P[o])[0] for o in (a, b)]
    outlines = PlateOutlines([a, b], [areas[0], 2 * areas[1]])
    before = lm.ip_integral("one")
    assert outlines.pinch(lm, *_facing_sides(lm, a, b), SPACING) is None
    check_constrained(lm)
    assert len(outlines.loops) == 1 and outlines.areas0 == [areas[0] + 2 * areas[1]]
    o = outlines.loops[0]
    check_chain(lm, o, closed=True)
    assert len(o) == len(a) + len(b) == lm.triangulation.segments.shape[0]
    assert outlines.crossings(lm.nodes) == 0
    joined = polygon_area_centroid(lm.nodes[o])[0]
    assert 0 < joined - sum(areas) <= 0.004 * SPACING * (1 + 1e-9)     # the film
    assert outlines.inside(lm.nodes, np.array([[0.5, 0.5], [0.3, 0.5], [0.7, 0.5]])).all()
    np.testing.assert_allclose(lm.ip_integral("one"), before, rtol=1e-13)


def test_pieces_that_meet_far_from_a_film_are_not_joined(tmp_path):
    """The facing sides 0.04 apart, more than the outline's spacing: the reason comes
    back and nothing changes."""
    lm, a, b = two_blocks(gap=0.04)
    outlines = PlateOutlines([a, b], [1.0, 1.0])
    before = saved_state(lm, tmp_path / "before.npz")
    why = outlines.pinch(lm, *_facing_sides(lm, a, b), SPACING)
    assert "two pieces of the plate meet" in why and "spacing" in why
    assert_same_state(saved_state(lm, tmp_path / "after.npz"), before)
    assert len(outlines.loops) == 2 and outlines.areas0 == [1.0, 1.0]


def _arms(lm, loop, y):
    """Positions of the two segments facing each other across the U's gap, nearest
    height ``y``."""
    P = lm.nodes[loop]
    Q = np.roll(P, -1, axis=0)
    mid = 0.5 * (P + Q)
    vertical = np.abs(P[:, 0] - Q[:, 0]) < 1e-12
    out = []
    for x in (0.49, 0.51):
        cand = np.flatnonzero(vertical & (np.abs(mid[:, 0] - x) < 1e-9))
        out.append(cand[np.argmin(np.abs(mid[cand, 1] - y))])
    return out


def test_a_small_fold_is_closed_and_its_fluid_joins_the_plate():
    """The arms of a U meeting from outside just above the bottom of its slot: the plate
    keeps the outer loop (one piece, the same reference area), the pocket's segments and
    the two that met are released (the nodes below the upper ends of those two on no
    segment, inside the plate: the two can never cross), every segment an edge, the mesh
    constrained Delaunay, the ip integrals kept."""
    lm, loop = dumbbell(0.0, gap=0.02)
    P = lm.nodes
    A0 = abs(polygon_area_centroid(P[loop])[0])
    outlines = PlateOutlines([loop], [A0])
    before = lm.ip_integral("one")
    arms = _arms(lm, loop, 0.4875)
    met = [loop[[i, (i + 1) % len(loop)]] for i in arms]
    rows = pair_rows(lm, met)
    # the slot's nodes below the upper ends of the two segments that meet (at y = 0.5)
    top = max(P[met[0], 1])
    pocket = [n for n in loop if abs(P[n, 0] - 0.5) < 0.011 and P[n, 1] < top - 1e-9]
    assert outlines.pinch(lm, *rows, SPACING) is None
    check_constrained(lm)
    assert len(outlines.loops) == 1 and outlines.areas0 == [A0]
    o = outlines.loops[0]
    check_chain(lm, o, closed=True)
    assert lm.triangulation.segments.shape[0] == len(o) == len(loop) - len(pocket)
    assert not set(pocket) & set(lm.triangulation.segments.ravel())
    assert outlines.inside(lm.nodes, lm.nodes[pocket]).all()
    area = abs(polygon_area_centroid(lm.nodes[o])[0])
    assert 0 < area / A0 - 1 <= FOLD_AREA_TOLERANCE      # the pocket joined the plate
    np.testing.assert_allclose(lm.ip_integral("one"), before, rtol=1e-13)


def _loop_segment(lm, loop, a, b):
    """Row of the loop's segment from the node nearest ``a`` to the node nearest ``b``
    (within 1e-3), and its position in the loop."""
    P = lm.nodes[loop]
    i = int(np.argmin(np.hypot(*(P - a).T)))
    j = (i + 1) % len(loop)
    assert np.allclose(P[i], a, atol=1e-3) and np.allclose(P[j], b, atol=1e-3)
    return pair_rows(lm, [loop[[i, j]]])[0], i


# a sliver of fluid (the bottom of a U's slot) and one of plate (a spike on its top)
# (the slot narrows to its bottom, so its bottom nodes are the two nearest each other)
SPIKES = {"crack": ([[0.2, 0.35], [0.8, 0.35], [0.8, 0.65], [0.51, 0.65], [0.505, 0.45],
                     [0.495, 0.45], [0.49, 0.65], [0.2, 0.65]],
                    [(0.5056, 0.4722), (0.505, 0.45)], [(0.495, 0.45), (0.4944, 0.4722)]),
          "neck": ([[0.2, 0.35], [0.8, 0.35], [0.8, 0.65], [0.505, 0.65], [0.5, 0.69],
                    [0.495, 0.65], [0.2, 0.65]],
                   [(0.505, 0.65), (0.5025, 0.67)], [(0.4975, 0.67), (0.495, 0.65)]),
          "spike": ([[0.2, 0.35], [0.8, 0.35], [0.8, 0.65], [0.505, 0.65], [0.5, 0.67],
                     [0.495, 0.65], [0.2, 0.65]],
                    [(0.505, 0.65), (0.5, 0.67)], [(0.5, 0.67), (0.495, 0.65)])}


@pytest.mark.parametrize("kind", sorted(SPIKES))
def test_a_spike_is_closed_across_its_base(kind, tmp_path):
    """Faces of the loop meeting a few nodes apart along it (a cut would leave a piece
    of fewer than three nodes or a sliver of at most WELD_FRACTION of the area): the
    arc's segments are released, the nodes at its tip removed, a segment joins its
    ends; one loop, the same reference area, every segment an edge, the mesh
    constrained Delaunay, the ip integrals kept. Where the sliver is more than
    WELD_FRACTION of the reference area, nothing changes (or, at a neck, the plate is
    cut in two)."""
    corners, first, second = SPIKES[kind]
    lm, loop = outlined(corners)
    P = lm.nodes
    A0 = abs(polygon_area_centroid(P[loop])[0])
    (r0, i), (r1, j) = (_loop_segment(lm, loop, *f) for f in (first, second))
    tip = loop[i + 1:j + 1]
    assert 1 <= len(tip) <= (3 if kind == "neck" else 2)
    sliver = abs(polygon_area_centroid(P[loop[i:j + 2]])[0])
    # (at the neck, the piece a cut would leave is the tip's, inside the sliver)
    piece = abs(polygon_area_centroid(P[tip])[0]) if kind == "neck" else sliver
    small = PlateOutlines([loop], [0.99 * piece / WELD_FRACTION])
    before = saved_state(lm, tmp_path / "before.npz")
    why = small.pinch(lm, r0, r1, SPACING)
    if kind == "neck":
        assert why is None and len(small.loops) == 2
        lm, loop = outlined(corners)
    else:
        assert "more than WELD_FRACTION" in why
        assert_same_state(saved_state(lm, tmp_path / "after.npz"), before)
    outlines = PlateOutlines([loop], [A0])
    n, area = lm.nodes.shape[0], lm.ip_integral("one")
    ends = lm.nodes[[loop[i], loop[j + 1]]]
    assert outlines.pinch(lm, r0, r1, SPACING) is None
    check_constrained(lm)
    assert len(outlines.loops) == 1 and outlines.areas0 == [A0]
    o = outlines.loops[0]
    check_chain(lm, o, closed=True)
    assert lm.nodes.shape[0] == n - len(tip) and len(o) == len(loop) - len(tip)
    assert lm.triangulation.segments.shape[0] == len(o)
    k = int(np.flatnonzero(np.hypot(*(lm.nodes[o] - ends[0]).T) == 0)[0])
    np.testing.assert_array_equal(lm.nodes[o[[k, (k + 1) % len(o)]]], ends)
    change = abs(polygon_area_centroid(lm.nodes[o])[0]) - A0
    assert change == pytest.approx(sliver if kind == "crack" else -sliver, rel=1e-12)
    np.testing.assert_allclose(lm.ip_integral("one"), area, rtol=1e-13)


def test_the_sinking_plate_goes_on_in_two_pieces(tmp_path):
    """A closing film across the middle of the plate (between its bottom and top faces)
    cuts it in two before the next step, also after a restart from a checkpoint written
    with the film pending; the run goes on with two outlines held to their areas, counted
    in the diagnostics, kept through a checkpoint."""
    cfg = PlateConfig(nodes=300, end_time=6.0, max_dt=2.0, output_interval=6.0)
    sim = SinkingPlate(cfg, tmp_path)
    area0 = sim.plate_area0
    lm, o = sim.lm, sim.outline
    rows = facing(lm, o, cfg.plate_x + 1e-3, cfg.plate_z)
    sim._closing = ClosingFilm(rows[0], rows[1], True, 0.1, "two faces close")
    sim.checkpoint()                     # (a stopped run's checkpoint keeps the film)
    sim = SinkingPlate.restart(tmp_path)
    lm = sim.lm
    sim.run(progress=False)
    from skfem_nem.apps.output import read_csv_columns
    d = read_csv_columns(tmp_path / "diagnostics.csv")
    assert (d["plate_pieces"] == 2).all() and d["pinches"][-1] == 1
    assert np.abs(d["plate_area"] / area0 - 1).max() < 0.02
    assert d["outline_crossings"].max() == 0 and d["inverted_triangles"].max() == 0
    assert len(sim.outlines.loops) == 2
    for loop, a0 in zip(sim.outlines.loops, sim.outlines.areas0):
        assert abs(polygon_area_centroid(lm.nodes[loop])[0]) == pytest.approx(a0, rel=0.02)
    again = SinkingPlate.restart(tmp_path)
    assert [x.tolist() for x in again.outlines.loops] == [x.tolist() for x in sim.outlines.loops]
    assert again.outlines.areas0 == sim.outlines.areas0
    sim.figures()


def test_crossings_count_within_and_between_outlines():
    """A bow tie crosses itself once; two squares overlapping at a corner cross twice;
    apart, or sharing nothing but a neighbourhood, nothing."""
    from skfem_nem.apps.plate_outlines import crossings
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    bowtie = square[[0, 1, 3, 2]]
    assert crossings([bowtie]) == 1
    assert crossings([square, square + 0.5]) == 2
    assert crossings([square, square + 1.5]) == 0 == crossings([square])


def test_a_step_whose_faces_would_cross_cuts_the_plate_there(tmp_path):
    """Every try of a step fails because two faces of the plate would cross (within a
    relocation): the plate is cut there, with a warning, and the step goes on; where one
    of the two is the interface, the interface segment is released instead (the outline
    kept whole) and the step goes on."""
    from skfem_nem.evolution import StepTooLong
    cfg = PlateConfig(nodes=300, end_time=6.0, max_dt=2.0, output_interval=6.0)
    sim = SinkingPlate(cfg, tmp_path)
    lm = sim.lm
    seg = lm.triangulation.segments
    faces = [seg[r].tolist() for r in facing(lm, sim.outline, cfg.plate_x + 1e-3, cfg.plate_z)]
    real, calls = lm.advance, []

    def crossing(velocity, dt, **kw):
        calls.append(dt)
        if len(calls) <= 5:
            raise StepTooLong("segments would cross: reduce dt", crossing=faces)
        return real(velocity, dt, **kw)

    lm.advance = crossing
    with pytest.warns(RuntimeWarning, match="the plate cut there"):
        row = sim.step(2.0)
    assert calls == [2.0, 1.0, 0.5, 0.25, 0.125, 0.125] and row["dt"] == 0.125
    assert len(sim.outlines.loops) == 2 and row["pinches"] == 1 and row["plate_pieces"] == 2
    tri = lm.triangulation
    iface = tri.segments[tri.segment_source >= sim.outline_segments][0].tolist()
    calls.clear()

    def interface(velocity, dt, **kw):
        calls.append(dt)
        if len(calls) <= 5:
            raise StepTooLong("segments would cross: reduce dt", crossing=[faces[0], iface])
        return real(velocity, dt, **kw)

    lm.advance = interface
    with pytest.warns(RuntimeWarning, match="interface released"):
        row = sim.step(2.0)
    assert len(calls) == 6 and row["segments_released"] >= 1 and row["pinches"] == 1
    tri = lm.triangulation
    assert not (tri.segment_rows([iface]) >= 0).any()      # no longer a segment
    for loop in sim.outlines.loops:                          # the outline is whole
        assert (tri.segment_rows(np.c_[loop, np.roll(loop, -1)]) >= 0).all()


def test_a_closing_interface_film_releases_the_interface(tmp_path):
    """Two parts of the layer interface found closing within any step (a film of fluid
    pinched out between them, as where the interface folds onto itself against the bottom
    wall): the next step releases both segments instead of stopping, also after a restart
    from the checkpoint a stopped run wrote; counted in that step's row. The outline and
    the interface closing: only the interface's segment goes."""
    cfg = PlateConfig(nodes=300, end_time=4.0, max_dt=2.0, output_interval=100.0,
                      checkpoint_every=100)
    sim = SinkingPlate(cfg, tmp_path)
    tri = sim.lm.triangulation
    rows = np.flatnonzero(tri.segment_source >= sim.outline_segments)[[5, 40]]
    pair = tri.segments[rows].tolist()
    sim._closing = ClosingFilm(int(rows[0]), int(rows[1]), False, 1e-13, "two parts close")
    sim.checkpoint()
    sim = SinkingPlate.restart(tmp_path)
    tri, n0 = sim.lm.triangulation, sim.lm.triangulation.segments.shape[0]
    row = sim.step(2.0)
    tri = sim.lm.triangulation
    assert row["segments_released"] == 2 and tri.segments.shape[0] == n0 - 2
    assert not (tri.segment_rows(pair) >= 0).any() and sim._closing is None
    check_constrained(sim.lm)
    outline = np.flatnonzero(tri.segment_source < sim.outline_segments)[0]
    inner = np.flatnonzero(tri.segment_source >= sim.outline_segments)[0]
    pair = tri.segments[[outline, inner]].tolist()
    sim._closing = ClosingFilm(int(outline), int(inner), False, 1e-13, "outline, interface")
    row = sim.step(2.0)
    tri = sim.lm.triangulation
    assert row["segments_released"] >= 1
    assert tri.segment_rows(pair).tolist()[0] >= 0 and tri.segment_rows(pair).tolist()[1] < 0


def test_an_interface_film_is_released_whole():
    """A hairpin of interface whose arms are 0.01 apart over most of their length (less
    than a quarter of the spacing 0.1) next to a straight interface line far away: one
    closing pair releases every facing segment of the arms at once, not those near the
    bend (neighbours along the line) nor the far line; rows that are all the outline's
    release nothing. The mesh stays constrained Delaunay."""
    from skfem_nem.apps.plate_films import release_interface_film
    from skfem_nem.geometry.polylines import close_segment_pairs
    xs = np.linspace(0.2, 0.8, 13)
    arms = np.r_[np.c_[xs, np.full(13, 0.5)], np.c_[xs[::-1], np.full(13, 0.51)]]
    line = np.c_[xs, np.full(13, 0.2)]
    p = square_nodes(300, 16, 3, jitter=0.3, margin=0.01)
    d, _ = cKDTree(np.r_[arms, line]).query(p)
    p = p[(d > 0.03) | (np.arange(p.shape[0]) < 64)]
    k0 = p.shape[0]
    hairpin, pl = k0 + np.arange(26), k0 + 26 + np.arange(13)
    segs = np.r_[np.c_[hairpin[:-1], hairpin[1:]], np.c_[pl[:-1], pl[1:]]]
    lm = LagrangianMesh(np.r_[p, arms, line], segments=segs)
    tri = lm.triangulation
    face = pair_rows(lm, [(hairpin[5], hairpin[6]), (hairpin[19], hairpin[20])])
    assert release_interface_film(lm, face, tri.segments.shape[0], 0.1, 0.5) == 0
    n = release_interface_film(lm, face, 0, 0.1, 0.5)
    assert 10 < n < 24 and tri.segments.shape[0] == 37 - n
    i, _, _ = close_segment_pairs(lm.nodes, tri.segments, 0.025, 4)
    assert i.size == 0                                # no film left
    assert (tri.segment_rows(np.c_[pl[:-1], pl[1:]].tolist()) >= 0).all()
    check_constrained(lm)
