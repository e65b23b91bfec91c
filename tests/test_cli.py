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
    r = np.loadtxt(out, delimiter=",", skiprows=1)
    lin = 2 * q[:, 0] - q[:, 1] + 1
    np.testing.assert_allclose(r[:, 2], lin, atol=1e-12)   # linear precision
    np.testing.assert_allclose(r[:, 3], 3 * lin, atol=1e-12)
    np.testing.assert_allclose(r[:, 4], 2, atol=1e-10)     # df/dx
    np.testing.assert_allclose(r[:, 7], -3, atol=1e-10)    # dg/dy


def test_interpolate_errors(tmp_path, capsys):
    def user_error(argv):
        with pytest.raises(SystemExit) as exc:
            main(argv)
        assert exc.value.code == 2
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0, err
        return err

    (tmp_path / "n.csv").write_text("x,y,f\n0,0,1\n1,0,1\n0,1,1\n")
    (tmp_path / "q.csv").write_text("2,2\n")
    assert re.search(r"outside the convex hull.*x\[0\]", user_error(
        ["interpolate", str(tmp_path / "n.csv"), str(tmp_path / "q.csv"), "-o",
         str(tmp_path / "o.csv")]))
    (tmp_path / "bad.csv").write_text("x,y,f\n0,0,1\n1,zero,1\n")
    assert "line 2 is not numeric" in user_error(
        ["interpolate", str(tmp_path / "bad.csv"), str(tmp_path / "q.csv")])
    assert "cannot read nodes" in user_error(
        ["interpolate", str(tmp_path / "missing.csv"), str(tmp_path / "q.csv")])
    (tmp_path / "nan.csv").write_text("x,y,f\n0,0,1\n1,0,nan\n0,1,1\n")
    (tmp_path / "q1.csv").write_text("0.2,0.2\n")
    assert "line 2 holds a value that is not finite" in user_error(
        ["interpolate", str(tmp_path / "nan.csv"), str(tmp_path / "q1.csv")])
    out = tmp_path / "no" / "such" / "folder" / "o.csv"
    assert "cannot write output file" in user_error(
        ["interpolate", str(tmp_path / "n.csv"), str(tmp_path / "q1.csv"), "-o", str(out)])


def test_first_run_notice(tmp_path, monkeypatch, capsys):
    from skfem_nem.apps import cli as cli
    from pathlib import Path
    package = Path(cli.__file__).resolve().parents[1]
    for module in cli.FIRST_KERNELS:  # the names follow the package's layout
        assert (package / f"{module}.py").exists(), module
    assert not cli.kernels_cached(tmp_path)
    for k, module in enumerate(cli.FIRST_KERNELS):
        assert not cli.kernels_cached(tmp_path)
        folder = tmp_path / module.split("/")[0] / "__pycache__"
        folder.mkdir(parents=True)
        (folder / f"{module.split('/')[1]}.kernel-{k}.py311.nbi").write_text("")
    assert cli.kernels_cached(tmp_path)
    # the command says so before the first step when the cache is empty
    monkeypatch.setattr(cli, "kernels_cached", lambda folder=None: False)
    assert main(["sinking-plate", "-o", str(tmp_path / "run"), "--nodes", "300",
                 "--end-time", "1", "--quiet"]) == 0
    assert "compiling the numerical kernels" in capsys.readouterr().out
    monkeypatch.setattr(cli, "kernels_cached", lambda folder=None: True)
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
