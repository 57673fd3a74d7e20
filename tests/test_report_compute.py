"""Report computations against exact formulas (SPEC section 5, paper eq. 11-12)."""

import numpy as np
import pytest
from scipy import signal as sps

from hcid.arx.response import path_response as arx_response
from hcid.calibration import clopper_pearson
from hcid.report.compute import compute_errors


def test_shift_is_undone_exactly():
    # SPEC 5: exp(+jw 1.0) z^-nk B/A with B = [1], A = [1], nk = 25 samples of 0.04 s = 1 s -> 1.
    w = np.geomspace(0.1, 30, 50)
    np.testing.assert_allclose(arx_response([1.0], [1.0], 25, w, 0.04, advance=1.0), 1.0, atol=1e-12)


def test_discrete_response_matches_freqz():
    # z^-nk B(z)/A(z) against scipy.signal.freqz of the same polynomials in z^-1.
    a, b, nk, dt = [1.0, -0.9, 0.2], [0.5, -0.3], 3, 0.04
    w = np.geomspace(0.1, 30, 40)
    _, expected = sps.freqz(np.concatenate([np.zeros(nk), b]), a, worN=w * dt)
    np.testing.assert_allclose(arx_response(a, b, nk, w, dt), expected, rtol=1e-12)


def test_absent_path_is_zero():
    assert np.all(arx_response([1.0, 0.5], [], 0, np.array([1.0]), 0.04) == 0)


def test_errors_wrap_phase_and_skip_absent_paths():
    # Paper eq. 11-12: a 350 deg phase difference is a 10 deg error; an absent path adds
    # its full magnitude error and no phase error.
    h_true = np.array([2.0 + 0j])
    h_id = np.array([[1.5 * np.exp(1j * np.radians(350.0))], [0.0 + 0j]])
    err = compute_errors(h_id, h_true)
    assert err["mag_mean"][0] == pytest.approx((0.5 + 2.0) / 2)
    assert err["mag_max"][0] == pytest.approx(2.0)
    assert err["phase_mean"][0] == pytest.approx(10.0)
    assert err["phase_max"][0] == pytest.approx(10.0)


def test_clopper_pearson_exact_values():
    # k = 0 of n = 50: upper bound 1 - 0.025^(1/50) = 0.0711; k = n mirrors it.
    low, high = clopper_pearson(np.array([0, 50]), 50)
    assert low[0] == 0.0 and high[0] == pytest.approx(1 - 0.025 ** (1 / 50), rel=1e-9)
    assert high[1] == 1.0 and low[1] == pytest.approx(0.025 ** (1 / 50), rel=1e-9)
