"""The HC model's discretised paths against scipy.signal.freqz and the continuous-time truth (SPEC 1)."""

import numpy as np
import pytest
from scipy import signal as sps

from hcid.loop.hcmodel import DiscreteLoop, feedback_path, feedforward_path, plant, true_response

W = np.geomspace(0.1, 30.0, 60)


@pytest.fixture(scope="module")
def ff_loop(paper_config):
    return DiscreteLoop.build(paper_config.model("FF"), paper_config.loop, paper_config.timing.sim_dt)


@pytest.mark.parametrize("which", ["feedforward", "feedback", "plant", "remnant"])
def test_discrete_response_equals_freqz(ff_loop, which):
    # DiscreteLoop.response against scipy.signal.freqz of the same (b, a), times the
    # whole-sample delay z^-L (24 samples for He, 35 for Hft at 100 Hz).
    b, a = getattr(ff_loop, which)
    delay = {"feedforward": ff_loop.delay_ft, "feedback": ff_loop.delay_e}.get(which, 0)
    _, h = sps.freqz(b, a, worN=W * ff_loop.dt)
    expected = h * np.exp(-1j * W * ff_loop.dt * delay)
    np.testing.assert_allclose(ff_loop.response(which, W), expected, rtol=1e-10)


def test_delays_are_whole_samples(ff_loop):
    assert (ff_loop.delay_ft, ff_loop.delay_e) == (35, 24)  # SPEC 1: 0.35 s and 0.24 s at 100 Hz


@pytest.mark.parametrize("path", ["feedforward", "feedback"])
def test_tustin_paths_match_the_continuous_truth(paper_config, ff_loop, path):
    # Tustin maps s to (2/T)(z-1)/(z+1): the frequency warps by tan(wT/2)/(T/2), a relative
    # (wT)^2/12 = 7.5e-4 at 3 rad/s with T = 0.01 s; allow 2e-3 below 3 rad/s.
    hft, he = true_response(paper_config.model("FF"), paper_config.loop, W)
    truth = hft if path == "feedforward" else he
    low = W <= 3.0
    h = ff_loop.response(path, W)
    np.testing.assert_allclose(h[low], truth[low], rtol=2e-3)


def test_paths_are_proper_products_with_the_nms(paper_config):
    # SPEC 1: Ynms*Ypt and Ynms*Ype are proper; Ypt = Kpt / Yc / (TI s + 1)^2 (relative degree
    # 2 + 2 - 2 = 2 for the paper's plant), Ype = Kpe (TL s + 1) (relative degree 2 - 1 = 1).
    loop, ff = paper_config.loop, paper_config.model("FF")
    for sys, rel_degree in ((feedforward_path(ff, loop), 2), (feedback_path(ff, loop), 1)):
        num, den = np.trim_zeros(sys.num[0][0], "f"), sys.den[0][0]
        assert len(den) - len(num) == rel_degree
    # Yc = Kc wb / (s (s + wb)) at s = j: 2.75 * 2 / (j (j + 2)).
    assert complex(plant(loop)(1j)) == pytest.approx(5.5 / (1j * (1j + 2)))
