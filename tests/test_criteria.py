"""Selection criteria: SPEC 4 and 9 values, config errors, and a registered criterion flowing through."""

import math

import pytest
from typer.testing import CliRunner

from hcid.assembly.resolve import parse_config
from hcid.cli import app
from hcid.errors import ConfigError
from hcid.selection import criteria


def test_spec_values_at_nf_960():
    # SPEC 4: W_AIC = 2/960 = 2.08e-3, W_BIC = ln(960)/960 = 7.15e-3; SPEC 9: c = 3 gives 0.0214.
    assert criteria.build("aic").w(960) == pytest.approx(2.083e-3, rel=1e-3)
    assert criteria.build("bic").w(960) == pytest.approx(7.15e-3, rel=1e-3)
    assert criteria.build("mbic").w(960) == pytest.approx(0.0214, rel=3e-3)
    assert criteria.build("mbic", {"c": 1.0}).w(960) == criteria.build("bic").w(960)


@pytest.mark.parametrize(
    ("value", "message"),
    [
        ({"xic": {}}, "selection.criteria.xic: unknown criterion (allowed: aic, bic, mbic)"),
        ({"mbic": {"c": -1}}, "selection.criteria.mbic.c: must be a number in [0, 1000], got -1"),
        ({"mbic": {"k": 2}}, "selection.criteria.mbic.k: unknown key (allowed: c)"),
        ({"aic": {"c": 2}}, "selection.criteria.aic.c: unknown key (allowed: none)"),
        ([], "selection.criteria: must be a non-empty mapping"),
    ],
)
def test_bad_criteria_are_refused(ci_raw, value, message):
    ci_raw.setdefault("selection", {})["criteria"] = value
    with pytest.raises(ConfigError) as info:
        parse_config(ci_raw, "ci")
    assert str(info.value).startswith(message)


def test_a_registered_criterion_flows_through_to_thresholds_and_printout(ci_raw, tmp_path, monkeypatch):
    # The seam of issue 9: one CRITERIA entry (here Hannan-Quinn, W = 2 ln ln Nf / Nf) reaches the
    # thresholds table, the CLI printout and the report's marks with nothing else changed.
    hq = criteria.CriterionKind(
        "Hannan-Quinn", {}, lambda c: ("W_HQ", lambda nf: 2 * math.log(math.log(nf)) / nf)
    )
    monkeypatch.setitem(criteria.CRITERIA, "hq", hq)
    config = tmp_path / "hq.yaml"
    import yaml

    ci_raw["selection"]["criteria"] = {"bic": {}, "hq": {}}
    config.write_text(yaml.safe_dump(ci_raw))
    run = tmp_path / "hq"
    result = CliRunner().invoke(app, ["run", str(config), "--run", str(run), "--jobs", "1", "--quiet"])
    assert result.exit_code == 0, result.output
    expected = 2 * math.log(math.log(960)) / 960
    assert f"W_HQ = {expected:.4g}" in result.output
    import pyarrow.parquet as pq

    rows = pq.read_table(run / "thresholds.parquet").to_pylist()
    assert all(r["w_hq"] == pytest.approx(expected, rel=1e-12) for r in rows)
    assert "w_aic" not in rows[0]

    from hcid.report.build import compute_report

    assert compute_report(run).sections["curves"].criterion_marks["W_HQ"] == pytest.approx(expected)
