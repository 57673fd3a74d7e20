"""The frontier of a searched grid (private to :mod:`hcid.arx.engine`): each triple's best candidate
simulated as :func:`hcid.arx.simulation.simulate` does it (unfused), its V and VAFs, and the
:class:`~hcid.arx.gridfit.GridFit` they make."""

import numpy as np
import pyarrow as pa

from hcid.arx import _blocks, _kernels, _lanes
from hcid.arx.grid import n_parameters
from hcid.arx.gridfit import GridFit

# Frontier rows whose squared errors are held at once for their VAF (a
# few MB, so that they stay in cache instead of paging in a stage-1
# frontier's 90 MB).
_VAF_ROWS = 128


def grid_fit(
    grid, blocks, candidate_orders, first, searched, v_all, theta_all, scores, keep_candidates
) -> GridFit:
    """The :class:`GridFit` of the searched grid: each triple's best candidate (``first``) and its
    scores; a triple not ``searched`` to its end (``best_only``) has none."""
    block_na, block_nb1, block_nb2, start = blocks
    cand_na, cand_nb1, cand_nb2, cand_nk1, cand_nk2 = candidate_orders
    v, vaf_est, vaf_val = scores
    unstable = ~np.isfinite(v_all)
    fitted = np.isfinite(v_all[first]) & searched
    nk1 = np.where(fitted, cand_nk1[first], -1)
    nk2 = np.where(fitted, cand_nk2[first], -1)
    # Each row's [1, a1..a_na], b1, b2: slices of one copy of the frontier's theta.
    ones = np.ones((start.size, 1))
    frontier = np.concatenate((ones, theta_all[first]), axis=1)
    empty = np.empty(0)
    a_rows, b1_rows, b2_rows = [], [], []
    for row, (na, nb1, nb2, ok) in enumerate(zip(block_na, block_nb1, block_nb2, fitted, strict=True)):
        theta = frontier[row]
        a_rows.append(theta[: na + 1] if ok else empty)
        b1_rows.append(theta[na + 1 : na + 1 + nb1] if ok else empty)
        b2_rows.append(theta[na + 1 + nb1 : na + 1 + nb1 + nb2] if ok else empty)

    table = None
    if keep_candidates:
        table = pa.table(
            {
                "na": cand_na,
                "nb1": cand_nb1,
                "nb2": cand_nb2,
                "nk1": cand_nk1,
                "nk2": cand_nk2,
                "v": v_all,
            }
        )
    return GridFit(
        grid=grid,
        na=block_na.copy(),  # copies: the grid's layout is cached for the next fit (engine._layout)
        nb1=block_nb1.copy(),
        nb2=block_nb2.copy(),
        nk1=nk1,
        nk2=nk2,
        d=n_parameters(block_na, block_nb1, block_nb2),
        v=v,
        vaf_estimation=vaf_est,
        vaf_validation=vaf_val,
        n_unstable=np.add.reduceat(unstable, start).astype(np.int64),
        a=tuple(a_rows),
        b1=tuple(b1_rows),
        b2=tuple(b2_rows),
        n_candidates=int(v_all.size),
        n_unstable_total=int(np.count_nonzero(unstable)),
        candidates=table,
    )


def outputs(first, searched, v_all, theta_all, layout, i1p, i2p, tv1, tv2, pad, o, windows):
    """V, VAF on the estimation rows and VAF on the validation rows of each block's candidate
    ``first``, from its output as :func:`hcid.arx.simulation.simulate` gives it (unfused). ``layout`` is the
    blocks' (na, nb1, nb2) and the candidates' (nk1, nk2). A block without a finite search V
    keeps it and NaN VAF; so does a row whose output is not finite (never seen: the search
    found it finite). A block not ``searched`` to its end (``best_only``) has NaN throughout."""
    block_na, block_nb1, block_nb2, cand_nk1, cand_nk2 = layout
    (est_start, est_stop), (val_start, val_stop) = windows
    v = np.where(searched, v_all[first], np.nan)
    rows = np.flatnonzero(np.isfinite(v))
    chosen = first[rows]
    models = (
        theta_all[chosen],
        block_na[rows],
        block_nb1[rows],
        block_nb2[rows],
        cand_nk1[chosen],
        cand_nk2[chosen],
    )
    vaf_est = np.full(first.size, np.nan)
    vaf_val = np.full(first.size, np.nan)
    same = (est_start, est_stop) == (val_start, val_stop)  # stage 1: one window for both
    for chunk in range(0, rows.size, _VAF_ROWS):  # squared errors a chunk of rows at a time (in cache)
        part = slice(chunk, chunk + _VAF_ROWS)
        err_est, err_val = _squared_errors(
            [x[part] for x in models], i1p, i2p, tv1, tv2, pad, o, *windows, same
        )
        vaf_est[rows[part]] = _vaf(err_est, o[est_start:est_stop])
        vaf_val[rows[part]] = vaf_est[rows[part]] if same else _vaf(err_val, o[val_start:val_stop])
        unfused = np.empty(err_val.shape[0])
        _kernels.mse_of_squares(err_val, unfused)
        v[rows[part]] = np.where(np.isfinite(unfused), unfused, v[rows[part]])
    return v, vaf_est, vaf_val


def _squared_errors(models, i1p, i2p, tv1, tv2, pad, o, est, val, same):
    """Squared simulation errors of frontier models on the estimation and validation rows.

    ``models`` is (theta, na, nb1, nb2, nk1, nk2), one row per model; on
    the vector lanes where they can, else on the plain kernel. With
    ``same`` (the estimation and validation rows equal) the kernels fill one array (the
    validation one they get is empty) and it is returned for both.
    """
    n_rows = models[0].shape[0]
    err_est = np.empty((n_rows, est[1] - est[0]))
    err_val = np.empty((n_rows, 0 if same else val[1] - val[0]))
    plain = np.ones(n_rows, dtype=bool)
    if _lanes._WIDE:
        done = np.zeros(n_rows, dtype=bool)
        _blocks.squared_errors_wide(*models, tv1, tv2, pad, o, est[0], val[0], err_est, err_val, done)
        plain = ~done
    if plain.any():  # no JIT, na above MAX_NA, or an output not finite (simulate()'s NaN rule)
        some = (np.ascontiguousarray(x[plain]) for x in models)
        est_part, val_part = err_est[plain], err_val[plain]
        _kernels.squared_errors(*some, i1p, i2p, pad, o, est[0], val[0], est_part, val_part)
        err_est[plain] = est_part
        err_val[plain] = val_part
    return err_est, err_est if same else err_val


def _vaf(squared_errors: np.ndarray, o: np.ndarray) -> np.ndarray:
    """VAF (percent) per row of squared errors ``(o - o_hat)^2`` on the rows of ``o``.

    Each row's sum is numpy's pairwise sum over that row alone, as for a
    1-D array, so a row's VAF equals ``(1 - sum((o - o_hat)**2) /
    sum(o**2)) * 100`` computed on its own.
    """
    with np.errstate(divide="ignore", invalid="ignore"):  # o = 0 on the rows: NaN
        return (1.0 - np.sum(squared_errors, axis=-1) / np.sum(o**2)) * 100.0
