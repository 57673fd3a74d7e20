"""Report computations against exact formulas (paper eq. 11-12)."""

import numpy as np
import pytest

from hcid.report.compute import compute_errors


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
