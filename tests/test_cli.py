import re

import numpy as np
import pytest

from skfem_nem.apps.cli import main


def test_interpolate_csv(tmp_path):
    rng = np.random.default_rng(0)
    p = np.r_[[[0, 0], [1, 0], [1, 1], [0, 1]], rng.random((50, 2))]
    f = 2 * p[:, 0] - p[:, 1] + 1
    np.savetxt(tmp_path / "nodes.csv", np.c_[p, f, 3 * f], delimiter=",", header="x,y,f,g",
               comments="")
    q = 0.1 + 0.8 * rng.random((20, 2))
    np.savetxt(tmp_path / "q.csv", q, delimiter=",")
    out = tmp_path / "out.csv"
    assert main(["interpolate", str(tmp_path / "nodes.csv"), str(tmp_path / "q.csv"),
                 "-o", str(out), "--gradient"]) == 0
    assert header(out) == "x,y,f,g,df/dx,dg/dx,df/dy,dg/dy"
    r = np.loadtxt(out, delimiter=",", skiprows=1)
    lin = 2 * q[:, 0] - q[:, 1] + 1
    np.testing.assert_allclose(r[:, 2], lin, atol=1e-12)   # linear precision
    np.testing.assert_allclose(r[:, 3], 3 * lin, atol=1e-12)
    np.testing.assert_allclose(r[:, 4], 2, atol=1e-10)     # df/dx
    np.testing.assert_allclose(r[:, 7], -3, atol=1e-10)    # dg/dy


def header(path):
    return path.read_text().splitlines()[0]


def write_nodes(tmp_path, n=80, seed=1):
    """Nodes with named columns: the corners of the unit square and random points; values
    'temp' (linear) and 'rain' (smooth)."""
    rng = np.random.default_rng(seed)
    p = np.r_[[[0, 0], [1, 0], [1, 1], [0, 1]], rng.random((n - 4, 2))]
    temp, rain = 1 + 2 * p[:, 0] - 3 * p[:, 1], np.sin(3 * p[:, 0]) * p[:, 1]
    np.savetxt(tmp_path / "nodes.csv", np.c_[p, temp, rain], delimiter=",",
               header="lon,lat,temp,rain", comments="")
    return p, np.c_[temp, rain]


def test_interpolate_keeps_names_and_fills_outside(tmp_path, capsys):
    """The output's header is the input's column names; queries outside the hull do not
    stop the run: their rows carry the fill value (NaN by default), the summary counts
    them, the rows inside are the interpolator's."""
    from skfem_nem import NaturalNeighbourInterpolator
    p, f = write_nodes(tmp_path)
    q = np.array([[0.3, 0.4], [1.5, 0.5], [0.9, 0.2], [-0.1, -2.0], [1.0, 0.5]])
    np.savetxt(tmp_path / "q.csv", q, delimiter=",", header="lon,lat", comments="")
    out = tmp_path / "out.csv"
    assert main(["interpolate", str(tmp_path / "nodes.csv"), str(tmp_path / "q.csv"),
                 "-o", str(out)]) == 0
    assert "2 outside the data's convex hull, set to nan" in capsys.readouterr().out
    assert header(out) == "lon,lat,temp,rain"
    r = np.loadtxt(out, delimiter=",", skiprows=1)
    np.testing.assert_array_equal(r[:, :2], q)
    assert np.isnan(r[[1, 3], 2:]).all() and np.isfinite(r[[0, 2, 4], 2:]).all()
    ref = NaturalNeighbourInterpolator(p, f)(q[[0, 2, 4]])
    np.testing.assert_allclose(r[[0, 2, 4], 2:], ref, rtol=0, atol=1e-15)
    assert main(["interpolate", str(tmp_path / "nodes.csv"), str(tmp_path / "q.csv"),
                 "-o", str(out), "--fill-value", "-9999"]) == 0
    assert "2 outside the data's convex hull, set to -9999" in capsys.readouterr().out
    r = np.loadtxt(out, delimiter=",", skiprows=1)
    np.testing.assert_array_equal(r[[1, 3], 2:], -9999.0)
    np.testing.assert_allclose(r[[0, 2, 4], 2:], ref, rtol=0, atol=1e-15)


@pytest.mark.parametrize("method", ["sibson", "laplace", "sibson1", "farin", "linear",
                                    "nearest"])
def test_interpolate_every_method(tmp_path, capsys, method):
    """--method reaches the interpolator: the output is its values and gradients."""
    from skfem_nem import NaturalNeighbourInterpolator
    p, f = write_nodes(tmp_path)
    q = 0.05 + 0.9 * np.random.default_rng(2).random((30, 2))
    np.savetxt(tmp_path / "q.csv", q, delimiter=",")
    out = tmp_path / "out.csv"
    assert main(["interpolate", str(tmp_path / "nodes.csv"), str(tmp_path / "q.csv"),
                 "-o", str(out), "--method", method, "--gradient"]) == 0
    assert f"method {method};" in capsys.readouterr().out
    assert header(out) == ("lon,lat,temp,rain,dtemp/dlon,drain/dlon,dtemp/dlat,drain/dlat")
    r = np.loadtxt(out, delimiter=",", skiprows=1)
    itp = NaturalNeighbourInterpolator(p, f, method=method)
    np.testing.assert_allclose(r[:, 2:4], itp(q), rtol=0, atol=1e-14)
    g = itp.gradient(q)
    np.testing.assert_allclose(r[:, 4:6], g[:, :, 0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(r[:, 6:8], g[:, :, 1], rtol=0, atol=1e-12)
    if method != "nearest":                      # linear precision of 'temp'
        np.testing.assert_allclose(r[:, 2], 1 + 2 * q[:, 0] - 3 * q[:, 1], atol=1e-12)


def test_interpolate_on_a_grid(tmp_path, capsys):
    """--grid NX NY [--bounds]: the grid's points, x varying fastest, in the data's bounding
    box by default; points of the grid outside the hull get the fill value."""
    p, f = write_nodes(tmp_path)
    out = tmp_path / "g.csv"
    assert main(["interpolate", str(tmp_path / "nodes.csv"), "--grid", "5", "3",
                 "--bounds", "0.1", "0.9", "-0.5", "0.5", "-o", str(out)]) == 0
    r = np.loadtxt(out, delimiter=",", skiprows=1)
    assert header(out) == "lon,lat,temp,rain" and r.shape == (15, 4)
    gx, gy = np.meshgrid(np.linspace(0.1, 0.9, 5), np.linspace(-0.5, 0.5, 3))
    np.testing.assert_allclose(r[:, 0], gx.ravel(), rtol=0, atol=1e-15)
    np.testing.assert_allclose(r[:, 1], gy.ravel(), rtol=0, atol=1e-15)
    below = r[:, 1] < 0
    assert np.isnan(r[below, 2:]).all() and np.isfinite(r[~below, 2:]).all()
    np.testing.assert_allclose(r[~below, 2], 1 + 2 * r[~below, 0] - 3 * r[~below, 1],
                               atol=1e-12)
    assert "; 5 outside the data's convex hull" in capsys.readouterr().out
    assert main(["interpolate", str(tmp_path / "nodes.csv"), "--grid", "4", "6",
                 "-o", str(out)]) == 0                 # the unit square: all inside
    assert "(method sibson; 0 outside" in capsys.readouterr().out
    r = np.loadtxt(out, delimiter=",", skiprows=1)
    np.testing.assert_allclose(r[[0, 3, -1], :2], [[0, 0], [1, 0], [1, 1]], atol=1e-15)
    np.testing.assert_allclose(r[:, 2], 1 + 2 * r[:, 0] - 3 * r[:, 1], atol=1e-12)


def test_interpolate_3d_grid_without_header(tmp_path, capsys):
    """--dim 3 with --grid NX NY NZ; a file without a header gives x, y, z, value0, ..."""
    rng = np.random.default_rng(4)
    corners = np.array(np.meshgrid([0.0, 1.0], [0.0, 1.0], [0.0, 1.0])).reshape(3, -1).T
    p = np.r_[corners, rng.random((60, 3))]
    np.savetxt(tmp_path / "n.csv", np.c_[p, 1 + p @ [1.0, -2.0, 0.5]], delimiter=",")
    out = tmp_path / "g.csv"
    assert main(["interpolate", str(tmp_path / "n.csv"), "--dim", "3", "--grid", "3", "2",
                 "4", "--bounds", "0", "1", "0", "1", "0.1", "0.9", "-o", str(out),
                 "--gradient"]) == 0
    assert header(out) == "x,y,z,value0,dvalue0/dx,dvalue0/dy,dvalue0/dz"
    r = np.loadtxt(out, delimiter=",", skiprows=1)
    assert r.shape == (24, 7)
    np.testing.assert_allclose(r[:4, :3], [[0, 0, 0.1], [0.5, 0, 0.1], [1, 0, 0.1],
                                           [0, 1, 0.1]], atol=1e-15)
    np.testing.assert_allclose(r[:, 3], 1 + r[:, :3] @ [1.0, -2.0, 0.5], atol=1e-12)


def user_error(argv, capsys):
    """The one line on stderr of a command that exits with status 2 (no traceback)."""
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "Traceback" not in err, err
    assert err.startswith("skfem-nem: "), err
    return err


def test_interpolate_errors(tmp_path, capsys):
    (tmp_path / "n.csv").write_text("x,y,f\n0,0,1\n1,0,1\n0,1,1\n")
    (tmp_path / "q.csv").write_text("2,2\n")
    (tmp_path / "bad.csv").write_text("x,y,f\n0,0,1\n1,zero,1\n")
    assert "line 2 is not numeric" in user_error(
        ["interpolate", str(tmp_path / "bad.csv"), str(tmp_path / "q.csv")], capsys)
    assert "cannot read nodes" in user_error(
        ["interpolate", str(tmp_path / "missing.csv"), str(tmp_path / "q.csv")], capsys)
    assert "cannot read queries" in user_error(
        ["interpolate", str(tmp_path / "n.csv"), str(tmp_path / "missing.csv")], capsys)
    (tmp_path / "nan.csv").write_text("x,y,f\n0,0,1\n1,0,nan\n0,1,1\n")
    (tmp_path / "q1.csv").write_text("0.2,0.2\n")
    assert "line 2 holds a value that is not finite" in user_error(
        ["interpolate", str(tmp_path / "nan.csv"), str(tmp_path / "q1.csv")], capsys)
    out = tmp_path / "no" / "such" / "folder" / "o.csv"
    assert "cannot write output file" in user_error(
        ["interpolate", str(tmp_path / "n.csv"), str(tmp_path / "q1.csv"), "-o", str(out)],
        capsys)
    assert not out.parent.exists()


def test_interpolate_input_errors_name_the_input(tmp_path, capsys):
    """Missing columns, an unknown method or one not available in the dimension, a query
    file and --grid together, bad --grid and --bounds, a bad fill value: one line each,
    naming the offending input, and no output file."""
    n, q, o = tmp_path / "n.csv", tmp_path / "q.csv", tmp_path / "o.csv"
    n.write_text("x,y,f\n0,0,1\n1,0,1\n0,1,1\n1,1,2\n")
    q.write_text("0.5,0.5\n")
    run = ["interpolate", str(n), str(q), "-o", str(o)]
    grid = ["interpolate", str(n), "-o", str(o), "--grid"]
    (tmp_path / "two.csv").write_text("x,y\n0,0\n1,0\n0,1\n")
    assert re.search(r"nodes file .*two.csv.* needs at least 3 columns", user_error(
        ["interpolate", str(tmp_path / "two.csv"), str(q)], capsys))
    (tmp_path / "n3.csv").write_text("x,y,z,f\n0,0,0,1\n1,0,0,1\n0,1,0,1\n0,0,1,1\n")
    assert re.search(r"queries file .*q.csv.* needs at least 3 columns", user_error(
        ["interpolate", str(tmp_path / "n3.csv"), str(q), "--dim", "3"], capsys))
    (tmp_path / "hdr.csv").write_text("x,y\n0,0,1\n1,0,1\n0,1,1\n")
    assert "header names 2 column(s), the data lines have 3" in user_error(
        ["interpolate", str(tmp_path / "hdr.csv"), str(q)], capsys)
    assert "unknown --method 'cubic': one of sibson, laplace" in user_error(
        run + ["--method", "cubic"], capsys)
    assert "either a QUERIES file or --grid" in user_error(run + ["--grid", "3", "3"], capsys)
    assert "give a QUERIES file or --grid" in user_error(
        ["interpolate", str(n), "-o", str(o)], capsys)
    assert "--grid needs 2 positive integers NX NY" in user_error(grid + ["3"], capsys)
    assert "--grid needs 2 positive integers" in user_error(grid + ["3", "x"], capsys)
    assert "--grid needs 2 positive integers" in user_error(grid + ["3", "0"], capsys)
    assert "--bounds needs 4 finite numbers" in user_error(
        grid + ["3", "3", "--bounds", "0", "1", "0"], capsys)
    assert "--bounds needs 4 finite numbers" in user_error(
        grid + ["3", "3", "--bounds", "0", "1", "0", "one"], capsys)
    assert "XMIN must be below XMAX, got 1 and 0" in user_error(
        grid + ["3", "3", "--bounds", "1", "0", "0", "1"], capsys)
    assert "--bounds needs --grid" in user_error(run + ["--bounds", "0", "1", "0", "1"], capsys)
    assert "--fill-value must be a number" in user_error(run + ["--fill-value", "none"], capsys)
    assert "--dim must be 2 or 3" in user_error(run + ["--dim", "4"], capsys)
    (tmp_path / "dup.csv").write_text("x,y,f\n0,0,1\n1,0,1\n0,1,1\n0,0,2\n")
    assert re.search(r"nodes file .*dup.csv.*duplicate", user_error(
        ["interpolate", str(tmp_path / "dup.csv"), str(q)], capsys))
    assert not o.exists()


def test_interpolate_laplace_is_2d_only(tmp_path, capsys):
    rng = np.random.default_rng(5)
    p = rng.random((40, 3))
    np.savetxt(tmp_path / "n3.csv", np.c_[p, p.sum(axis=1)], delimiter=",")
    np.savetxt(tmp_path / "q3.csv", [[0.5, 0.5, 0.5]], delimiter=",")
    err = user_error(["interpolate", str(tmp_path / "n3.csv"), str(tmp_path / "q3.csv"),
                      "--dim", "3", "--method", "laplace"], capsys)
    assert "'laplace' works in 2D only; in 3D: sibson, sibson1, farin, linear, nearest" in err


def test_first_run_notice(tmp_path, monkeypatch, capsys):
    from skfem_nem.apps import cli as cli
    from pathlib import Path
    package = Path(cli.__file__).resolve().parents[1]
    for dim in (2, 3):
        for module in cli.FIRST_KERNELS[dim]:  # the names follow the package's layout
            assert (package / f"{module}.py").exists(), module
        assert not cli.kernels_cached(tmp_path, dim=dim)
        for k, module in enumerate(cli.FIRST_KERNELS[dim]):
            assert not cli.kernels_cached(tmp_path, dim=dim)
            folder = tmp_path / module.split("/")[0] / "__pycache__"
            folder.mkdir(parents=True, exist_ok=True)
            (folder / f"{module.split('/')[1]}.kernel-{k}.py311.nbi").write_text("")
        assert cli.kernels_cached(tmp_path, dim=dim)
    # the 2D kernels cached say nothing of the 3D ones
    (tmp_path / "models" / "__pycache__" / "condensation_tet.kernel-2.py311.nbi").unlink()
    assert cli.kernels_cached(tmp_path, dim=2) and not cli.kernels_cached(tmp_path, dim=3)
    # a cache kept elsewhere (NUMBA_CACHE_DIR) is where the kernels are looked for
    import numba
    elsewhere = tmp_path / "elsewhere"
    monkeypatch.setattr(numba.config, "CACHE_DIR", str(elsewhere))
    assert not cli.kernels_cached(tmp_path, dim=2)
    for module in cli.FIRST_KERNELS[2]:
        folder = elsewhere / f"{module.split('/')[0]}_0123abcd"
        folder.mkdir(parents=True, exist_ok=True)
        (folder / f"{module.split('/')[1]}.kernel-0.py311.nbi").write_text("")
    assert cli.kernels_cached(tmp_path, dim=2) and not cli.kernels_cached(tmp_path, dim=3)
    monkeypatch.undo()
    # the command says so before the first step when the cache is empty, with the
    # plate's own estimate
    asked = []
    monkeypatch.setattr(cli, "kernels_cached",
                        lambda folder=None, dim=2: asked.append(dim) or False)
    assert main(["sinking-plate", "-o", str(tmp_path / "run"), "--nodes", "300",
                 "--end-time", "1", "--quiet"]) == 0
    assert "compiling the numerical kernels (about half a minute, once)" in \
        capsys.readouterr().out and asked == [2]
    monkeypatch.setattr(cli, "kernels_cached", lambda folder=None, dim=2: True)
    assert main(["sinking-plate", "-o", str(tmp_path / "run2"), "--nodes", "300",
                 "--end-time", "1", "--quiet"]) == 0
    assert "compiling" not in capsys.readouterr().out


def test_sinking_plate_help_states_each_default_once(capsys):
    """Every parameter's help names its built-in default once; nothing says
    "default: None" (the command line's marker for "not given") or a flag's False."""
    from dataclasses import fields

    from skfem_nem.apps.sinking_plate import PlateConfig
    with pytest.raises(SystemExit) as exc:
        main(["sinking-plate", "--help"])
    assert exc.value.code == 0
    text = re.sub(r"\s+", " ", capsys.readouterr().out)
    assert "default: None" not in text and "default: False" not in text
    assert "(default: out/sinking-plate)" in text
    section = text.split("the --dim 3 default):")[1]
    # one block per option: "--flag METAVAR help" or "--flag, --no-flag help"
    blocks = re.split(r" (?=--[a-z-]+ [A-Z_]{2,} |--[a-z-]+, --no-)", " " + section)

    def block(name):
        flag = "--" + name.replace("_", "-")
        part, = [b for b in blocks if b.startswith(flag + " ") or b.startswith(flag + ",")]
        assert part.count("(default") == 1, part
        return part

    from skfem_nem.apps.plate3d_config import Plate3DConfig
    three = {f.name: getattr(Plate3DConfig, f.name) for f in fields(Plate3DConfig)}
    for f in fields(PlateConfig):
        part = block(f.name)
        d2 = getattr(PlateConfig, f.name)
        assert f"(default {d2})" in part, part
        d3 = three.pop(f.name, None)
        tail = "[2D only]" if d3 is None else "[3D: same]" if d3 == d2 else f"[3D: {d3}]"
        assert tail in part, (part, tail)
    for name, d3 in three.items():      # the 3D plate's own
        assert f"[3D only] (default {d3})" in block(name)
