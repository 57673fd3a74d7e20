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
quadratic approximation behind both formulas does not hold there.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

__all__ = ["COVARIANCES", "Z95", "covariance", "jacobian"]

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

    The step is ``1e-4 max(|x_i|, 0.01 (upper_i - lower_i))``; a step that would
    leave the bounds is taken one-sided.
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
    window). NaN throughout when ``J^T J`` is singular or ``n <= p``.

    Examples
    --------
    A straight line through four points (the textbook OLS covariance):

    >>> jac = np.column_stack([np.ones(4), np.arange(4.0)])
    >>> r = np.array([0.1, -0.2, 0.2, -0.1])
    >>> bool(np.allclose(covariance("gauss_newton", jac, r), 0.05 * np.linalg.inv(jac.T @ jac)))
    True
    """
    n, p = jac.shape
    if p == 0:
        return np.zeros((0, 0))
    if n <= p:
        return np.full((p, p), np.nan)
    jtj = jac.T @ jac
    try:
        bread = np.linalg.inv(jtj)
    except np.linalg.LinAlgError:
        return np.full((p, p), np.nan)
    if not np.all(np.isfinite(bread)) or np.linalg.cond(jtj) > 1e14:
        return np.full((p, p), np.nan)
    if kind == "gauss_newton":
        return float(r @ r) / (n - p) * bread
    if kind != "sandwich":
        raise ValueError(f"kind: must be one of {COVARIANCES}, got {kind!r}")
    g = jac * r[:, None]
    meat = g.T @ g
    for lag_l in range(1, min(lag, n - 1) + 1):
        gamma = g[lag_l:].T @ g[:-lag_l]
        meat += (1.0 - lag_l / (lag + 1.0)) * (gamma + gamma.T)
    return n / (n - p) * bread @ meat @ bread
