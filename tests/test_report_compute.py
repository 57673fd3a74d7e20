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


def test_each_status_has_its_mark_in_the_run_table():
    # † undetermined, ‡ determined but to read with care, ° held (the table's own note says so).
    from hcid.report.sections.study import _with_se

    def row(status, se=0.1):
        return {"Kpe": 33.5, "Kpe_se": se, "Kpe_status": status}

    assert _with_se(row("determined"), "Kpe") == "33.5 ± 0.1"
    assert _with_se(row("outside its plausible range"), "Kpe") == "33.5 ± 0.1‡"
    assert _with_se(row("not told from 0 (se above |value|)"), "Kpe") == "33.5 ± 0.1‡"
    assert _with_se(row("in a failed fit (validation VAF below 0%)", 3.8e-9), "Kpe") == "33.5 ± 3.8e-09†"
    assert _with_se(row("fixed at a literature value", float("nan")), "Kpe") == "33.5°"
