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
    assert _with_se(row("in a failed fit (validation VAF below 0%)", 3.8e-9), "Kpe") == "33.5†"  # no se
    assert _with_se(row("correlated with TL (r = -0.97)", 3.3e5), "Kpe") == "33.5†"
    assert _with_se(row("fixed at a literature value", float("nan")), "Kpe") == "33.5°"


def test_the_evidence_caption_names_each_run_by_the_factors_that_differ():
    # The figure numbers runs; its caption keys them to the factors that differ within the group
    # (the group's own factor is the same for all), up to 24 runs (beyond: the run table).
    from hcid.report.sections.study import _run_names

    runs = [
        {"run_id": i + 1, "method": "direct", "subject": s, "plant": "fo", "trial": t}
        for i, (s, t) in enumerate([("dp", "+1"), ("dp", "-1"), ("ef", "+1")])
    ]
    assert _run_names(runs) == " Runs (subject, trial): 1 dp +1; 2 dp -1; 3 ef +1."
    assert _run_names([{**r, "subject": "dp", "trial": "+1"} for r in runs]) == ""  # nothing differs
    many = [{"run_id": i, "method": "direct", "subject": f"S{i}"} for i in range(25)]
    assert _run_names(many) == "" and _run_names(many[:24]).startswith(" Runs (subject): 0 S0; 1 S1;")
