"""ARX path frequency responses against exact formulas and scipy.signal.freqz (SPEC section 5)."""

import numpy as np
from scipy import signal as sps

from hcid.arx.response import path_response as arx_response


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
