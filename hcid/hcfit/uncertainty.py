"""Standard errors of a least-squares fit: the Gauss-Newton covariance and a lag-window sandwich.

With residuals ``r`` (n,) and their Jacobian ``J`` (n, p) at the optimum:

- ``gauss_newton``: ``cov = s^2 (J^T J)^-1``, ``s^2 = sum r^2 / (n - p)``: the
  Cramer-Rao bound when the residuals are white and Gaussian.
- ``sandwich``: ``cov = n/(n - p) B M B`` with ``B = (J^T J)^-1`` and
  ``M = sum_{|l| <= L} w_l sum_t g_t g_{t-l}^T``, ``g_t = J_t r_t``, Bartlett weights
  ``w_l = 1 - |l|/(L + 1)`` (Newey and West 1987): right also when the residuals
  are coloured, as a remnant seen through the loop is, provided their
  correlation dies out within ``L`` samples.

Parameters on a bound are left out (their standard error is NaN): the
quadratic approximation behind both formulas does not hold there. Parameters the
residuals cannot tell apart get an infinite standard error (see :func:`covariance`).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from hcid.errors import IdentificationError

__all__ = ["COVARIANCES", "Z95", "covariance", "jacobian", "strongest_correlations"]

COVARIANCES = ("sandwich", "gauss_newton")
#: The standard normal's 97.5% quantile: a 95% interval is ``estimate +- Z95 se``.
Z95 = 1.959963984540054


def jacobian(
    residuals: Callable[[np.ndarray], np.ndarray],
    x: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    free: np.ndarray,
) -> np.ndarray:
    """Central-difference Jacobian (n, n_free) of ``residuals`` at ``x`` over the free parameters.

    The step is ``1e-4 max(|x_i|, 0.01 (upper_i - lower_i))`` each way, cut short at a
    bound (the difference then spans the shorter interval).
    """
    columns = []
    for i in np.flatnonzero(free):
        h = 1e-4 * max(abs(x[i]), 0.01 * (upper[i] - lower[i]))
        hi, lo = min(x[i] + h, upper[i]), max(x[i] - h, lower[i])
        xp, xm = x.copy(), x.copy()
        xp[i], xm[i] = hi, lo
        columns.append((residuals(xp) - residuals(xm)) / (hi - lo))
    return np.column_stack(columns) if columns else np.zeros((residuals(x).size, 0))


def covariance(kind: str, jac: np.ndarray, r: np.ndarray, lag: int = 0) -> np.ndarray:
    """Covariance (p, p) of the estimates from the Jacobian ``jac`` (n, p) and residuals ``r`` (n,).

    ``kind`` is ``gauss_newton`` or ``sandwich`` (``lag`` samples of Bartlett
    window). ``J^T J`` is inverted through the SVD of J with unit columns: a
    direction of the parameters the residuals do not see (a singular value below
    1e-8 of the largest, e.g. TL and tau_pe when TL is near 0, ``TL s + 1 ~ exp(s TL)``)
    is left out, and the parameters that move along it get an infinite variance
    (the record does not determine them); the others keep theirs. NaN throughout
    when ``n <= p``.

    Examples
    --------
    A straight line through four points (the textbook OLS covariance):

    >>> jac = np.column_stack([np.ones(4), np.arange(4.0)])
    >>> r = np.array([0.1, -0.2, 0.2, -0.1])
    >>> bool(np.allclose(covariance("gauss_newton", jac, r), 0.05 * np.linalg.inv(jac.T @ jac)))
    True
    """
    if kind not in COVARIANCES:
        raise IdentificationError(f"kind: must be one of {COVARIANCES}, got {kind!r}")
    n, p = jac.shape
    if p == 0:
        return np.zeros((0, 0))
    if n <= p or not np.all(np.isfinite(jac)):
        return np.full((p, p), np.nan)
    norms = np.linalg.norm(jac, axis=0)
    norms = np.where(norms > 0, norms, 1.0)
    _, sing, vt = np.linalg.svd(jac / norms, full_matrices=False)
    kept = sing > 1e-8 * sing[0]
    v = vt[kept].T / sing[kept]
    bread = (v @ v.T) / np.outer(norms, norms)  # (J^T J)^+ in the parameters' units
    if kind == "gauss_newton":
        cov = float(r @ r) / (n - p) * bread
    else:
        g = jac * r[:, None]
        meat = g.T @ g
        for lag_l in range(1, min(lag, n - 1) + 1):
            gamma = g[lag_l:].T @ g[:-lag_l]
            meat += (1.0 - lag_l / (lag + 1.0)) * (gamma + gamma.T)
        cov = n / (n - p) * bread @ meat @ bread
    # Parameters along a left-out direction: not determined by these residuals.
    lost = np.any(np.abs(vt[~kept]) > 0.1, axis=0) if (~kept).any() else np.zeros(p, dtype=bool)
    cov[lost, :] = np.nan
    cov[:, lost] = np.nan
    cov[lost, lost] = np.inf
    return cov


def strongest_correlations(cov: np.ndarray, names: np.ndarray, size: int, free: np.ndarray):
    """Per parameter, the free parameter its estimate is most correlated with, and the correlation."""
    partner, correlation = ["" for _ in range(size)], [math.nan for _ in range(size)]
    d = np.sqrt(np.diag(cov)) if cov.size else np.zeros(0)
    ok = np.isfinite(d) & (d > 0)
    if ok.sum() < 2:
        return tuple(partner), tuple(correlation)
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(d, d)
    corr[~ok, :] = np.nan
    corr[:, ~ok] = np.nan
    np.fill_diagonal(corr, np.nan)
    positions = np.flatnonzero(free)
    for i in range(corr.shape[0]):
        if not ok[i]:
            continue
        j = int(np.nanargmax(np.abs(corr[i])))
        partner[positions[i]] = str(names[j])
        correlation[positions[i]] = float(corr[i, j])
    return tuple(partner), tuple(correlation)
