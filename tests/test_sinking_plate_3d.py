"""The 3D sinking plate (``skfem-nem sinking-plate --dim 3``): a small elasto-plastic run end
to end, its outputs and figures, a restart with its stress history, failed steps that leave
the state as it was, the viscous plate, and the command line's one-line errors."""
import json

import numpy as np
import pytest

from skfem_nem.apps.cli import main

SMALL = ["--dim", "3", "--nodes", "500", "--density-length", "0.3", "--end-time", "60",
         "--max-dt", "30", "--output-interval", "30", "--quiet"]


@pytest.fixture(scope="module")
def run3d(tmp_path_factory):
    out = tmp_path_factory.mktemp("plate3d")
    assert main(["sinking-plate", *SMALL, "-o", str(out)]) == 0
    return out


def test_the_run_writes_its_outputs(run3d):
    import meshio

    from skfem_nem.apps.output import read_csv_columns
    pvd = (run3d / "plate.pvd").read_text()
    files = [f for f in ("plate_00000.vtu", "plate_00001.vtu", "plate_00002.vtu") if f in pvd]
    assert len(files) == 3 and 'timestep="60"' in pvd
    m = meshio.read(run3d / files[-1])
    (cells,) = m.cells
    n = m.points.shape[0]
    assert cells.type == "tetra" and cells.data.max() == n - 1
    assert m.point_data["velocity"].shape == (n, 3)
    assert m.point_data["pressure"].shape == (n,)
    assert set(np.unique(m.point_data["material"])) == {0.0, 1.0, 2.0}
    # the nodes moved; their initial heights travel with them
    first = meshio.read(run3d / files[0])
    np.testing.assert_array_equal(first.points[:, 2], m.point_data["initial_height"])
    assert np.abs(m.points - first.points).max() > 0
    d = read_csv_columns(run3d / "diagnostics.csv")
    assert d["time"][-1] == 60 and np.all(np.diff(d["time"]) > 0)
    # the plate sinks (its nodes' mean height falls), downwards velocity, volume kept
    assert np.all(np.diff(d["plate_depth"]) > 0) and np.all(d["plate_velocity"] < 0)
    assert np.abs(d["plate_volume_change"]).max() < 0.05
    assert np.all(d["solver_iterations"] > 0) and np.all(d["seconds"] > 0)
    # the tetrahedra are mended by flips, never rebuilt
    assert d["flips"].sum() > 0 and np.all(d["rebuilt"] == 0) and np.all(d["repair_seconds"] > 0)
    # elasto-plastic: Picard iterations, yield at the yield stress and no more, plastic
    # strain; no step longer than its own velocity allows
    assert np.all(d["picard_iterations"] > 1) and d["yielded_points"].max() > 0
    assert np.all(d["max_plate_stress"] <= 0.12 * (1 + 1e-9))
    assert d["max_plate_stress"].max() > 0.12 * (1 - 1e-9)
    assert d["max_plastic_strain"][-1] > 0
    assert np.all(d["dt"] <= 1.25 * d["stable_dt"] * (1 + 1e-12))
    assert np.all(d["injected"] >= 0) and np.all(np.diff(d["nodes"]) == d["injected"][1:])
    assert m.point_data["plastic_strain"].shape == (n,) and m.point_data["plastic_strain"].max() > 0
    assert m.cell_data["stress_invariant"][0].max() > 0
    assert m.cell_data["plastic_strain"][0].shape == (cells.data.shape[0],)


def test_the_slices_show_the_plate_where_it_is(run3d):
    import matplotlib.image as mpimg

    from skfem_nem.apps.plate3d_figures import COLOURS, slices
    from skfem_nem.apps.sinking_plate_3d import SinkingPlate3D, plate_box
    sim = SinkingPlate3D.restart(run3d)
    panels = slices(sim)
    assert [p[1] for p in panels] == ["xz", "xy", "xz", "xy"]
    lo, hi = plate_box(sim.cfg)
    (_, _, image, extent) = panels[0]                  # start, vertical slice y = plate_y
    rows, cols = image.shape
    x = np.linspace(extent[0], extent[1], cols)
    z = np.linspace(extent[2], extent[3], rows)
    X, Z = np.meshgrid(x, z)
    plate = image == 2
    assert plate.any()
    slack = 0.15                                        # the node spacing near the plate
    assert np.all((X[plate] > lo[0] - slack) & (X[plate] < hi[0] + slack))
    assert np.all((Z[plate] > lo[2] - slack) & (Z[plate] < hi[2] + slack))
    # away from the plate: the upper fluid above the interface, the lower below
    far = np.abs(X - 0.5 * (lo[0] + hi[0])) > 0.5 * (hi[0] - lo[0]) + slack
    assert np.all(image[far & (Z > sim.cfg.interface_z + 0.1)] == 0)
    assert np.all(image[far & (Z < sim.cfg.interface_z - 0.1)] == 1)
    # and the figure draws them: the plate's colour is in the picture
    png = mpimg.imread(run3d / "slices.png")[..., :3]
    red = np.array([int(COLOURS[2][k:k + 2], 16) / 255 for k in (1, 3, 5)])
    assert (np.abs(png - red).max(axis=2) < 0.02).sum() > 100


def test_a_restart_continues_the_run(run3d, tmp_path):
    import shutil
    out = tmp_path / "r"
    shutil.copytree(run3d, out)
    # one step more than stored: the log keeps its rows and adds the new ones
    meta = json.loads((out / "checkpoint.json").read_text())
    assert meta["dim"] == 3
    rows = (out / "diagnostics.csv").read_text().strip().splitlines()
    assert main(["sinking-plate", "--restart", "--end-time", "80", "--quiet",
                 "-o", str(out)]) == 0
    more = (out / "diagnostics.csv").read_text().strip().splitlines()
    assert more[:len(rows)] == rows and len(more) > len(rows)
    assert float(more[-1].split(",")[1]) == 80


def test_a_restart_carries_the_stress_history(run3d):
    from skfem_nem.apps.sinking_plate_3d import SinkingPlate3D
    from skfem_nem.evolution.remap3d import cell_volumes
    sim = SinkingPlate3D.restart(run3d)
    with np.load(run3d / "checkpoint.npz") as z:
        w = cell_volumes(z["nodes"], z["tetrahedra"])
        stored = {k: np.einsum("t,tk...->...", w, z[f"ip__{k}"])
                  for k in ("stress", "plastic_strain", "log_eta_eff")}
    assert stored["plastic_strain"] > 0 and np.abs(stored["stress"]).max() > 0
    for k, v in stored.items():
        np.testing.assert_allclose(sim.lm.ip_integral(k), v, rtol=1e-12, atol=1e-15)
    assert sim.lm.time == 60 and sim.cfg.shear_modulus == 2.0


def small_sim(tmp_path, **kw):
    from skfem_nem.apps.plate3d_config import Plate3DConfig
    from skfem_nem.apps.sinking_plate_3d import SinkingPlate3D
    cfg = dict(nodes=300, density_length=0.3, max_dt=30.0, end_time=60.0, output_interval=30.0)
    cfg.update(kw)
    return SinkingPlate3D(Plate3DConfig(**cfg), tmp_path / "s")


@pytest.mark.parametrize("stage", ["picard", "move", "midpoint"])
def test_a_failed_step_leaves_the_state_as_it_was(stage, tmp_path, monkeypatch):
    from skfem_nem.apps import sinking_plate_3d
    from skfem_nem.apps.sinking_plate import StepStalled
    from skfem_nem.evolution.stepping import StepTooLong
    from skfem_nem.models.rheology import PicardNotConverged
    sim = small_sim(tmp_path, min_dt=4.0, midpoint=stage == "midpoint")
    sim.step(10.0)                                      # a stress history to lose
    before = {k: v.copy() for k, v in sim.lm.ip_fields.items()}
    nodes, t0, tries = sim.lm.nodes.copy(), sim.lm.time, []
    step0, reports = sim.lm.step, len(sim.lm.history)
    assert np.abs(before["stress"]).max() > 0
    if stage == "midpoint":      # the second solve fails, after the half-way move
        solve = sinking_plate_3d.vep_step

        def fail(*a, **k):
            if k.get("on_iterate") is None:
                tries.append(a[3])
                raise PicardNotConverged("no convergence")
            return solve(*a, **k)
        monkeypatch.setattr(sinking_plate_3d, "vep_step", fail)
    elif stage == "picard":
        def fail(*a, **k):
            tries.append(a[3])
            raise PicardNotConverged("no convergence")
        monkeypatch.setattr(sinking_plate_3d, "vep_step", fail)
    else:
        def fail(velocity, dt, tol, inject=None):
            tries.append(dt)
            raise StepTooLong("two nodes would coincide")
        monkeypatch.setattr(sim.lm, "advance", fail)
    with pytest.raises(StepStalled, match="failed at dt = 5"):
        sim.step(20.0)
    assert tries == [20.0, 10.0, 5.0]          # halved down to min_dt
    assert sim.lm.ip_fields.keys() == before.keys()
    for k, v in before.items():
        np.testing.assert_array_equal(sim.lm.ip_fields[k], v)
    np.testing.assert_array_equal(sim.lm.nodes, nodes)
    assert sim.lm.time == t0 and sim.lm.step == step0 and len(sim.lm.history) == reports


@pytest.mark.parametrize("midpoint", [False, True])
def test_a_step_longer_than_its_velocity_allows_is_solved_again(midpoint, tmp_path,
                                                                 monkeypatch):
    """A try far too long stops at its first Picard iterate (FIRST_ITERATE_SLACK) and is
    solved again at the dt that iterate asks for; the step taken keeps within
    STABLE_SLACK of its own velocity's dt (with midpoint, both solves' velocities)."""
    import skfem_nem.apps.sinking_plate_3d as app
    iterations = []
    solve = app.vep_step

    def counted(*a, **kw):
        seen = []
        check = kw["on_iterate"] or (lambda sol: None)
        kw["on_iterate"] = lambda sol: (seen.append(sol), check(sol))
        try:
            return solve(*a, **kw)
        finally:
            iterations.append(len(seen))

    monkeypatch.setattr(app, "vep_step", counted)
    sim = small_sim(tmp_path, max_dt=500.0, end_time=1000.0, midpoint=midpoint)
    row = sim.step(500.0)
    assert row["retries"] >= 1 and row["dt"] < 500.0
    assert row["dt"] <= app.STABLE_SLACK * row["stable_dt"]
    assert iterations[0] == 1 and iterations[-1] == row["picard_iterations"] > 1


@pytest.mark.parametrize("picard_tol", [1e-3, 3e-2])
def test_a_midpoint_step_solves_again_half_way(picard_tol, tmp_path, monkeypatch):
    """midpoint: the second solve starts from the first's velocity on the nodes moved half
    a step with it; the nodes end where the second velocity takes them from the start
    (walls kept); one step, one report with both moves' flips. The first solve stops at
    the looser of PREDICTOR_TOL and picard_tol, the second at picard_tol."""
    import skfem_nem.apps.sinking_plate_3d as app
    calls = []
    solve = app.vep_step

    def spy(spaces, *a, **kw):
        r = solve(spaces, *a, **kw)
        calls.append((spaces.mesh.p.T.copy(), kw.get("u_guess"), r, kw["tol"]))
        return r

    monkeypatch.setattr(app, "vep_step", spy)
    sim = small_sim(tmp_path, midpoint=True, split_edges=float("inf"),
                    picard_tol=picard_tol)
    x0, step0, reports = sim.lm.nodes.copy(), sim.lm.step, len(sim.lm.history)
    row = sim.step(10.0)
    assert row["retries"] == 0 and len(calls) == 2
    (xa, _, r1, tol1), (xb, guess, r2, tol2) = calls
    assert (tol1, tol2) == (max(app.PREDICTOR_TOL, picard_tol), picard_tol)
    assert 1e-3 < app.PREDICTOR_TOL < 3e-2
    np.testing.assert_array_equal(xa, x0)
    v1, v2 = r1.solution.velocity_at_nodes(), r2.solution.velocity_at_nodes()
    lo, hi = x0.min(axis=0), x0.max(axis=0)
    np.testing.assert_allclose(xb, np.clip(x0 + 5.0 * v1, lo, hi), atol=1e-12)
    np.testing.assert_array_equal(guess, r1.solution.u)
    np.testing.assert_allclose(sim.lm.nodes, np.clip(x0 + 10.0 * v2, lo, hi), atol=1e-12)
    assert np.abs(v2 - v1).max() > 0
    assert sim.lm.step == step0 + 1 == row["step"] and len(sim.lm.history) == reports + 1
    assert sim.lm.history[-1]["dt"] == 10.0 and row["flips"] == sim.lm.history[-1]["flips"]


def test_a_midpoint_step_frees_the_first_spaces_before_its_second_solve(tmp_path,
                                                                         monkeypatch):
    """The second solve runs with the first solve's spaces (and the hierarchy built on
    them) gone: a midpoint step holds one set of bases at a time, besides the last
    step's solution."""
    import weakref

    import skfem_nem.apps.sinking_plate_3d as app
    seen, solve = [], app.vep_step

    def spy(spaces, *a, **kw):
        if seen:
            seen.append(seen[0]() is None)
        else:
            seen.append(weakref.ref(spaces))
        return solve(spaces, *a, **kw)

    monkeypatch.setattr(app, "vep_step", spy)
    sim = small_sim(tmp_path, split_edges=float("inf"))
    assert sim.cfg.midpoint
    sim.step(10.0)
    assert len(seen) == 2 and seen[1] is True


def test_a_step_builds_its_spaces_with_the_last_steps_gone(tmp_path, monkeypatch):
    """The next step's spaces are built after the last step's spaces, blocks and AMG
    hierarchy are let go (30,300 nodes: 1.6 GB of the peak); the step keeps only its
    solution's arrays, and its velocity is the next step's start."""
    import weakref

    import skfem_nem.apps.sinking_plate_3d as app
    seen, build, solve = [], app.stokes_spaces, app.vep_step
    kept, cells = {}, []

    def spy_build(mesh, **kw):
        cells.append(mesh.nelements)
        seen.append(all(r() is None for r in kept.values()))
        return build(mesh, **kw)

    def spy_solve(spaces, *a, **kw):
        out = solve(spaces, *a, **kw)
        kept.update(spaces=weakref.ref(spaces), hierarchy=weakref.ref(kw["cache"].hierarchy))
        seen.append("u_guess" in kw)
        return out

    monkeypatch.setattr(app, "stokes_spaces", spy_build)
    monkeypatch.setattr(app, "vep_step", spy_solve)
    sim = small_sim(tmp_path, split_edges=float("inf"), midpoint=False, solver="fgmres")
    sim.step(10.0)
    last = sim.solution()
    assert isinstance(last, app.LastSolve)
    assert all(isinstance(a, np.ndarray) for a in (last.u, last.p, last.velocity,
                                                    last.pressure))
    assert last.velocity.shape == (sim.lm.nodes.shape[0], 3)
    assert last.cells == cells[-1] and last.ranks == 1
    sim.step(10.0)
    assert seen == [True, False, True, True]


def test_nodes_added_after_a_step_get_fields_and_output(tmp_path):
    import meshio

    from skfem_nem.apps.output import PVDWriter
    sim = small_sim(tmp_path, split_edges=1.6)
    n = sim.lm.nodes.shape[0]
    row = sim.step(10.0)
    assert row["injected"] > 0 and row["nodes"] == n + row["injected"] == sim.lm.nodes.shape[0]
    assert sim.lm.ip_fields["stress"].shape[0] == sim.lm.mesh.nelements
    sim._pvd = PVDWriter(sim.out / "plate.pvd")
    m = meshio.read(sim.out / sim.write_output())
    v = m.point_data["velocity"]
    assert v.shape == (sim.lm.nodes.shape[0], 3) and np.isfinite(v).all()
    # an added node's velocity lies between its neighbours' (Sibson: a convex combination)
    assert np.abs(v[n:]).max() <= np.abs(v[:n]).max()
    assert sim.step(10.0)["picard_iterations"] >= 1      # and the next step solves on them


def test_infinite_modulus_and_yield_stress_give_the_viscous_plate(tmp_path):
    sim = small_sim(tmp_path, shear_modulus=float("inf"), yield_stress=float("inf"),
                    plate_viscosity=1000.0)
    row = sim.step(10.0)
    assert row["picard_iterations"] == 1 and row["max_plastic_strain"] == 0
    assert row["yielded_points"] == 0 and np.abs(sim.lm.ip_fields["plastic_strain"]).max() == 0
    assert row["plate_velocity"] < 0


def test_a_checkpoint_of_the_viscous_plate_restarts_viscous(tmp_path):
    """A checkpoint written before the plate had a stress history (nodes and node
    fields only, a configuration without rheology) continues as the viscous plate."""
    from dataclasses import asdict

    from skfem_nem.apps.sinking_plate_3d import SinkingPlate3D
    sim = small_sim(tmp_path, plate_viscosity=1000.0)
    out = tmp_path / "old"
    out.mkdir()
    f = sim.lm.node_fields
    np.savez(out / "checkpoint.npz", nodes=sim.lm.nodes, plate=f["plate"], start=f["start"],
             clock=np.array([12.5, 3]))
    config = {k: v for k, v in asdict(sim.cfg).items()
              if k not in ("shear_modulus", "yield_stress", "picard_tol", "remap",
                           "viscosity_mean")}
    (out / "checkpoint.json").write_text(json.dumps(
        {"dim": 3, "config": config, "next_output": 30.0, "dt_next": 10.0, "outputs": 1,
         "volume0": sim.volume0}))
    old = SinkingPlate3D.restart(out)
    assert old.cfg.shear_modulus == np.inf and old.cfg.yield_stress == np.inf
    assert old.cfg.plate_viscosity == 1000.0 and old.cfg.picard_tol == 1e-3
    assert old.cfg.viscosity_mean == "geometric"        # the blend it ran with
    assert (old.lm.time, old.lm.step) == (12.5, 3)
    assert np.abs(old.lm.ip_fields["stress"]).max() == 0
    np.testing.assert_array_equal(old.lm.nodes, sim.lm.nodes)
    assert old.step(5.0)["picard_iterations"] == 1


def test_the_blended_viscosity_is_the_harmonic_or_the_geometric_mean():
    from skfem_nem.apps.plate3d_materials import blended_viscosity
    s = np.linspace(0.0, 1.0, 11)
    fluid = np.where(s < 0.5, 1.0, 10.0)
    h = blended_viscosity(fluid, 1e4, s, "harmonic")
    g = blended_viscosity(fluid, 1e4, s, "geometric")
    for eta in (h, g):
        np.testing.assert_allclose(eta[[0, -1]], [1.0, 1e4], rtol=1e-14)
    # harmonic: the compliance is linear in s; geometric: the log-viscosity
    np.testing.assert_allclose(1 / h, (1 - s) / fluid + s / 1e4, rtol=1e-14)
    np.testing.assert_allclose(np.log(g), (1 - s) * np.log(fluid) + s * np.log(1e4),
                               rtol=1e-14, atol=1e-14)
    # between the two materials the harmonic blend is the softer one, by far at s = 1/2
    assert np.all(h[1:-1] < g[1:-1]) and h[5] < 25 < 300 < g[5]
    with pytest.raises(ValueError, match="mean must be 'harmonic' or 'geometric', got 'x'"):
        blended_viscosity(fluid, 1e4, s, "x")


@pytest.mark.parametrize("mean", ["harmonic", "geometric"])
def test_the_plate_materials_use_the_configured_blend(mean, tmp_path):
    from skfem_nem.apps.plate3d_materials import blended_viscosity
    from skfem_nem.models.stokes import stokes_spaces
    sim = small_sim(tmp_path, viscosity_mean=mean)
    spaces = stokes_spaces(sim.lm.mesh)
    material, force, s = sim.materials(spaces)
    edge = (s > 0.05) & (s < 0.95)
    assert edge.sum() > 100                             # points in the blend
    fluid = material.viscosity[s == 0]
    upper, lower = np.isclose(fluid, 1.0, rtol=1e-14), np.isclose(fluid, 10.0, rtol=1e-14)
    assert np.all(upper | lower) and upper.any() and lower.any()
    z = np.asarray(spaces.pbasis.interpolate(sim.lm.node_fields["start"][:, 2]))
    expect = blended_viscosity(np.where(z > sim.cfg.interface_z, 1.0, 10.0), 1e4, s, mean)
    np.testing.assert_allclose(material.viscosity, expect, rtol=1e-13)
    np.testing.assert_array_equal(force[2], -1.5 * s)


def test_the_plastic_strain_figure_shows_the_plate(run3d):
    from skfem_nem.apps.plate3d_figures import plastic_slices, plate_surface
    from skfem_nem.apps.sinking_plate_3d import SinkingPlate3D, plate_box
    sim = SinkingPlate3D.restart(run3d)
    lo, hi = plate_box(sim.cfg)
    slack = 0.15
    # what is drawn interpolates the nodes' plastic strain linearly: within its range. That
    # range dips below 0 by the conservative remap's undershoot (docs/stokes_3d.md)
    strain = sim.lm.ip_at_nodes("plastic_strain")
    low, top = strain.min() - 1e-12, strain.max() + 1e-12
    assert top > 0 and low > -0.05 * top
    for title, plane, image, extent in plastic_slices(sim):
        inside = np.isfinite(image)
        assert inside.any() and (~inside).any()       # the plate only
        assert image[inside].min() >= low and image[inside].max() <= top
        # the plan view holds the largest values through the plate; the vertical slice
        # through its middle shows some (the bands that yield may lie off that plane)
        assert image[inside].max() > (0.5 * top if plane == "xy" else 0.0)
        rows, cols = image.shape
        x = np.linspace(extent[0], extent[1], cols)[None, :].repeat(rows, 0)
        assert np.all((x[inside] > lo[0] - slack) & (x[inside] < hi[0] + slack))
    triangles, values = plate_surface(sim)
    corners = triangles.reshape(-1, 3)
    assert triangles.shape[1:] == (3, 3) and values.shape == triangles.shape[:1]
    # (the surface cuts edges from plate nodes to the next nodes out, up to 0.3 long here)
    assert np.all((corners > lo - 2 * slack) & (corners < hi + 2 * slack))
    # the surface cuts each edge from a plate node outwards half-way, where the value is the
    # mean of the edge's ends: about half the plate's largest where the fluid has none
    assert values.min() >= low and values.max() <= top and values.max() > 0.25 * top
    assert (run3d / "plastic_strain.png").exists()


def test_level_surface_of_a_linear_field_is_its_plane():
    from skfem.mesh import MeshTet

    from skfem_nem.apps.plate3d_figures import level_surface
    m = MeshTet.init_tensor(*(np.linspace(0, 1, 5),) * 3)
    p, t = m.p.T, m.t.T
    s = p @ [0.3, 0.5, 0.2]
    triangles, values = level_surface(p, t, s, 0.45, 2 * s)
    corners = triangles.reshape(-1, 3)
    np.testing.assert_allclose(corners @ [0.3, 0.5, 0.2], 0.45, atol=1e-14)
    np.testing.assert_allclose(values, 0.9, atol=1e-14)
    # the cut through the cube: its area from the triangles
    area = 0.5 * np.linalg.norm(np.cross(triangles[:, 1] - triangles[:, 0],
                                         triangles[:, 2] - triangles[:, 0]), axis=1).sum()
    from scipy.spatial import ConvexHull
    n = np.array([0.3, 0.5, 0.2]) / np.linalg.norm([0.3, 0.5, 0.2])
    e1 = np.cross(n, [1, 0, 0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    exact = ConvexHull(np.c_[corners @ e1, corners @ e2]).volume
    np.testing.assert_allclose(area, exact, rtol=1e-12)


@pytest.mark.parametrize("args, words", [
    (["--dim", "3", "--outline-spacing", "1"],
     "--outline-spacing is not a parameter of the 3D plate (it is one of the 2D plate only)"),
    (["--dim", "3", "--remap", "nearest"], "remap must be one of"),
    (["--dim", "3", "--viscosity-mean", "arithmetic"],
     "viscosity_mean must be one of 'harmonic', 'geometric', got 'arithmetic'"),
    (["--dim", "3", "--shear-modulus", "-1"], "shear_modulus must be a positive number or inf"),
    (["--dim", "3", "--split-edges", "1"], "split_edges must be a number above 1 or inf"),
    (["--depth", "3"], "--depth is not a parameter of the 2D plate"),
    (["--dim", "3", "--plate-y", "1.9"], "plate_y / plate_width"),
    (["--dim", "3", "--solver", "pets"], "solver must be one of"),
    (["--dim", "3", "--first-solve-tol", "1"],
     "first_solve_tol must be 0 (solver_tol's) or a number in (0, 1), got 1"),
])
def test_user_errors_are_one_line(args, words, tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["sinking-plate", *args, "-o", str(tmp_path / "o"), "--quiet"])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and words in err


def test_a_restart_keeps_its_dimension(run3d, tmp_path, capsys):
    import shutil
    out = tmp_path / "r"
    shutil.copytree(run3d, out)
    before = (out / "checkpoint.json").read_text()
    for args, words in ((["--dim", "2"], "--dim 2 cannot change"),
                        (["--depth", "3"], "--depth cannot change")):
        with pytest.raises(SystemExit) as exc:
            main(["sinking-plate", "--restart", *args, "-o", str(out), "--quiet"])
        assert exc.value.code == 2 and words in capsys.readouterr().err
    assert (out / "checkpoint.json").read_text() == before


def test_a_toml_file_with_a_2d_key_is_refused(tmp_path, capsys):
    cfg = tmp_path / "p.toml"
    cfg.write_text("[sinking-plate]\noutline_spacing = 3.0\n")
    with pytest.raises(SystemExit) as exc:
        main(["sinking-plate", "--dim", "3", "--config", str(cfg), "-o", str(tmp_path / "o")])
    assert exc.value.code == 2 and "unknown configuration key 'outline_spacing'" in \
        capsys.readouterr().err


def test_the_nodes_are_numbered_along_the_z_order_curve():
    """Neighbours get nearby numbers (the viscous block's rows touch nearby memory): the
    median number distance along the tetrahedra's edges is a small fraction of the drawn
    order's, and the node set itself is the drawn one."""
    from skfem_nem import delaunay_mesh
    from skfem_nem.apps.plate3d_config import Plate3DConfig
    from skfem_nem.apps.sinking_plate_3d import initial_nodes
    from skfem_nem.geometry.nodesets import morton_order
    cfg = Plate3DConfig(nodes=3000)
    p = initial_nodes(cfg)
    np.testing.assert_array_equal(morton_order(p), np.arange(p.shape[0]))
    t = delaunay_mesh(p).t
    edges = np.concatenate([t[[i, j]] for i in range(4) for j in range(i + 1, 4)], axis=1)
    drawn = np.random.default_rng(0).permutation(p.shape[0])   # any order but a local one
    gap = np.median(np.abs(edges[0] - edges[1]))
    assert gap < 0.05 * np.median(np.abs(drawn[edges[0]] - drawn[edges[1]]))


def test_the_slices_share_one_tetrahedralisation_a_node_set(run3d, monkeypatch):
    """The figures' slices interpolate on one Delaunay tetrahedralisation of each node set
    (the start's and now's, two for the slices, one for the plastic strain's 17), and draw
    what a tetrahedralisation of their own for each slice draws."""
    import skfem_nem.apps.plate3d_figures as figures
    from skfem_nem.apps.sinking_plate_3d import SinkingPlate3D
    from skfem_nem.geometry.delaunay_nd import delaunay_of
    sim = SinkingPlate3D.restart(run3d)
    built = []

    def counted(nodes):
        built.append(nodes.shape)
        return delaunay_of(nodes)
    monkeypatch.setattr(figures, "delaunay_of", counted)
    shared = figures.slices(sim) + figures.plastic_slices(sim)
    assert len(built) == 3
    monkeypatch.setattr(figures, "delaunay_of", lambda nodes: nodes)   # raw nodes: one each
    own = figures.slices(sim) + figures.plastic_slices(sim)
    assert len(shared) == len(own) == 6
    for (t1, p1, a, e1), (t2, p2, b, e2) in zip(shared, own):
        assert (t1, p1, e1) == (t2, p2, e2)
        np.testing.assert_array_equal(a, b)
