"""Products with a symmetric matrix kept as its upper triangle
(:class:`skfem_nem.basis.symmetric_rows.SymmetricRows`), the Lanczos bound of the
Chebyshev smoother (:func:`skfem_nem.models.krylov.largest_eigenvalue`) and the finest
level of the viscous block's multigrid that uses both."""
import numpy as np
import pytest
import scipy.sparse as sps
from hypothesis import given, settings
from hypothesis import strategies as st

from skfem_nem.models.krylov import largest_eigenvalue
from skfem_nem.models.stokes_amg import ViscousAMG, scaled_block, unit_scale
from skfem_nem.basis.symmetric_rows import SymmetricRows


def _symmetric(n, density, seed, diagonal=True):
    """A random symmetric sparse matrix (rows may be empty, diagonal entries missing)."""
    M = sps.random(n, n, density=density, random_state=seed, format="csr")
    M = M + M.T
    if diagonal:
        M = M + sps.diags(np.random.default_rng(seed).random(n) + n)
    return sps.csr_matrix(M)


@settings(max_examples=40, deadline=None)
@given(n=st.integers(1, 80), density=st.floats(0.0, 0.5), seed=st.integers(0, 10_000),
       diagonal=st.booleans())
def test_products_are_scipys(n, density, seed, diagonal):
    A = _symmetric(n, density, seed, diagonal)
    S = SymmetricRows(A)
    x = np.random.default_rng(seed + 1).standard_normal(n)
    ref = A @ x
    assert np.allclose(S @ x, ref, rtol=1e-13, atol=1e-13 * (abs(A) @ abs(x)).max())
    assert S.nnz == sps.triu(A, 1).nnz + n
    assert np.array_equal(S @ x, S @ x)             # the same sums in the same order


def test_refresh_takes_new_values_and_a_new_pattern():
    A = _symmetric(60, 0.2, 1)
    S = SymmetricRows(A)
    x = np.random.default_rng(2).standard_normal(60)
    band = sps.diags([np.ones(59), np.ones(59)], [-1, 1])
    B = sps.csr_matrix(A + band)                     # new values, and a new pattern
    C = A.copy()
    C.data = 2 * C.data                              # the same pattern
    assert S.same_pattern(C) and not S.same_pattern(B)
    S.refresh(C)
    assert np.allclose(S @ x, C @ x, rtol=1e-13)
    S.refresh(B)
    assert np.allclose(S @ x, B @ x, rtol=1e-13)


def test_bad_input_is_named():
    with pytest.raises(ValueError, match=r"square matrix, got shape \(2, 3\)"):
        SymmetricRows(sps.csr_matrix(np.ones((2, 3))))
    S = SymmetricRows(sps.identity(4, format="csr"))
    with pytest.raises(ValueError, match=r"x of shape \(4,\), got \(3,\)"):
        S @ np.ones(3)


def test_largest_eigenvalue_is_an_upper_estimate():
    rng = np.random.default_rng(0)
    Q, _ = np.linalg.qr(rng.standard_normal((300, 300)))
    lam = np.r_[np.linspace(0.01, 1.0, 299), 1.3]
    A = (Q * lam) @ Q.T
    est = largest_eigenvalue(lambda v: A @ v, 300)
    assert 1.3 - 1e-12 <= est <= 1.3 * 1.05, est
    # an invariant subspace: a 3 x 3 operator is exact after three steps
    D = np.diag([1.0, 2.0, 5.0])
    assert abs(largest_eigenvalue(lambda v: D @ v, 3) - 5.0) < 1e-12


def test_the_finest_level_is_the_scaled_block():
    """The multigrid's finest products and Chebyshev bound come from the scaled block: a
    2D Laplacian of an elasticity-like pair of components."""
    n = 40
    L = sps.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(n, n))
    eta = sps.diags(np.sqrt(np.linspace(1, 100, 2 * n * n)))     # a viscosity ramp
    A = sps.csr_matrix(eta @ sps.kron(sps.identity(2), sps.kronsum(L, L)) @ eta)
    modes = np.kron(np.eye(2), np.ones((n * n, 1)))
    amg = ViscousAMG(A, modes)
    x = np.random.default_rng(3).standard_normal(A.shape[0])
    scaled = scaled_block(A, unit_scale(A))
    assert np.allclose(amg.fine @ x, scaled @ x, rtol=1e-13)
    rho = np.linalg.eigvalsh(scaled.toarray())[-1]
    assert amg.n_levels >= 2
    # the smoother's interval reaches past the spectrum: Chebyshev damps every mode
    est = largest_eigenvalue(amg.fine.matvec, A.shape[0])
    assert rho - 1e-10 <= est <= 1.05 * rho
    b = A @ x
    err = [np.linalg.norm(amg.cg(b, k) - x) / np.linalg.norm(x) for k in (1, 4, 12)]
    assert err[0] > err[1] > err[2] and err[2] < 1e-6, err


def test_a_hierarchy_made_over_the_blocks_values_is_the_same():
    """``overwrite``: the hierarchy made and refreshed over the block's own values cycles
    as the one made from a copy, and the block then holds the scaled block (no second
    copy); a block it cannot write over is named."""
    n = 30
    L = sps.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(n, n))
    eta = sps.diags(np.sqrt(np.linspace(1, 100, 2 * n * n)))
    A = sps.csr_matrix(eta @ sps.kron(sps.identity(2), sps.kronsum(L, L)) @ eta)
    modes = np.kron(np.eye(2), np.ones((n * n, 1)))
    b = np.random.default_rng(5).standard_normal(A.shape[0])
    copy = A.copy()
    kept, over = ViscousAMG(A, modes), ViscousAMG(copy, modes, overwrite=True)
    assert np.allclose(copy.toarray(), scaled_block(A, unit_scale(A)).toarray(), rtol=1e-15)
    assert np.array_equal(kept.cg(b, 3), over.cg(b, 3))
    assert np.array_equal(kept.matvec(b), over.matvec(b))
    A2 = sps.csr_matrix(2.0 * A + sps.identity(A.shape[0]))
    copy2 = A2.copy()
    kept.refresh(A2)
    over.refresh(copy2, overwrite=True)
    assert np.allclose(copy2.toarray(), scaled_block(A2, unit_scale(A2)).toarray(),
                       rtol=1e-15)
    assert np.array_equal(kept.cg(b, 3), over.cg(b, 3))
    # between solves the finest values go; a refresh brings them back, the same
    over.release_values()
    for call in (lambda: over.cg(b, 3), lambda: over.matvec(b), lambda: over.fine @ b):
        with pytest.raises(RuntimeError, match="values were let go"):
            call()
    copy3 = A2.copy()
    over.refresh(copy3, overwrite=True)
    kept.refresh(A2)
    assert np.array_equal(kept.cg(b, 3), over.cg(b, 3))
    with pytest.raises(ValueError, match="overwrite=True needs a CSR matrix of float64.*csc"):
        ViscousAMG(A.tocsc(), modes, overwrite=True)
    with pytest.raises(ValueError, match="overwrite=True needs a CSR matrix of float64.*"
                                         "float32"):
        over.refresh(A2.astype(np.float32), overwrite=True)
    assert np.array_equal(kept.cg(b, 3), over.cg(b, 3))      # (left as it was)


def test_the_pattern_is_read_from_the_triangle_not_kept_from_the_matrix():
    """``same_pattern`` holds no reference to the matrix's index arrays (a 3D viscous
    block's are 55 MB) and still tells a moved upper entry or a missing diagonal from new
    values."""
    A = _symmetric(50, 0.2, 4)
    S = SymmetricRows(A)
    held = [v for v in vars(S).values() if isinstance(v, np.ndarray)]
    assert not any(np.shares_memory(v, a) for v in held for a in (A.indices, A.indptr))
    assert S.source.dtype == np.int32                  # positions in 32 bits where they fit
    C = A.copy()
    C.data = 3 * C.data
    assert S.same_pattern(C) and S.same_pattern(sps.csr_matrix(A.toarray() + 0.0))
    U = sps.triu(A, 1).tocsr()
    i = int(np.flatnonzero(np.diff(U.indptr) > 0)[0])
    j = U.indices[U.indptr[i]]                            # an upper entry (i, j), j > i
    moved = A.tolil()
    moved[i, j], moved[j, i] = 0.0, 0.0
    free = next(c for c in range(i + 1, 50) if A[i, c] == 0)
    moved[i, free] = moved[free, i] = 1.0                 # the entry moved along its row
    moved = sps.csr_matrix(moved)
    moved.eliminate_zeros()
    assert not S.same_pattern(moved)
    no_diag = sps.csr_matrix(A - sps.diags(A.diagonal()))
    no_diag.eliminate_zeros()
    assert not S.same_pattern(no_diag)
    assert not S.same_pattern(A.tocsc())


def test_the_multigrid_keeps_no_finest_matrix():
    """Past its set-up (and a refresh) the hierarchy multiplies through its triangles only:
    no CSR copy of the scaled finest block stays, and a refresh that renews the coarse
    levels (from a finest matrix made again) gives a cycle that still reduces the
    residual."""
    n = 30
    L = sps.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(n, n))
    A = sps.csr_matrix(sps.kron(sps.identity(2), sps.kronsum(L, L)))
    modes = np.kron(np.eye(2), np.ones((n * n, 1)))
    amg = ViscousAMG(A, modes)
    assert amg.n_levels >= 2 and amg.ml.levels[0].A is None
    assert amg.same_pattern(A) and not amg.same_pattern(sps.csr_matrix(A + sps.eye(2 * n * n,
                                                                                   k=5)))
    A2 = sps.csr_matrix(A @ sps.diags(np.linspace(1, 5, 2 * n * n)))
    A2 = sps.csr_matrix(0.5 * (A2 + A2.T))
    amg.refresh(A2, coarse=True)
    assert amg.ml.levels[0].A is None
    b = np.random.default_rng(5).standard_normal(A.shape[0])
    x = amg.cycle(b)
    assert np.linalg.norm(A2 @ x - b) < 0.5 * np.linalg.norm(b)


def test_a_pattern_found_the_same_is_not_checked_again(monkeypatch):
    """The hierarchy checks a block's pattern, then refreshes its triangles and their twin
    from it: the index array found the same is remembered (weakly), not read three times."""
    import gc

    import skfem_nem.basis.symmetric_rows as rows
    A = _symmetric(40, 0.3, 7)
    S = SymmetricRows(A)
    calls = []
    check = rows._same_upper
    monkeypatch.setattr(rows, "_same_upper", lambda *a: calls.append(1) or check(*a))
    C = sps.csr_matrix((2 * A.data, A.indices.copy(), A.indptr.copy()), shape=A.shape)
    assert S.same_pattern(C)
    S.refresh(C)
    S.twin(C)
    assert len(calls) == 1
    D = sps.csr_matrix((A.data, C.indices.copy(), A.indptr), shape=A.shape)
    del C
    gc.collect()
    assert S._checked() is None          # not held
    assert S.same_pattern(D) and len(calls) == 2
