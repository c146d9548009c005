"""Checks and layouts of a neuron's covariance P_i (eq. 10) as the core
stores it, shared by the identifier and the state file: the packed upper
triangle unpacked bit for bit, and the test for a matrix that is clearly not
positive semi-definite."""
from __future__ import annotations

import numpy as np

__all__ = ["clearly_indefinite", "unpacked"]


def clearly_indefinite(P: np.ndarray) -> float | None:
    """The smallest eigenvalue of the symmetric covariance ``P`` if it is
    clearly negative, else None. P_i is a covariance (eq. 10), but one the
    filter itself produced may sit a rounding error below semi-definite, so
    only what is negative beyond L ulps of P's largest eigenvalue, at P's
    own dtype, counts."""
    eig = np.linalg.eigvalsh(P.astype(np.float64))
    eps = float(np.finfo(P.dtype).eps) if P.dtype.kind == "f" else float(np.finfo(np.float64).eps)
    if eig[0] < -P.shape[0] * eps * float(np.max(np.abs(eig))):
        return float(eig[0])
    return None


def unpacked(p: np.ndarray, L: int) -> np.ndarray:
    """The symmetric matrix of a packed upper triangle, every entry's bits
    as stored (a -0 stays -0: P + P.T would turn it into +0)."""
    P = np.zeros((L, L), dtype=p.dtype)
    P[np.triu_indices(L)] = p
    lower = np.tril_indices(L, -1)
    P[lower] = P.T[lower]
    return P
