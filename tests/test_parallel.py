"""The parts of skfem_nem.parallel that need no PETSc: the error naming the installation
route when petsc4py is missing, finding Debian's PETSc, the row split, the strip
ordering of the Stokes unknowns, argument checks. The solves themselves are checked
against the serial solvers in tests/mpi, which the MPI step of CI runs under mpiexec
with 1, 2 and 4 ranks (the default run does not collect it; see pyproject.toml)."""
import pathlib
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from skfem_nem import delaunay_mesh
from skfem_nem.geometry.nodesets import box_nodes
from skfem_nem.models.stokes import outline_flux, solve_stokes, stokes_spaces
from skfem_nem.models.stokes_solvers import SOLVERS, StokesCache, check_solver, part_order
from skfem_nem.parallel import PETSC_INSTALL_HINT, PetscUnavailableError, solver_petsc
from skfem_nem.parallel import petsc as petsc_module
from skfem_nem.parallel.partition import Bisection
from skfem_nem.parallel.petsc import debian_petsc_dir, import_petsc, row_range
from skfem_nem.parallel.saddle import split_counts

ROOT = pathlib.Path(__file__).resolve().parents[1]


@pytest.fixture
def no_petsc(monkeypatch, tmp_path):
    """An interpreter without petsc4py: the import fails, PETSC_DIR points nowhere."""
    monkeypatch.setitem(sys.modules, "petsc4py", None)
    monkeypatch.delitem(sys.modules, "petsc4py.PETSc", raising=False)
    monkeypatch.setenv("PETSC_DIR", str(tmp_path / "no-petsc"))


def test_importing_the_package_does_not_import_petsc():
    code = "import sys, skfem_nem.parallel, skfem_nem.models.stokes; " \
           "print('petsc4py' in sys.modules, 'mpi4py' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=ROOT).stdout
    assert out.split() == ["False", "False"]


def test_missing_petsc_names_the_install_route(no_petsc):
    with pytest.raises(PetscUnavailableError) as err:
        import_petsc()
    msg = str(err.value)
    assert msg.startswith(PETSC_INSTALL_HINT)
    assert "apt-get install python3-petsc4py python3-mpi4py" in msg
    assert "--system-site-packages" in msg and "numpy<2" in msg and "PETSC_DIR" in msg
    assert isinstance(err.value, ImportError)


def test_solve_stokes_with_petsc_missing_raises_the_same(no_petsc):
    spaces = stokes_spaces(delaunay_mesh(box_nodes(60, seed=2)))
    with pytest.raises(PetscUnavailableError, match="apt-get install python3-petsc4py"):
        solve_stokes(spaces, 1.0, lambda x: [0 * x[0], -x[0]], solver="petsc")
    A = np.eye(3)
    with pytest.raises(PetscUnavailableError, match="docs/parallel.md"):
        solver_petsc()(A, np.ones(3))


def test_debian_petsc_is_found(monkeypatch, tmp_path):
    for version in ("petsc3.17", "petsc3.18"):
        (tmp_path / version / "x86_64-linux-gnu-real").mkdir(parents=True)
        (tmp_path / version / "x86_64-linux-gnu-complex").mkdir(parents=True)
    monkeypatch.setattr(petsc_module, "DEBIAN_PETSC_GLOB", str(tmp_path / "petsc*" / "*-real"))
    monkeypatch.delenv("PETSC_DIR", raising=False)
    assert debian_petsc_dir() == str(tmp_path / "petsc3.18" / "x86_64-linux-gnu-real")
    monkeypatch.setenv("PETSC_DIR", "/opt/petsc")
    assert debian_petsc_dir() == "/opt/petsc"
    monkeypatch.delenv("PETSC_DIR")
    monkeypatch.setattr(petsc_module, "DEBIAN_PETSC_GLOB", str(tmp_path / "none*"))
    assert debian_petsc_dir() is None


class FakeComm:
    """The two methods of a PETSc communicator that row_range reads."""

    def __init__(self, rank, size):
        self.rank, self.size = rank, size

    def getRank(self):
        return self.rank

    def getSize(self):
        return self.size


@pytest.mark.parametrize("n,size", [(10, 1), (10, 3), (7, 2), (2, 3)])
def test_rows_split_like_petsc(n, size):
    ranges = [row_range(n, FakeComm(r, size)) for r in range(size)]
    assert ranges[0][0] == 0 and ranges[-1][1] == n
    assert all(a[1] == b[0] for a, b in zip(ranges[:-1], ranges[1:]))
    sizes = [r1 - r0 for r0, r1 in ranges]
    assert max(sizes) - min(sizes) <= 1 and sizes == sorted(sizes, reverse=True)
    mask = np.arange(n) % 3 == 0
    assert split_counts(mask, size) == [int(mask[r0:r1].sum()) for r0, r1 in ranges]


def test_a_given_split_is_checked():
    assert row_range(10, FakeComm(1, 2), owned=[7, 3]) == (7, 10)
    with pytest.raises(ValueError, match=r"2 non-negative row counts adding up to 10, "
                                         r"got \[7, 2\]"):
        row_range(10, FakeComm(0, 2), owned=[7, 2])


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2 ** 31), n=st.integers(1, 400), dim=st.sampled_from([2, 3]),
       parts=st.integers(1, 9))
def test_bisection_parts_are_balanced(seed, n, dim, parts):
    """Random points (distinct coordinates): each part holds ``n / parts`` points to
    within one at every cut, so within the depth of the cuts; the cuts classify the same
    points the same way, and unplaced points come last."""
    x = np.random.default_rng(seed).random((dim, n))
    b = Bisection(x, parts)
    part = b.part(x)
    counts = np.bincount(part, minlength=parts)
    assert counts.size == parts and counts.sum() == n
    depth = int(np.ceil(np.log2(parts)))
    if n >= parts:
        assert np.abs(counts - n / parts).max() <= depth + 1, counts
    y = np.c_[x, np.full((dim, 1), np.nan)]
    assert np.array_equal(b.part(y), np.r_[part, parts])


def test_bisection_cuts_four_parts_of_a_square_in_quadrants():
    """Four parts of a square are its quadrants (two cuts, one along each axis), where
    strips would be four slabs along x; bad input is named."""
    g = np.linspace(0.05, 0.95, 10)
    x = np.array(np.meshgrid(g, g)).reshape(2, -1)
    part = Bisection(x, 4).part(x)
    for k in range(4):
        inside = x[:, part == k]
        assert inside.shape[1] == 25
        assert np.ptp(inside[0]) < 0.5 and np.ptp(inside[1]) < 0.5
    with pytest.raises(ValueError, match="parts must be a positive integer, got 0"):
        Bisection(x, 0)
    with pytest.raises(ValueError, match=r"finite \(dim, n\) array"):
        Bisection(np.c_[x, [np.inf, 0.0]], 2)


def test_part_order_keeps_parts_together():
    """Split in four, each quarter of the order holds the velocity and pressure
    unknowns of about one part of the square (a quadrant: the bisection's), in their
    order along x; a single part sorts them along x."""
    mesh = delaunay_mesh(box_nodes(300, seed=4))
    spaces = stokes_spaces(mesh)
    problem = _captured_problem(spaces)
    order = part_order(problem, 4)
    n = problem.n_velocity + problem.n_pressure
    assert np.array_equal(np.sort(order), np.arange(n))
    x = np.c_[spaces.ubasis.doflocs[:, problem.free], mesh.p]
    part = Bisection(mesh.p, 4).part(x)[order]
    assert np.all(np.diff(part) >= 0)
    for k in range(4):
        block = part[k * n // 4:(k + 1) * n // 4]
        assert np.count_nonzero(block == k) > 0.95 * block.size
    assert np.all(np.diff(x[0, part_order(problem)]) >= 0)


def _captured_problem(spaces, **kw):
    """The saddle-point problem ``solve_stokes`` hands to its solver."""
    class Captured(Exception):
        pass

    def capture(problem, tol, maxiter, info):
        raise Captured(problem)

    SOLVERS["capture"] = capture
    try:
        with pytest.raises(Captured) as got:
            solve_stokes(spaces, 1.0, lambda x: np.concatenate([0 * x[:-1], -x[:1]]),
                         solver="capture", **kw)
    finally:
        del SOLVERS["capture"]
    return got.value.args[0]


def test_part_order_of_one_part_keeps_strips_together():
    """Split in two, each half holds the velocity and pressure unknowns of one side of
    the square; constraint multipliers come last."""
    mesh = delaunay_mesh(box_nodes(200, seed=4))
    spaces = stokes_spaces(mesh)
    problem = _captured_problem(spaces, constraints=outline_flux(spaces, np.arange(4)))
    order = part_order(problem)
    n1, n = problem.n_velocity, problem.n_velocity + problem.n_pressure
    assert np.array_equal(np.sort(order), np.arange(n))
    assert order[-1] == n - 1                        # the multiplier
    x = np.r_[spaces.ubasis.doflocs[0, problem.free], mesh.p[0], np.inf][order]
    assert np.all(np.diff(x) >= 0)
    half = order[:n // 2]
    assert 0.3 * n1 < np.count_nonzero(half < n1) < 0.7 * n1


@pytest.mark.parametrize("dim", [2, 3])
def test_part_order_places_the_mini_bubbles_at_their_cells(dim):
    """scikit-fem puts the MINI bubbles at NaN; the strips take each at its cell's
    centroid, so the first half of the order holds about half of them (all went to the
    last rank before)."""
    from skfem_nem.geometry import box_nodes_3d
    mesh = delaunay_mesh(box_nodes(150, seed=4) if dim == 2 else box_nodes_3d(80, seed=4))
    spaces = stokes_spaces(mesh, "mini")
    problem = _captured_problem(spaces)
    order = part_order(problem)
    inner = np.asarray(spaces.ubasis.dofs.interior_dofs).ravel()
    bubble = np.zeros(spaces.ubasis.N, bool)
    bubble[inner] = True
    bubble = np.r_[bubble[problem.free], np.zeros(problem.n_pressure, bool)]
    first = np.count_nonzero(bubble[order[:order.size // 2]])
    assert 0.3 < first / np.count_nonzero(bubble) < 0.7
    centroid = mesh.p[0, mesh.t].mean(axis=0)
    xu = np.array(spaces.ubasis.doflocs[0])
    xu[np.asarray(spaces.ubasis.dofs.interior_dofs)] = centroid
    x = np.r_[xu[problem.free], mesh.p[0]][order]
    assert np.all(np.diff(x) >= 0)


def test_petsc_is_a_solver_without_cache():
    check_solver("petsc", None)
    with pytest.raises(ValueError, match="not by solver='petsc'"):
        check_solver("petsc", StokesCache())


def test_solver_petsc_checks_its_arguments_before_needing_petsc(no_petsc):
    with pytest.raises(ValueError, match="rtol must be a positive number, got 0"):
        solver_petsc(rtol=0)
    with pytest.raises(ValueError, match="maxiter must be a positive integer, got 2.5"):
        solver_petsc(maxiter=2.5)
    with pytest.raises(ValueError, match="'-ksp_monitor': give it without the leading '-'"):
        solver_petsc(options={"-ksp_monitor": ""})


def test_the_default_run_leaves_the_mpi_tests_to_the_mpi_step():
    """tests/mpi is not collected by ``python -m pytest`` (it would fail without
    petsc4py), and .ci/run runs it under mpiexec on 1, 2 and 4 ranks."""
    out = subprocess.run([sys.executable, "-m", "pytest", "--collect-only", "-q",
                          "-p", "no:cacheprovider", "tests/test_parallel.py", "tests"],
                         capture_output=True, text=True, cwd=ROOT).stdout
    assert "tests/mpi" not in out and "test_parallel.py" in out
    assert sorted(p.name for p in (ROOT / "tests" / "mpi").glob("test_*.py")) == \
        ["test_petsc_failures.py", "test_petsc_plate.py", "test_petsc_plate_3d.py",
         "test_petsc_solver.py", "test_petsc_stokes.py", "test_petsc_stokes_3d.py"]
    ci = (ROOT / ".ci" / "run").read_text()
    for ranks in (1, 2, 4):
        assert f"mpiexec --allow-run-as-root -n {ranks} python -m pytest" in ci
    assert "tests/mpi" in ci


@pytest.mark.parametrize("dim", ["2", "3"])
def test_the_sinking_plate_without_petsc_is_a_user_error(no_petsc, tmp_path, capsys, dim):
    """``--solver petsc`` where petsc4py is missing, in 2D and in 3D: exit status 2 and
    one line naming the installation route, no traceback, nothing written."""
    from skfem_nem.apps.cli import main
    out = tmp_path / "run"
    with pytest.raises(SystemExit) as stop:
        main(["sinking-plate", "--dim", dim, "--solver", "petsc", "--nodes", "300", "-o",
              str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert stop.value.code == 2 and len(err) == 1, err
    assert err[0].startswith("skfem-nem: sinking-plate: ") and "apt-get install" in err[0]
    assert "Traceback" not in err[0] and not out.exists()


@settings(max_examples=30, deadline=None)
@given(st.integers(1, 40), st.integers(0, 10**6), st.data())
def test_renumbered_rows_are_scipys_double_fancy_indexing(n, seed, data):
    """The rows a rank sends under a renumbering: one copy of those rows, equal to
    ``A[order][:, order]``'s rows, in canonical form."""
    import scipy.sparse as sp
    from skfem_nem.basis.locality import inverse_order, renumbered
    rng = np.random.default_rng(seed)
    A = sp.random(n, n, density=0.3, format="csr", random_state=rng)
    order = rng.permutation(n)
    a = data.draw(st.integers(0, n))
    b = data.draw(st.integers(a, n))
    got = renumbered(A, order[a:b], inverse_order(order))
    ref = A[order][:, order][a:b]
    assert got.shape == ref.shape and got.has_canonical_format
    assert (got != ref).nnz == 0
    assert np.array_equal(inverse_order(order)[order], np.arange(n))
