"""The sinking-plate application: a short coarse run, outputs, restart, bad configuration."""
import json
import warnings
from pathlib import Path

import meshio
import numpy as np
import pytest

from skfem_nem.apps.cli import main
from skfem_nem.apps.output import read_csv_columns
from skfem_nem.apps.sinking_plate import (PlateConfig, SinkingPlate, StepStalled, initial_nodes,
                                         load_config)
from skfem_nem.evolution import LagrangianMesh, StepTooLong

SMALL = dict(nodes=500, end_time=24.0, max_dt=4.0, output_interval=8.0, checkpoint_every=2,
             segments=True)


@pytest.fixture(scope="module")
def coarse_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("plate")
    sim = SinkingPlate(PlateConfig(**SMALL), out)
    area0, _ = sim.plate_area_centroid()
    sim.run(progress=False)
    sim.figures()
    return sim, out, area0


def test_coarse_run_physics(coarse_run):
    sim, out, area0 = coarse_run
    d = read_csv_columns(out / "diagnostics.csv")
    assert d["time"][-1] == pytest.approx(SMALL["end_time"])
    # plate and fluid areas conserved (incompressible flow, Lagrangian outline)
    assert np.abs(d["plate_area"] / area0 - 1).max() < 0.01
    box = sim.cfg.width * sim.cfg.height
    assert np.abs(d["fluid_area"] / (box - area0) - 1).max() < 0.01
    # the plate sinks, monotonically
    depth = d["plate_depth"]
    assert np.all(np.diff(depth) > 0)
    assert depth[-1] > depth[0]
    # the mesh stays a valid Delaunay triangulation at every step, never regridded
    assert d["inverted_triangles"].max() == 0 and d["non_delaunay_edges"].max() == 0
    assert sim.lm.triangulation.is_delaunay()
    assert d["min_angle"].min() > 0
    assert d["flips"].sum() > 0
    # the outline polygon stays simple
    assert d["outline_crossings"].max() == 0
    # the plate stresses up to the yield stress and no further
    assert d["max_plate_stress"].max() <= sim.cfg.yield_stress * (1 + 1e-9)
    assert d["max_plate_stress"].max() > 0.5 * sim.cfg.yield_stress


def test_outline_and_interface_are_segments(coarse_run):
    """With segments the plate outline and the layer interface are edges of the mesh at
    every step: no triangle straddles either, and nodes injected on the outline's
    stretched segments take their places in the plate polygon."""
    sim, out, _ = coarse_run
    lm, c = sim.lm, sim.cfg
    keys = lm.triangulation.segment_keys
    o = sim.outline
    pairs = np.sort(np.c_[o, np.roll(o, -1)], axis=1)
    assert np.isin((pairs[:, 0] << 32) | pairs[:, 1], keys).all()
    assert lm.triangulation.missing_segments().size == 0
    z0 = lm.node_fields["z0"][lm.triangles]           # initial heights of the vertices
    above, below = (z0 >= c.interface_z).all(1), (z0 <= c.interface_z).all(1)
    assert (above | below).all()
    interface = np.flatnonzero(lm.node_fields["z0"] == c.interface_z)
    assert interface.size > 100 and np.isin(lm.triangulation.segments, interface).any()
    d = read_csv_columns(out / "diagnostics.csv")
    assert np.all(np.diff(d["outline_nodes"]) >= 0)
    _, o0, i0 = initial_nodes(c)
    assert d["outline_nodes"][-1] == len(o)
    # every split put one node on the outline or on the interface
    assert len(o) - len(o0) + len(interface) - len(i0) == d["segments_split"].sum()


def test_outputs(coarse_run):
    sim, out, _ = coarse_run
    text = (out / "plate.pvd").read_text()
    files = [ln.split('file="')[1].split('"')[0] for ln in text.splitlines() if "file=" in ln]
    assert len(files) == 5  # t = 0, 1 (the early snapshot), 8, 16, 24
    m = meshio.read(out / files[-1])
    for k in ("velocity", "pressure", "viscosity", "density", "material", "initial_depth"):
        assert k in m.point_data, k
    for k in ("stress_invariant", "plastic_strain"):
        assert k in m.cell_data, k
    assert m.points.shape[0] == sim.lm.nodes.shape[0]
    cols = read_csv_columns(out / "diagnostics.csv")
    for k in ("plate_depth", "plate_area", "fluid_area", "max_plastic_strain", "flips",
              "injected", "min_angle", "solver_iterations", "picard_iterations",
              "factorisations"):
        assert k in cols, k


def test_a_step_lets_its_spaces_go_before_the_mesh_moves(tmp_path, monkeypatch):
    """The bases, the system and the cache of a step's solve are let go before its nodes
    move and before the next step builds its own (the solution holds its spaces: at
    357,024 nodes on one rank 1,014 MB); the step keeps the solve's arrays, which the
    snapshot writes."""
    import weakref

    import skfem_nem.apps.sinking_plate as app
    kept, seen = {}, []
    build, solve, advance = app.stokes_spaces, app.vep_step, LagrangianMesh.advance

    def gone():
        return all(r() is None for r in kept.values())

    def spy_build(mesh, *a, **kw):
        seen.append(("build", gone()))
        return build(mesh, *a, **kw)

    def spy_solve(spaces, *a, **kw):
        out = solve(spaces, *a, **kw)
        kept.update(spaces=weakref.ref(spaces), solution=weakref.ref(out.solution))
        return out

    def spy_advance(lm, *a, **kw):
        seen.append(("advance", gone()))
        return advance(lm, *a, **kw)

    monkeypatch.setattr(app, "stokes_spaces", spy_build)
    monkeypatch.setattr(app, "vep_step", spy_solve)
    monkeypatch.setattr(LagrangianMesh, "advance", spy_advance)
    sim = SinkingPlate(PlateConfig(**{**SMALL, "inject": 0}), tmp_path)
    sim.run(progress=False, max_steps=1)        # to t = 1, the early snapshot
    last = sim.solution
    n = sim.lm.nodes.shape[0]
    assert all(isinstance(a, np.ndarray) for a in (last.u, last.p, last.velocity,
                                                    last.pressure))
    assert last.velocity.shape == (n, 2) and last.pressure.shape == (n,)
    assert last.cells == sim.lm.triangles.shape[0] and last.ranks == 1
    m = meshio.read(tmp_path / "plate_00001.vtu")
    np.testing.assert_array_equal(m.point_data["velocity"][:, :2], last.velocity)
    np.testing.assert_array_equal(m.point_data["pressure"], last.pressure)
    sim.step(1.0)
    assert seen == [("build", True), ("advance", True), ("build", True), ("advance", True)]


def drawn_figures(sim, monkeypatch):
    """sim.figures() again, keeping each Figure it saves (by file name)."""
    from matplotlib.figure import Figure
    saved, savefig = {}, Figure.savefig

    def keep(fig, fname, *args, **kwargs):
        saved[Path(fname).name] = fig
        return savefig(fig, fname, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", keep)
    paths = sim.figures()
    assert sorted(p.name for p in paths) == sorted(saved)
    return saved


def test_figures_draw_the_run(coarse_run, monkeypatch):
    sim, out, _ = coarse_run
    figs = drawn_figures(sim, monkeypatch)
    assert {"fig6.png", "plate_strain.png", "diagnostics.png"} <= set(figs)
    # Fig. 6: the mesh coloured by initial depth at t = 1 and at the end, the
    # whole box in view, the plate outline drawn on the last panel
    early, end = [a for a in figs["fig6.png"].axes if a.get_title().startswith("t =")]
    assert early.get_title().startswith("t = 1:")
    assert end.get_title().startswith(f"t = {sim.lm.time:.4g}:")
    (tp,) = [c for c in end.collections if c.get_array() is not None]
    np.testing.assert_allclose(tp.get_array(), sim.cfg.height - sim.lm.node_fields["z0"])
    for a in (early, end):
        assert a.get_xlim() == (0, sim.cfg.width) and a.get_ylim() == (0, sim.cfg.height)
    outline = end.lines[-1].get_xydata()
    np.testing.assert_allclose(outline[:-1], sim.plate_polygon)
    np.testing.assert_allclose(outline[-1], outline[0])
    # the diagnostics: the columns of diagnostics.csv against time
    d = read_csv_columns(out / "diagnostics.csv")
    axes = figs["diagnostics.png"].axes
    assert [a.get_title() for a in axes][:2] == ["plate centroid depth", "plate area"]
    for a, k in zip(axes, ("plate_depth", "plate_area", "max_plastic_strain", "flips", "nodes",
                           "min_angle")):
        np.testing.assert_allclose(a.lines[0].get_xdata(), d["time"])
        np.testing.assert_allclose(a.lines[0].get_ydata(), d[k])


def test_restart_continues_identically(tmp_path):
    cfg = PlateConfig(**{**SMALL, "end_time": 16.0, "checkpoint_every": 1})
    a = SinkingPlate(cfg, tmp_path / "a")
    a.run(progress=False)
    b = SinkingPlate(cfg, tmp_path / "b")
    b.run(progress=False, max_steps=2)
    assert b.lm.time < cfg.end_time
    c = SinkingPlate.restart(tmp_path / "b")
    c.run(progress=False)
    assert np.array_equal(a.lm.nodes, c.lm.nodes)
    assert np.array_equal(a.lm.triangles, c.lm.triangles)
    assert np.array_equal(a.lm.ip_fields["stress"], c.lm.ip_fields["stress"])
    da = read_csv_columns(tmp_path / "a" / "diagnostics.csv")
    dc = read_csv_columns(tmp_path / "b" / "diagnostics.csv")
    assert np.array_equal(da["plate_depth"], dc["plate_depth"])


def user_error(capsys, argv):
    """Run the command line expecting a user error: exit status 2, one line."""
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and err.startswith("skfem-nem: "), err
    return err


def test_bad_configuration(tmp_path, capsys):
    with pytest.raises(ValueError, match="plate_x"):
        load_config(overrides={"plate_x": 0.3})
    with pytest.raises(ValueError, match="eta_lower"):
        load_config(overrides={"eta_lower": -1.0})
    with pytest.raises(ValueError, match="yield_stress"):
        load_config(overrides={"yield_stress": float("nan")})
    p = tmp_path / "c.toml"
    p.write_text("[sinking-plate]\nnodes = 800\nplate_viscosty = 3.0\n")
    with pytest.raises(ValueError, match="plate_viscosty"):
        load_config(str(p))
    p.write_text("nodes = 800\nend_time = 50\n")
    cfg = load_config(str(p))
    assert cfg.nodes == 800 and cfg.end_time == 50.0
    # wrong types, NaN, keys beside the table, broken TOML: named, never a traceback
    for text, word in (('plate_x = "middle"', "plate_x must be float"),
                       ("plate_x = nan", "plate_x must be a number"),
                       ("nodes = 1500.0", "nodes must be int"),
                       ('remap = 3', "remap must be str"),
                       ("nodes = 800\n[sinking-plate]\nseed = 1", "'nodes' stands outside"),
                       ("nodes = = 3", "not valid TOML")):
        p.write_text(text + "\n")
        with pytest.raises(ValueError, match=word):
            load_config(str(p))
        assert word in user_error(capsys, ["sinking-plate", "--config", str(p), "-o",
                                           str(tmp_path / "y"), "--quiet"])
    assert "plate_z" in user_error(capsys, ["sinking-plate", "-o", str(tmp_path / "x"),
                                            "--plate-z", "0.99", "--quiet"])
    assert "seed must be a non-negative integer, got -1" in user_error(
        capsys, ["sinking-plate", "-o", str(tmp_path / "x"), "--seed", "-1", "--quiet"])
    assert "--max-steps must be a non-negative integer, got -3" in user_error(
        capsys, ["sinking-plate", "-o", str(tmp_path / "x"), "--max-steps", "-3", "--quiet"])
    assert not (tmp_path / "x").exists()   # rejected before anything runs
    assert not (tmp_path / "y").exists()
    assert "no checkpoint" in user_error(capsys, ["sinking-plate", "-o", str(tmp_path / "none"),
                                                  "--restart", "--quiet"])


def test_restart_keeps_the_stored_configuration(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["sinking-plate", "-o", str(out), "--nodes", "400", "--end-time", "3",
                 "--max-dt", "3", "--output-interval", "3", "--eta-lower", "3",
                 "--quiet"]) == 0
    capsys.readouterr()
    # the physics of the stored run cannot change on restart
    err = user_error(capsys, ["sinking-plate", "-o", str(out), "--restart", "--eta-lower", "5",
                              "--quiet"])
    assert "--eta-lower cannot change" in err
    assert "--config cannot be combined" in user_error(
        capsys, ["sinking-plate", "-o", str(out), "--restart", "--config", "x.toml"])
    # its end time can: the run continues with eta_lower = 3 and its own nodes
    assert main(["sinking-plate", "-o", str(out), "--restart", "--end-time", "6",
                 "--quiet"]) == 0
    said = capsys.readouterr().out
    assert "restart: end_time = 6 (was 3)" in said
    cfg = json.loads((out / "checkpoint.json").read_text())["config"]
    assert cfg["eta_lower"] == 3.0 and cfg["nodes"] == 400 and cfg["end_time"] == 6.0
    assert SinkingPlate.restart(out).lm.time == pytest.approx(6.0)


def test_command_line_short_run(tmp_path):
    out = tmp_path / "cli"
    rc = main(["sinking-plate", "-o", str(out), "--nodes", "400", "--end-time", "6",
               "--max-dt", "3", "--output-interval", "3", "--quiet"])
    assert rc == 0
    meta = json.loads((out / "checkpoint.json").read_text())
    assert meta["config"]["nodes"] == 400
    assert (out / "plate.pvd").exists() and (out / "fig6.png").exists()
    # the default: outline and interface as segments, merging, the area kept
    cfg = meta["config"]
    assert cfg["segments"] is True and cfg["merge"] is True and cfg["keep_area"] is True
    # each step's seconds split: the parts within the Picard loop within the step
    d = read_csv_columns(out / "diagnostics.csv")
    parts = d["basis_seconds"] + d["assembly_seconds"] + d["solver_seconds"]
    assert (d["assembly_seconds"] > 0).all() and (d["solver_seconds"] > 0).all()
    assert (parts <= d["solve_seconds"]).all()
    assert (d["solve_seconds"] + d["evolution_seconds"] <= d["step_seconds"]).all()
    sim = SinkingPlate.restart(out)
    assert sim.lm.triangulation.segment_keys.size > 0
    assert np.count_nonzero(sim.lm.node_fields["z0"] == sim.cfg.interface_z) > 100


def test_command_line_without_segments(tmp_path):
    out = tmp_path / "plain"
    assert main(["sinking-plate", "-o", str(out), "--nodes", "300", "--end-time", "2",
                 "--max-dt", "2", "--quiet", "--no-segments", "--no-merge"]) == 0
    meta = json.loads((out / "checkpoint.json").read_text())
    assert meta["config"]["segments"] is False and meta["config"]["merge"] is False
    sim = SinkingPlate.restart(out)
    assert sim.lm.triangulation.segment_keys.size == 0
    # no line of nodes on the interface
    assert not np.any(sim.lm.node_fields["z0"] == sim.cfg.interface_z)


def test_command_line_with_segments_and_merging(tmp_path):
    out = tmp_path / "merge"
    assert main(["sinking-plate", "-o", str(out), "--nodes", "300", "--end-time", "6",
                 "--max-dt", "2", "--quiet", "--segments", "--merge"]) == 0
    meta = json.loads((out / "checkpoint.json").read_text())
    assert meta["config"]["merge"] is True
    d = read_csv_columns(out / "diagnostics.csv")
    sim = SinkingPlate.restart(out)
    n0 = initial_nodes(sim.cfg)[0].shape[0]
    # every node removed or merged is counted
    assert d["nodes"][-1] == n0 + d["injected"].sum() - d["removed"].sum() - d["merged"].sum()
    assert d["removed"].sum() > 0
    assert sim.lm.nodes.shape[0] == d["nodes"][-1]
    # the outline is still a closed chain of segments
    o = sim.outline
    keys = (np.minimum(o, np.roll(o, -1)) << 32) | np.maximum(o, np.roll(o, -1))
    assert np.isin(keys, sim.lm.triangulation.segment_keys).all()
    assert d["outline_crossings"].max() == 0


def test_lagrangian_fem_inverts_where_nem_does_not(tmp_path):
    import sys
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "examples"))
    import ex10_lagrangian_fem_fails as ex10

    cfg = PlateConfig(nodes=500, max_dt=4.0, end_time=200.0, output_interval=50.0)
    fem = ex10.run_fem(cfg, out=tmp_path / "fem", verbose=False)
    assert fem["inverted_at"] is not None and fem["inverted_at"] < cfg.end_time
    nem_cfg = PlateConfig(**{**cfg.__dict__, "end_time": float(fem["inverted_at"])})
    sim = SinkingPlate(nem_cfg, tmp_path / "nem")
    sim.run(progress=False)
    assert sim.lm.time == pytest.approx(fem["inverted_at"])
    assert sim.lm.triangulation.is_delaunay() and sim.lm.min_angle() > 0
    assert (sim.lm.triangulation.orientation() > 0).all()
    fig = ex10.visualize(fem, tmp_path / "nem", path=tmp_path / "ex10.png")
    assert (tmp_path / "ex10.png").exists()
    angles, mesh = fig.axes
    # FEM and NEM minimum angles over time, the FEM inversion marked
    fem_line, nem_line, inversion = angles.lines
    np.testing.assert_allclose(fem_line.get_ydata(), fem["min_angle"])
    assert nem_line.get_xdata()[-1] == pytest.approx(fem["inverted_at"])
    assert min(nem_line.get_ydata()) > 0 and min(fem_line.get_ydata()) < min(nem_line.get_ydata())
    np.testing.assert_allclose(inversion.get_xdata(), fem["inverted_at"])
    # the last FEM mesh: its nodes, inside the box
    P, T = fem["mesh"]
    lim = mesh.dataLim
    assert (lim.x0, lim.x1) == pytest.approx((P[:, 0].min(), P[:, 0].max()))
    assert f"t = {fem['time'][-1]:.4g}" in mesh.get_title()


def test_step_retried_with_half_dt_and_fields_restored(tmp_path):
    sim = SinkingPlate(PlateConfig(**SMALL), tmp_path)
    sim.step(2.0)
    before = {k: v.copy() for k, v in sim.lm.ip_fields.items()}
    nodes = sim.lm.nodes.copy()
    real = sim.lm.advance
    calls = []

    def flaky(velocity, dt, **kw):
        calls.append(dt)
        if len(calls) == 1:
            raise StepTooLong("triangle 0 inverts and none of its vertices can be relocated: "
                              "reduce dt")
        return real(velocity, dt, **kw)

    sim.lm.advance = flaky
    with warnings.catch_warnings():
        warnings.simplefilter("error")             # counted in the row, no warning
        row = sim.step(2.0)
    assert calls == [2.0, 1.0] and row["retries"] == 1 and row["dt"] == 1.0
    assert sim.lm.time == pytest.approx(3.0)
    # the failed attempt left nothing behind: the retry started from the saved state
    sim2 = SinkingPlate(PlateConfig(**SMALL), tmp_path / "b")
    sim2.step(2.0)
    assert np.array_equal(sim2.lm.nodes, nodes)
    for k, v in before.items():
        assert np.array_equal(sim2.lm.ip_fields[k], v)
    sim2.step(1.0)
    assert np.array_equal(sim2.lm.nodes, sim.lm.nodes)
    sim.lm.advance = real

    def broken(velocity, dt, **kw):
        raise ValueError("velocity returned non-finite values at 1 node(s)")

    sim.lm.advance = broken
    with pytest.raises(ValueError, match="non-finite"):
        sim.step(1.0)


def test_stopped_run_keeps_its_outputs_and_says_why(tmp_path, capsys, monkeypatch):
    out = tmp_path / "run"
    real = SinkingPlate._step
    calls = {"n": 0}

    def failing(self, dt):
        calls["n"] += 1
        if calls["n"] > 2:
            raise RuntimeError("Schur CG did not converge in 5 iterations\nsecond line")
        return real(self, dt)

    monkeypatch.setattr(SinkingPlate, "_step", failing)
    rc = main(["sinking-plate", "-o", str(out), "--nodes", "400", "--end-time", "12",
               "--max-dt", "3", "--output-interval", "3", "--quiet"])
    assert rc == 1
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0
    stopped = SinkingPlate.restart(out).lm         # the checkpoint: the last completed step
    assert stopped.step == 2
    assert f"stopped at t = {stopped.time:g} (step 2): Schur CG did not converge" in err
    assert "--restart" in err
    assert (out / "fig6.png").exists() and (out / "diagnostics.png").exists()
    monkeypatch.undo()
    # the run continues from there, with a smaller time step allowed on restart
    assert main(["sinking-plate", "-o", str(out), "--restart", "--max-dt", "2",
                 "--quiet"]) == 0
    assert SinkingPlate.restart(out).lm.time == pytest.approx(12.0)


def test_run_warnings_are_one_line_each(tmp_path, capsys, monkeypatch):
    import warnings
    real = SinkingPlate._step

    def warning(self, dt):
        warnings.warn(f"step at t = {self.lm.time:g}: a test warning", RuntimeWarning)
        return real(self, dt)

    monkeypatch.setattr(SinkingPlate, "_step", warning)
    assert main(["sinking-plate", "-o", str(tmp_path / "w"), "--nodes", "300", "--end-time",
                 "2", "--quiet"]) == 0
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert err and all(ln.startswith("skfem-nem: RuntimeWarning: step at t = ") for ln in err)
    assert warnings.showwarning.__module__ == "warnings"      # restored after the run


def test_keep_area_holds_the_plate_area(tmp_path):
    """With ``keep_area`` (the default) each step's outline flux gives back the area the
    earlier steps lost to the time-step error, so the drift does not add up; off, the
    flux is zero and the area drifts step by step. The sinking is the same."""
    runs = {}
    for keep in (True, False):
        cfg = PlateConfig(nodes=500, end_time=60.0, max_dt=5.0, output_interval=100.0,
                          checkpoint_every=100, segments=True, merge=True, keep_area=keep)
        sim = SinkingPlate(cfg, tmp_path / str(keep))
        area0, _ = sim.plate_area_centroid()
        sim.run(progress=False)
        d = read_csv_columns(sim.out / "diagnostics.csv")
        runs[keep] = (np.abs(d["plate_area"] / area0 - 1), d["plate_depth"][-1])
    held, drifting = runs[True][0], runs[False][0]
    assert drifting[-1] > 2e-5                    # measured 5.2e-5 after 13 steps
    assert held.max() < 0.3 * drifting.max()      # measured 8.1e-6
    assert held[-1] < 0.1 * drifting[-1]          # measured 8.4e-7
    assert runs[True][1] == pytest.approx(runs[False][1], rel=1e-4)


def test_interface_segments_under_the_plate_are_released(tmp_path):
    """A plate started just above the layer interface (a film of 0.005, below a quarter of
    the outline's spacing 0.025): the interface segments under it are released at the
    first step (counted in the CSV), those farther away stay segments, and the outline
    stays a closed chain of segments."""
    from skfem_nem.apps.sinking_plate import FILM_FRACTION
    from skfem_nem.geometry.polylines import segment_distances
    cfg = PlateConfig(nodes=300, plate_z=0.805, end_time=4.0, max_dt=2.0,
                      output_interval=100.0, checkpoint_every=100)
    sim = SinkingPlate(cfg, tmp_path)
    sim.run(progress=False)
    d = read_csv_columns(tmp_path / "diagnostics.csv")
    assert d["segments_released"][0] > 0
    tri, P, o = sim.lm.triangulation, sim.lm.nodes, sim.outline
    iface = tri.segments[tri.segment_source >= sim.outline_segments]
    gap = segment_distances(P[iface[:, 0]], P[iface[:, 1]], P[o], P[np.roll(o, -1)])
    h = FILM_FRACTION * cfg.outline_spacing * cfg.plate_thickness
    assert gap.min() >= h and iface.shape[0] > 100
    keys = (np.minimum(o, np.roll(o, -1)) << 32) | np.maximum(o, np.roll(o, -1))
    assert np.isin(keys, tri.segment_keys).all()


def test_segment_distances():
    from skfem_nem.geometry.polylines import segment_distances
    a, b = np.array([[0, 0.], [0, 0], [0.5, -1]]), np.array([[1, 0.], [1, 1], [0.5, 0.5]])
    c, d = np.array([[0, 1.], [2, 0]]), np.array([[1, 1.], [3, 0]])
    # apart (1), touching at an end (0), and crossing nothing but 0.5 below the first
    np.testing.assert_allclose(segment_distances(a, b, c, d), [1.0, 0.0, 0.5])
    cross = segment_distances(np.array([[0.5, 0.5]]), np.array([[0.5, 1.5]]), c, d)
    assert cross[0] == 0.0


def test_time_step_anticipates_a_wall(tmp_path):
    """A node moving towards a wall moves at most WALL_FRACTION of its distance to it
    per step; moving away, or along the wall, only its spacing limits the step."""
    from skfem_nem.apps.sinking_plate import WALL_FRACTION
    sim = SinkingPlate(PlateConfig(nodes=300, max_dt=1e9, cfl=1.0), tmp_path)
    P = sim.lm.nodes
    sim.lm.node_map = np.arange(P.shape[0])
    inner = np.flatnonzero((P[:, 1] > 0.01) & (P[:, 1] < 0.99) & (P[:, 0] > 0.01)
                           & (P[:, 0] < 9.99))
    k = inner[np.argmin(P[inner, 1])]                  # the interior node nearest the bottom
    v = np.zeros_like(P)
    v[k] = [0.0, -1e-3]
    away = sim._stable_dt(-v)                          # the spacing's limit only
    assert WALL_FRACTION * P[k, 1] / 1e-3 < away
    assert sim._stable_dt(v) == pytest.approx(WALL_FRACTION * P[k, 1] / 1e-3, rel=1e-12)
    v[k] = [1e-3, 0.0]
    assert sim._stable_dt(v) == pytest.approx(away, rel=1e-12)


def test_time_step_anticipates_a_closing_film(tmp_path):
    """The interface pushed towards the plate's outline: the step keeps at least
    1 - WALL_FRACTION of the film (and not much more: the step is halved only as often as
    needed); pushed away, or moving with the plate, the film does not limit the step."""
    from skfem_nem.apps.sinking_plate import WALL_FRACTION
    from skfem_nem.geometry.polylines import segment_distances
    sim = SinkingPlate(PlateConfig(nodes=300, plate_z=0.82, max_dt=1e9, cfl=1.0), tmp_path)
    P, tri, o = sim.lm.nodes, sim.lm.triangulation, sim.outline
    sim.lm.node_map = np.arange(P.shape[0])
    iface = tri.segments[tri.segment_source >= sim.outline_segments]

    def film(Q):
        return segment_distances(Q[iface[:, 0]], Q[iface[:, 1]], Q[o], Q[np.roll(o, -1)]).min()

    v = np.zeros_like(P)
    v[np.unique(iface), 1] = 1e-3                       # the interface moves up, to the plate
    closing, away = sim._stable_dt(v), sim._stable_dt(-v)
    assert closing < 0.5 * away
    assert film(P + closing * v) >= (1 - WALL_FRACTION) * film(P)
    assert film(P + 2 * closing * v) < (1 - WALL_FRACTION) * film(P)
    v[:, 1] = 1e-3                                      # everything up: the film stays
    v[np.isin(np.arange(P.shape[0]), np.unique(iface), invert=True) & (P[:, 1] == 1.0)] = 0
    assert sim._stable_dt(v) > closing


def test_close_segment_pairs_finds_facing_lines_not_neighbours_along_one():
    """A hairpin polyline (arms 0.1 apart, spacing 0.05) and a line 0.03 above it: the
    facing pairs are found with their gaps, never two segments a few apart along one line."""
    from skfem_nem.geometry.polylines import close_segment_pairs
    x = np.r_[np.linspace(0, 1, 21), np.linspace(1, 0, 21), np.linspace(0, 1, 11)]
    P = np.c_[x, np.r_[np.zeros(21), np.full(21, 0.1), np.full(11, 0.13)]]
    S = np.r_[np.c_[np.arange(41), np.arange(1, 42)], np.c_[42 + np.arange(10), 43 + np.arange(10)]]
    i, j, gap = close_segment_pairs(P, S, 0.11, apart=4)
    arm = lambda r: np.where(r < 20, 0, np.where(r < 21, 1, np.where(r < 41, 2, 3)))  # noqa: E731
    pair = {(int(a), int(b)) for a, b in zip(arm(i), arm(j))}
    assert pair == {(0, 2), (1, 3), (2, 3)}      # (the bend is 0.03 below the line too)
    assert gap[(arm(i) == 0) & (arm(j) == 2)].min() == pytest.approx(0.1)
    assert gap[(arm(i) == 2) & (arm(j) == 3)].min() == pytest.approx(0.03)
    assert gap.max() < 0.11
    # the segments near the hairpin's bend are within 4 of each other along the line
    assert not ((np.abs(i - j) <= 4) & (j < 41)).any()


def test_material_lines_rest_on_a_wall_instead_of_reaching_it(tmp_path):
    """Nodes of the outline or interface closer to a wall than a quarter of the outline
    spacing keep no velocity towards it; away from it, along it, farther off or off the
    lines, velocities are untouched."""
    from skfem_nem.apps.plate_time_step import FILM_FRACTION, hold_off_walls
    cfg = PlateConfig(nodes=300)
    sim = SinkingPlate(cfg, tmp_path)
    lm = sim.lm
    h = FILM_FRACTION * cfg.outline_spacing * cfg.plate_thickness
    line = np.flatnonzero(lm.segment_nodes() & ~lm.on_walls.any(axis=1))
    a, b = line[:2]
    off = np.flatnonzero(~lm.segment_nodes() & ~lm.on_walls.any(axis=1))[0]
    x = np.array(lm.nodes)
    x[a], x[b], x[off] = [3.0, 0.5 * h], [3.5, 2 * h], [4.0, 0.5 * h]
    lm.triangulation.move_nodes(x)   # (a probe of positions only, no flips needed here)
    v = np.zeros_like(x)
    v[[a, b, off]] = [[0.3, -1.0], [0.0, -1.0], [0.0, -1.0]]
    w = hold_off_walls(lm, v, cfg)
    np.testing.assert_array_equal(w[a], [0.3, 0.0])      # towards the bottom: held off
    np.testing.assert_array_equal(w[[b, off]], v[[b, off]])
    v[a] = [0.3, 1.0]                                    # away from it: free
    np.testing.assert_array_equal(hold_off_walls(lm, v, cfg)[a], v[a])


def test_step_retried_when_the_plastic_iterations_stall(tmp_path, monkeypatch):
    """Picard iterations that do not converge make the step retry with half dt, like a
    mesh that cannot follow; a solver failure of another kind stops at once."""
    import skfem_nem.apps.sinking_plate as sp
    sim = SinkingPlate(PlateConfig(**SMALL), tmp_path)
    real, calls = sp.vep_step, []

    def stalling(*args, **kw):
        calls.append(args[3])
        if len(calls) == 1:
            raise sp.PicardNotConverged("visco-elasto-plastic Picard iterations did not "
                                        "converge: 100 iterations")
        return real(*args, **kw)

    monkeypatch.setattr(sp, "vep_step", stalling)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        row = sim.step(2.0)
    assert calls == [2.0, 1.0] and row["retries"] == 1 and sim.lm.time == pytest.approx(1.0)
    assert sim.dt_next <= 2.0                            # grows back from the retried step

    def singular(*args, **kw):
        raise RuntimeError("the viscous block is singular")

    monkeypatch.setattr(sp, "vep_step", singular)
    with pytest.raises(RuntimeError, match="singular"):
        sim.step(1.0)


def test_step_retried_when_a_stokes_solve_does_not_converge(tmp_path, monkeypatch):
    """A Stokes solve stopped at its iteration limit (SolverNotConverged, raised by the
    solvers themselves) makes the step retry with half dt, the stress of the step's start
    restored: a shorter step lowers the visco-elastic contrast."""
    import skfem_nem.apps.sinking_plate as sp
    import skfem_nem.models.rheology as rh
    from skfem_nem.models.stokes_solvers import SolverNotConverged
    sim = SinkingPlate(PlateConfig(**SMALL), tmp_path)
    before = {k: v.copy() for k, v in sim.lm.ip_fields.items()}
    real, calls = rh.solve_stokes_bc, []

    def stalling(*args, **kw):
        calls.append(1)
        if len(calls) == 1:
            raise SolverNotConverged("pressure CG did not converge: 2000 iterations, "
                                     "relative residual 1.678e-06 > tol 1.0e-06")
        return real(*args, **kw)

    real_step = sp.vep_step
    dts = []

    def recording(*args, **kw):
        dts.append(args[3])
        for k, v in before.items():                   # the start's stress on every try
            np.testing.assert_array_equal(sim.lm.ip_fields[k], v)
        return real_step(*args, **kw)

    monkeypatch.setattr(rh, "solve_stokes_bc", stalling)
    monkeypatch.setattr(sp, "vep_step", recording)
    row = sim.step(2.0)
    assert dts == [2.0, 1.0] and row["retries"] == 1 and sim.lm.time == pytest.approx(1.0)


def test_an_unconverged_move_is_retried_down_to_min_dt_then_the_run_stops(tmp_path, capsys,
                                                                           monkeypatch):
    """A predictor-corrector that does not converge is never accepted: the step is retried
    with half the time step (no warning), the next step grows back from it; one that
    fails at every time step down to ``min_dt`` stops the run with one line naming the
    step, the time step reached and what failed, the mesh and fields as before the step,
    a checkpoint written (status 1 from the command line)."""
    from skfem_nem.apps import cli
    from skfem_nem.evolution import MoveNotConverged
    cfg = PlateConfig(**{**SMALL, "min_dt": 0.2})
    sim = SinkingPlate(cfg, tmp_path)
    sim.step(2.0)
    real = sim.lm.advance
    calls = []

    def slow(velocity, dt, **kw):
        calls.append(dt)
        if len(calls) <= 2:
            raise MoveNotConverged("step 2: the predictor-corrector did not converge in 20 "
                                   "iterations: reduce dt")
        return real(velocity, dt, **kw)

    sim.lm.advance = slow
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        row = sim.step(2.0)
    assert calls == [2.0, 1.0, 0.5] and row["retries"] == 2 and row["dt"] == 0.5
    assert row["predictor_converged"] == 1 and sim.dt_next <= 1.0
    # never converging: halved to 0.25, then below min_dt = 0.2 the run stops
    state = (sim.lm.nodes.copy(), {k: v.copy() for k, v in sim.lm.ip_fields.items()},
             sim.lm.time)
    calls.clear()

    def never(velocity, dt, **kw):
        calls.append(dt)
        raise MoveNotConverged("step 3: the predictor-corrector did not converge in 20 "
                               "iterations: reduce dt")

    sim.lm.advance = never
    with pytest.raises(StepStalled, match=r"step 3 at t = 2.5 fails at dt = 0.25 \(min_dt "
                                          r"0.2\): step 3: the predictor-corrector did not"):
        sim.step(2.0)
    assert calls == [2.0, 1.0, 0.5, 0.25]
    np.testing.assert_array_equal(sim.lm.nodes, state[0])
    for k, v in state[1].items():
        np.testing.assert_array_equal(sim.lm.ip_fields[k], v)
    assert sim.lm.time == state[2]
    # from the command line: one line, status 1, the checkpoint kept
    out = tmp_path / "cli"
    real_advance = LagrangianMesh.advance

    def never_after_two(self, velocity, dt, **kw):
        if self.step >= 2:
            raise MoveNotConverged("the predictor-corrector did not converge in 20 "
                                   "iterations: reduce dt")
        return real_advance(self, velocity, dt, **kw)

    monkeypatch.setattr(LagrangianMesh, "advance", never_after_two)
    code = cli.main(["sinking-plate", "-o", str(out), "--quiet", "--nodes", "300",
                     "--min-dt", "0.5", "--end-time", "20"])
    err = capsys.readouterr().err
    assert code == cli.STOPPED
    lines = [x for x in err.splitlines() if x.strip()]
    assert len(lines) == 1 and "stopped at t = " in lines[0] and "(min_dt 0.5)" in lines[0]
    assert lines[0].endswith("try --restart with a smaller --min-dt or --cfl, or a new run "
                             "with more --nodes")
    assert (out / "checkpoint.npz").exists()
    # a run with one retried step completes and says so once, at the end
    failed = []

    def once(self, velocity, dt, **kw):
        if self.step == 2 and not failed:
            failed.append(dt)
            raise MoveNotConverged("the predictor-corrector did not converge: reduce dt")
        return real_advance(self, velocity, dt, **kw)

    monkeypatch.setattr(LagrangianMesh, "advance", once)
    code = cli.main(["sinking-plate", "-o", str(tmp_path / "once"), "--quiet", "--nodes",
                     "300", "--end-time", "8"])
    captured = capsys.readouterr()
    assert code == 0 and failed and captured.err == ""
    assert "1 step(s) were retried with a shorter time step" in captured.out


def test_a_crossing_at_the_time_step_floor_goes_to_the_cut_not_to_a_stall(tmp_path):
    """Two material lines that would cross at every time step down to ``min_dt`` are
    handed back to :meth:`SinkingPlate.step` (which cuts the plate or releases the
    interface there), not reported as a stalled step: at a small time step the floor
    comes before the usual number of halvings."""
    sim = SinkingPlate(PlateConfig(**{**SMALL, "min_dt": 0.5}), tmp_path)
    calls = []
    pairs = ([1, 2], [3, 4])

    def crossing(velocity, dt, **kw):
        calls.append(dt)
        raise StepTooLong("segment [1, 2] would cross segment [3, 4]: reduce dt", pairs)

    sim.lm.advance = crossing
    with pytest.raises(StepTooLong) as info:
        sim._tries(1.5, 4)
    assert not isinstance(info.value, StepStalled) and info.value.crossing == pairs
    assert calls == [1.5, 0.75]
    calls.clear()

    def stalling(velocity, dt, **kw):
        calls.append(dt)
        raise StepTooLong("triangle 0 inverts and none of its vertices can be relocated")

    sim.lm.advance = stalling
    with pytest.raises(StepStalled, match="fails at dt = 0.75"):
        sim._tries(1.5, 4)
    assert calls == [1.5, 0.75]


def test_csv_log_keeps_rows_on_restart_and_widens_for_new_columns(tmp_path):
    """A restart keeps the rows up to its time; a row with columns the file lacks (a run
    restarted from an older version's output) widens the file instead of dropping them."""
    from skfem_nem.apps.output import CSVLog
    p = tmp_path / "d.csv"
    log = CSVLog(p)
    for t in (1.0, 2.0, 3.0):
        log.append({"time": t, "a": 10 * t})
    log = CSVLog(p, keep_until=2.0)
    log.append({"time": 3.5, "a": 35.0, "b": 7.0})
    d = read_csv_columns(p)
    np.testing.assert_array_equal(d["time"], [1.0, 2.0, 3.5])
    np.testing.assert_array_equal(d["a"], [10.0, 20.0, 35.0])
    assert np.isnan(d["b"][:2]).all() and d["b"][2] == 7.0
