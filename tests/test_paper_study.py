"""The whole paper study end to end (slow: minutes on 2 cores; `make test-all`)."""

import pyarrow.parquet as pq
import pytest
from typer.testing import CliRunner

from hcid.cli import app

from .conftest import PAPER_CONFIG

runner = CliRunner()


@pytest.mark.slow
def test_paper_study_end_to_end(tmp_path):
    run = tmp_path / "paper"
    result = runner.invoke(app, ["run", str(PAPER_CONFIG), "--run", str(run), "--quiet"])
    assert result.exit_code == 0, result.output
    th = {(r["method"], r["model"]): r for r in pq.read_table(run / "thresholds.parquet").to_pylist()}
    # Paper section 5.2 (SPEC 6): W_FP 1.2e-2 (direct) / 3.7e-2 (indirect), W_FN ~0.26.
    # This tool finds 7.2e-3 / 1.05e-2 and 0.24 / 0.22 (README "Results"); the test holds
    # the paper's order of magnitude and the qualitative claims, not the exact figures.
    assert 1e-3 < th[("direct", "FB")]["w_fp"] < 5e-2
    assert th[("indirect", "FB")]["w_fp"] > th[("direct", "FB")]["w_fp"]
    for method in ("direct", "indirect"):
        assert th[(method, "FB")]["w_bic"] < th[(method, "FB")]["w_fp"]  # BIC does not prevent FPs
        assert 0.13 < th[(method, "FF")]["w_fn"] < 0.52  # within a factor 2 of 0.26
    result = runner.invoke(app, ["report", str(run)])
    assert result.exit_code == 0, result.output
    assert (run / "report" / "report.html").is_file()
