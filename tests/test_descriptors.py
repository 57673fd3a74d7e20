"""Crossover frequency and phase margin (hcid.analysis.descriptors), against exact formulas and
python-control."""

import control
import numpy as np
import pytest

from hcid.analysis.descriptors import loop_margins
from hcid.errors import IdentificationError
from hcid.loop.hcmodel import feedback_path, plant


def _response(tf):
    return lambda w: np.asarray(tf(1j * np.asarray(w)), dtype=complex)


@pytest.mark.parametrize(("K", "tau"), [(1.5, 0.0), (2.2, 0.24), (0.7, 0.35)])
def test_integrator_with_delay_exact(K, tau):
    # Source: L = K exp(-s tau) / s has |L| = K / w, so wc = K, and PM = 90 - K tau (deg).
    m = loop_margins(lambda w: K * np.exp(-1j * w * tau) / (1j * w))
    assert m.crossover == pytest.approx(K, rel=1e-12)
    assert m.phase_margin == pytest.approx(90.0 - np.degrees(K * tau), abs=1e-9)
    assert m.n_crossovers == 1


def test_double_integrator_exact():
    # Source: L = Kpe (TL s + 1) K / s^2: |L|^2 = Kpe^2 K^2 (TL^2 w^2 + 1) / w^4, a quadratic in w^2,
    # and PM = atan(TL wc) in deg (the two integrators give -180).
    Kpe, TL, K = 1.2, 0.8, 1.0
    a = Kpe**2 * K**2
    w2 = (a * TL**2 + np.sqrt(a**2 * TL**4 + 4 * a)) / 2
    m = loop_margins(lambda w: Kpe * (TL * 1j * w + 1) * K / (1j * w) ** 2)
    assert m.crossover == pytest.approx(np.sqrt(w2), rel=1e-12)
    assert m.phase_margin == pytest.approx(np.degrees(np.arctan(TL * np.sqrt(w2))), abs=1e-9)


@pytest.mark.parametrize("model_name", ["FB", "FF"])
def test_paper_loops_against_control_margin(paper_config, model_name):
    # Source: python-control's margin() on the same rational loop Hpe Yc (the delay left out,
    # which margin() cannot take); the delay then lowers the margin by wc tau exactly
    # (it leaves |L| and so wc unchanged).
    model = paper_config.model(model_name)
    rational = feedback_path(model, paper_config.loop) * plant(paper_config.loop)
    _, pm, _, wcp = control.margin(rational)
    mine = loop_margins(_response(rational))
    assert mine.crossover == pytest.approx(wcp, rel=1e-6)
    assert mine.phase_margin == pytest.approx(pm, abs=1e-6)
    delayed = loop_margins(lambda w: _response(rational)(w) * np.exp(-1j * w * model.tau_pe))
    assert delayed.crossover == pytest.approx(mine.crossover, rel=1e-12)
    assert delayed.phase_margin == pytest.approx(
        mine.phase_margin - np.degrees(mine.crossover * model.tau_pe), abs=1e-9
    )


def test_no_crossover_and_bad_input():
    m = loop_margins(lambda w: 0.001 / (1j * w + 1.0))
    assert np.isnan(m.crossover) and np.isnan(m.phase_margin) and m.n_crossovers == 0
    assert m.to_arrow().num_rows == 1
    with pytest.raises(IdentificationError, match="band"):
        loop_margins(lambda w: 1 / (1j * w), band=(1.0, 0.5))
    with pytest.raises(IdentificationError, match="finite complex response"):
        loop_margins(lambda w: np.full(w.shape, np.nan, dtype=complex))
