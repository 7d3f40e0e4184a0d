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
