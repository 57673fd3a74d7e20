"""The random-intercept model behind :mod:`hcid.analysis.effects` (SPEC 13; pure numerical core):
its REML fit, the fixed effects' model-based covariance and the cluster-robust one (CR2) with its
Satterthwaite degrees of freedom, and the subject-mean columns that make an effect the
within-subject one."""

from __future__ import annotations

import warnings

import numpy as np
from scipy import optimize
from statsmodels.regression.mixed_linear_model import MixedLM, MixedLMParams
from statsmodels.tools.sm_exceptions import ConvergenceWarning

__all__ = ["DEGENERATE", "WARNINGS", "cluster_robust", "fe_covariance", "fit_reml", "with_subject_means"]

#: The share of its unbiased value (the bread's diagonal, under the working model) below which a
#: coefficient's CR2 sandwich has lost directions to the pseudo-inverse of ``I - H_gg`` (a contrast
#: that one subject alone carries, or two on the CPHS recordings): there it is 0 or biased low,
#: its Satterthwaite dof rounding noise, and the effect's interval is the wider rule's.
DEGENERATE = 1 - 1e-6
#: statsmodels' warnings that do not mean a failed fit, and how an effect's note says them.
WARNINGS = {"on the boundary": "subjects' variance near 0", "not positive definite": "Hessian not definite"}


def with_subject_means(design: np.ndarray, columns, groups: np.ndarray, w: np.ndarray) -> np.ndarray:
    """The design with, for each of ``columns`` that varies within subjects, each run's subject's
    ``w``-weighted mean of it (Mundlak, Econometrica 46, 1978): the column's effect is then the
    within-subject one, as with a fixed effect per subject, and the random intercept keeps the
    subjects' spread. Without it, REML's random intercept also compares subjects with each other,
    biased where the runs left out depend on the subject (a subject's runs at a level all
    undetermined: only its reference runs stay). A mean that adds no rank (every subject with the
    same weighted share of the level, as in a complete balanced design without se) is not added:
    there the random intercept's estimate already is the within-subject one."""
    sw = np.bincount(groups, w)
    rank = np.linalg.matrix_rank(design)
    for j in columns:
        mean = (np.bincount(groups, w * design[:, j]) / sw)[groups]
        widened = np.column_stack([design, mean])
        if np.linalg.matrix_rank(widened) > rank:
            design, rank = widened, rank + 1
    return design


def fe_covariance(model: MixedLM, result, groups: np.ndarray) -> np.ndarray:
    """The fixed effects' covariance ``scale (X' V^-1 X)^-1`` at the REML variances, as lme4 and nlme
    give it (statsmodels' ``bse_fe`` inverts the Hessian of all parameters, singular where the subjects'
    variance is near 0); per subject ``V = I + psi z z'``, inverted by Sherman-Morrison."""
    x, z, psi = model.exog, model.exog_re[:, 0], float(result.cov_re_unscaled[0, 0])
    one_hot = np.eye(groups.max() + 1)[groups]
    zx, zz = one_hot.T @ (z[:, None] * x), one_hot.T @ z**2
    return result.scale * np.linalg.inv(x.T @ x - (zx.T * (psi / (1 + psi * zz))) @ zx)


def cluster_robust(model: MixedLM, result, groups: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The fixed effects' cluster-robust covariance by subject, Bell and McCaffrey's CR2 (Survey
    Methodology 28, 2002; Pustejovsky and Tipton, JBES 36, 2018), and each coefficient's
    Satterthwaite degrees of freedom. The sandwich of the REML fit's working covariance (per
    subject ``V = I + psi z z'``) with each subject's whitened residuals scaled by ``(I -
    H_gg)^(-1/2)``, ``H_gg`` its block of the whitened hat matrix: valid whatever the runs'
    covariance within a subject, unbiased where the working model is right. A coefficient's
    variance is ``sum_g (q_g' y)^2`` (``y`` whitened), whose dof under the working model is
    ``tr(G)^2 / tr(G^2)``, ``G`` the Gram matrix ``q_g' q_h``: ``subjects - 1`` on a balanced paired
    design (where :func:`fe_covariance`, the slow reference, equals the covariance). Unbiased
    means ``tr(G)`` equals the bread's diagonal; where the pseudo-inverse lost directions (a
    contrast one subject alone carries) it falls short, and the dof are NaN (:data:`DEGENERATE`)."""
    x, y, z = model.exog, model.endog, model.exog_re[:, 0]
    psi = float(result.cov_re_unscaled[0, 0])
    beta = np.asarray(result.fe_params)
    members = [np.flatnonzero(groups == g) for g in range(groups.max() + 1)]
    xw, uw = np.empty_like(x), np.empty_like(y)
    for rows in members:
        vals, vecs = np.linalg.eigh(np.eye(rows.size) + psi * np.outer(z[rows], z[rows]))
        root_inv = (vecs / np.sqrt(vals)) @ vecs.T
        xw[rows], uw[rows] = root_inv @ x[rows], root_inv @ (y[rows] - x[rows] @ beta)
    bread = np.linalg.inv(xw.T @ xw)
    residual = np.eye(y.size) - xw @ bread @ xw.T  # whitened residuals = residual @ whitened y
    meat = np.zeros_like(bread)
    q = np.empty((len(members), y.size, bread.shape[0]))
    for g, rows in enumerate(members):
        vals, vecs = np.linalg.eigh(residual[np.ix_(rows, rows)])
        scale = np.where(vals > 1e-10, 1 / np.sqrt(np.clip(vals, 1e-10, None)), 0.0)
        adjust = (vecs * scale) @ vecs.T
        contribution = xw[rows].T @ adjust @ uw[rows]
        meat += np.outer(contribution, contribution)
        q[g] = residual[:, rows] @ adjust @ xw[rows] @ bread  # coefficient j's term: (q[g][:, j] . y)^2
    gram = np.einsum("gnj,hnj->jgh", q, q)
    expected = np.trace(gram, axis1=1, axis2=2)  # the variance's mean under the working model
    with np.errstate(invalid="ignore", divide="ignore"):
        dof = expected**2 / np.einsum("jgh,jgh->j", gram, gram)
    dof[~(expected >= DEGENERATE * np.diag(bread))] = np.nan  # directions lost: no dof to read
    return bread @ meat @ bread, dof


def fit_reml(model: MixedLM):
    """The REML fit and a note (statsmodels' warnings), None where no maximum is found; where the optimizer
    stops early, the REML maximum over the variance ratio by a grid and Brent's bounded search."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = model.fit(reml=True)
        note = ""
        if not result.converged:

            def minus_llf(root: float) -> float:
                params = MixedLMParams.from_components(cov_re=np.array([[root**2]]))
                return -model.loglike(params, profile_fe=True)

            grid = np.r_[1e-6, np.logspace(-3, 2, 26)]
            best = int(np.argmin([minus_llf(t) for t in grid]))
            if best == grid.size - 1:
                return None, "the subjects' variance grows without bound"
            bounds = (0.0, grid[best + 1]) if best == 0 else (grid[best - 1], grid[best + 1])
            root = optimize.minimize_scalar(minus_llf, bounds=bounds, method="bounded").x
            start = MixedLMParams.from_components(np.zeros(model.k_fe), np.array([[root**2]]))
            free = MixedLMParams.from_components(np.ones(model.k_fe), np.zeros((1, 1)))
            result = model.fit(reml=True, start_params=start, free=free)
            note = "REML maximum by a bounded search over the variance ratio"
    said = " ".join(str(w.message) for w in caught if issubclass(w.category, ConvergenceWarning))
    extra = [text for flag, text in WARNINGS.items() if flag in said]
    return result, "; ".join([note, *extra] if note else extra)
