"""SVD compression of the VDM and MVM with a shared weight function (paper §3.3).

``A = [A_VDM, A_MVM]`` has rows (phi, y, x) and columns (c, theta) for the VDM block and
(c) for the MVM block.  ``A = U S E^T = W E^T``; with the eigenvectors E of ``A^T A``
(float64, at most ~150 x 150) the weights are ``W = A E``, and

    d_VDM(x, y, theta, phi, c)  = sum_{i < svd_terms} W^i(x, y, phi) E_VDM^i(theta, c)
    theta_MVM(x, y, phi, c)     = sum_{i < mvm_terms} W^i(x, y, phi) E_MVM^i(c)

share the first weight columns.  ``A^T A`` is accumulated over row chunks (float32
products, float64 sums) so the 524k x 144 matrix is never copied to float64.
"""
from __future__ import annotations

import contextlib
import ctypes
import glob
import os
from dataclasses import dataclass

import numpy as np

CHUNK_ROWS = 1 << 18


def _openblas():
    """NumPy's bundled OpenBLAS (ctypes handle) or None."""
    folder = os.path.join(os.path.dirname(np.__file__), os.pardir, "numpy.libs")
    for path in glob.glob(os.path.join(folder, "libscipy_openblas*.so*")):
        try:
            lib = ctypes.CDLL(path)
            lib.scipy_openblas_get_num_threads64_.restype = ctypes.c_int
            return lib
        except (OSError, AttributeError):
            continue
    return None


@contextlib.contextmanager
def single_threaded_blas():
    """Run NumPy's BLAS on one thread inside the block (restored afterwards).

    On a shared 2-core machine a multi-threaded OpenBLAS GEMM next to Dr.Jit's worker
    threads (or other processes) was measured to swing from 0.1 s to 10 s; one thread is
    0.1-0.4 s for the 524k x 144 Gram matrix, every time.  Without the bundled OpenBLAS
    (other NumPy builds) this does nothing.
    """
    lib = _openblas()
    if lib is None:
        yield
        return
    old = lib.scipy_openblas_get_num_threads64_()
    lib.scipy_openblas_set_num_threads64_(1)
    try:
        yield
    finally:
        lib.scipy_openblas_set_num_threads64_(old)


@dataclass
class Compressed:
    """Eigen-decomposition of A and the weights of its leading eigen-functions.

    Attributes:
        weights: (n_rows, k_stored) float32, W = A E[:, :k_stored].
        eigvecs: (n_cols, n_cols) float64, columns sorted by decreasing eigenvalue.
        eigvals: (n_cols,) float64 eigenvalues of A^T A (squared singular values).
        n_vdm_cols: columns of the VDM block (n_c * n_theta); the rest is the MVM block.
    """

    weights: np.ndarray
    eigvecs: np.ndarray
    eigvals: np.ndarray
    n_vdm_cols: int

    @property
    def k_stored(self) -> int:
        return self.weights.shape[1]

    def check_terms(self, svd_terms: int, mvm_terms: int) -> None:
        """ValueError naming the parameter if a term count is outside [1, k_stored]."""
        for name, k in (("svd_terms", svd_terms), ("mvm_terms", mvm_terms)):
            if int(k) != k or not 1 <= k <= self.k_stored:
                raise ValueError(f"vdm: '{name}' must be an integer in [1, {self.k_stored}], got {k}")

    def eigen_functions(self, svd_terms: int, mvm_terms: int) -> tuple[np.ndarray, np.ndarray]:
        """(E_VDM, E_MVM) float32 of shapes (n_vdm_cols, K) and (n_mvm_cols, K) with
        K = max(svd_terms, mvm_terms) and columns beyond each block's term count zeroed."""
        self.check_terms(svd_terms, mvm_terms)
        k = max(svd_terms, mvm_terms)
        e = self.eigvecs[:, :k].astype(np.float32)
        e_vdm, e_mvm = e[:self.n_vdm_cols].copy(), e[self.n_vdm_cols:].copy()
        e_vdm[:, svd_terms:] = 0.0
        e_mvm[:, mvm_terms:] = 0.0
        return e_vdm, e_mvm

    def reconstruct(self, svd_terms: int, mvm_terms: int, rows=slice(None)) -> np.ndarray:
        """Reconstructed A[rows] (float32) from the leading terms."""
        e_vdm, e_mvm = self.eigen_functions(svd_terms, mvm_terms)
        w = self.weights[rows, :e_vdm.shape[1]]
        return np.concatenate([w @ e_vdm.T, w @ e_mvm.T], axis=1)

    def nbytes(self, svd_terms: int, mvm_terms: int) -> int:
        """Bytes of the compressed representation (float32 W and E) at these term counts."""
        k = max(svd_terms, mvm_terms)
        n_mvm_cols = self.eigvecs.shape[0] - self.n_vdm_cols
        return 4 * (self.weights.shape[0] * k + self.n_vdm_cols * svd_terms + n_mvm_cols * mvm_terms)


def gram(A: np.ndarray) -> np.ndarray:
    """A^T A in float64, accumulated over row chunks of float32 products."""
    n = A.shape[1]
    g = np.zeros((n, n), np.float64)
    for start in range(0, A.shape[0], CHUNK_ROWS):  # chunks of 65k rows, not elements
        block = A[start:start + CHUNK_ROWS]
        g += (block.T @ block).astype(np.float64)
    return g


def compress(A: np.ndarray, n_vdm_cols: int, k_stored: int) -> Compressed:
    """Eigen-decomposition of A^T A and the weights of the ``k_stored`` leading terms.

    Args:
        A: (n_rows, n_cols) float32, finite.
        n_vdm_cols: columns of the VDM block.
        k_stored: weight columns kept (clamped to n_cols).
    """
    if not np.all(np.isfinite(A)):
        raise ValueError("vdm: the table to compress holds NaN/Inf entries")
    with single_threaded_blas():
        g = gram(A)
    vals, vecs = np.linalg.eigh(g)
    order = np.argsort(vals)[::-1]
    vals, vecs = np.maximum(vals[order], 0.0), vecs[:, order]
    # a deterministic sign per eigen-function (the largest |entry| positive)
    signs = np.sign(vecs[np.argmax(np.abs(vecs), axis=0), np.arange(vecs.shape[1])])
    vecs = vecs * np.where(signs == 0, 1.0, signs)
    k = min(k_stored, A.shape[1])
    with single_threaded_blas():
        weights = (A @ vecs[:, :k].astype(np.float32)).astype(np.float32)
    return Compressed(weights=weights, eigvecs=vecs, eigvals=vals, n_vdm_cols=n_vdm_cols)
