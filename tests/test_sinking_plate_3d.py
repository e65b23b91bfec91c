"""The 3D sinking plate (``skfem-nem sinking-plate --dim 3``): a small run end to end, its
outputs, a restart, and the command line's one-line errors."""
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


@pytest.mark.parametrize("args, words", [
    (["--dim", "3", "--yield-stress", "1"], "--yield-stress is not a parameter of the 3D"),
    (["--depth", "3"], "--depth is not a parameter of the 2D plate"),
    (["--dim", "3", "--plate-y", "1.9"], "plate_y / plate_width"),
    (["--dim", "3", "--solver", "petsc"], "solver must be one of"),
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
    cfg.write_text("[sinking-plate]\nshear_modulus = 3.0\n")
    with pytest.raises(SystemExit) as exc:
        main(["sinking-plate", "--dim", "3", "--config", str(cfg), "-o", str(tmp_path / "o")])
    assert exc.value.code == 2 and "unknown configuration key 'shear_modulus'" in \
        capsys.readouterr().err
