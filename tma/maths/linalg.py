"""Small batched linear algebra on stacks of symmetric matrices ``(n, k, k)``."""

import numpy as np


def jacobi_scaled_eigh(H):
    """Eigen-decompose ``D^-1 H D^-1`` with ``D = sqrt(diag H)`` (unit diagonal).

    Scaling makes definiteness tests and solves independent of units (metres vs m/s).
    Returns ``(w, V, d)``: eigenvalues, eigenvectors, the scale ``d``.
    """
    d = np.sqrt(np.einsum("nii->ni", H))
    d = np.where(d > 0, d, 1.0)
    w, V = np.linalg.eigh(H / (d[:, :, None] * d[:, None, :]))
    return w, V, d


def solve_shifted(w, V, d, g, shift):
    """Solve ``(H + shift * diag(H)) x = g`` per matrix from ``jacobi_scaled_eigh(H)``."""
    coeff = np.einsum("nji,nj->ni", V, g / d) / (w + np.asarray(shift)[:, None])
    return np.einsum("nij,nj->ni", V, coeff) / d


def scaled_inverse(H, rcond):
    """``H^-1`` per symmetric matrix ``(n, k, k)``, inverted in the diagonally scaled
    (unit-free, well-conditioned) form; returns ``(inverse, singular)``. ``singular``: the
    matrix is not finite or its scaled eigenvalue ratio is <= ``rcond``; its inverse is NaN."""
    finite = np.isfinite(H).all(axis=(1, 2))
    w, V, d = jacobi_scaled_eigh(np.where(finite[:, None, None], H, np.eye(H.shape[-1])))
    singular = ~finite | ~(w[:, 0] > rcond * np.abs(w[:, -1]))
    inv_w = 1.0 / np.where(singular[:, None], 1.0, w)
    inverse = np.einsum("nij,nj,nkj->nik", V, inv_w, V) / (d[:, :, None] * d[:, None, :])
    inverse[singular] = np.nan
    return inverse, singular
