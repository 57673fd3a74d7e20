"""Analyses of a selected model: the residual is the model's own, the fit sees the right paths."""

import dataclasses

import numpy as np
import pytest

from hcid import methods
from hcid.analysis.residuals import RESIDUAL
from hcid.arx.simulation import simulate
from hcid.config import Window
from hcid.hcfit.selected import SelectedModel, analyse_selected, true_parameters

FAST = {"starts": 1, "popsize": 4, "maxiter": 8}


def _selected(a, b_ft, b_e, nk_ft, nk_e, w=0.01):
    return SelectedModel(
        w=w,
        na=len(a) - 1,
        nb_ft=len(b_ft),
        nb_e=len(b_e),
        nk_ft=nk_ft,
        nk_e=nk_e,
        v=1.0,
        vaf_validation=float("nan"),
        a=np.asarray(a, float),
        b_ft=np.asarray(b_ft, float),
        b_e=np.asarray(b_e, float),
        method="direct",
        rate=25.0,
        target_shift=1.0,
        estimation=Window(129, 1088),
        validation=Window(1089, 2048),
    )


@pytest.fixture(scope="module")
def fast_config(paper_config):
    from hcid.hcfit import parse_fit_settings

    settings = parse_fit_settings(FAST, default_band=paper_config.disturbance.band)
    return dataclasses.replace(paper_config, fit_hc=settings)


def test_residual_of_the_true_output_error_model_is_the_added_noise(fast_config, paper_record):
    # Source: u built here as an output-error ARX model of ft_s and e plus white noise w
    # (seeded): the selected model's simulation residual is then w itself, so its
    # correlations are those of w, and about 1% of its lags lie outside the 99% band.
    a, b_ft, b_e, nk_ft, nk_e = [1.0, -0.8], [0.05, 0.02], [0.3], 20, 6
    r = dict(paper_record)
    w = 1e-3 * np.random.default_rng(5).standard_normal(r["e"].size)
    r["u"] = simulate(a, b_ft, b_e, nk_ft, nk_e, r["ft_s"], r["e"]) + w
    sel = _selected(a, b_ft, b_e, nk_ft, nk_e)
    result = analyse_selected(sel, r, fast_config, methods.get("direct"))
    validation = fast_config.identify.stage("direct").validation.rows()
    from hcid.analysis.residuals import analyse_residuals

    expected = analyse_residuals(w, {"ft_s": r["ft_s"], "e": r["e"]}, validation, 25, rate=25.0)
    for got, want in zip(result.residuals.correlations, expected.correlations, strict=True):
        assert got.signal == want.signal
        np.testing.assert_allclose(got.values, want.values, atol=1e-9)
    # 25 + 51 + 51 lags; a white residual independent of the inputs leaves ~1% outside.
    assert result.residuals.share_outside < 0.05
    assert result.residuals.correlation(RESIDUAL).lags.tolist() == list(range(1, 26))
    assert result.fit is not None and result.fit.has_feedforward  # nb_ft > 0: Kpt, TI, tau_pt fitted


def test_no_feedback_path_is_not_fitted_by_the_frequency_target(fast_config, paper_record):
    # He = 0 cannot be fitted by a relative error (SPEC 8 divides by |H_arx|): fit is None,
    # while the residuals are still analysed.
    sel = _selected([1.0, -0.5], [0.05], [], 25, 0)
    config = dataclasses.replace(
        fast_config, fit_hc=dataclasses.replace(fast_config.fit_hc, target="frequency")
    )
    result = analyse_selected(sel, paper_record, config, methods.get("direct"))
    assert result.fit is None
    assert result.residuals.n == 960


def test_true_parameters_follow_the_config(paper_config):
    # SPEC 1 table and loop: FF has every parameter; FB has Kpt = 0 and no TI, tau_pt.
    ff = true_parameters(paper_config, "FF")
    assert ff == {
        "Kpe": 0.75,
        "TL": 0.4,
        "tau_pe": 0.24,
        "w_nms": 10.1,
        "zeta_nms": 0.35,
        "Kpt": 0.8,
        "TI": 0.25,
        "tau_pt": 0.35,
    }
    fb = true_parameters(paper_config, "FB")
    assert fb["Kpt"] == 0.0 and np.isnan(fb["TI"]) and np.isnan(fb["tau_pt"])
