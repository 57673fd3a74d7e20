"""`hcid fit-hc` (issue 12): tables, determinism across --jobs, resuming, W choice, config errors."""

import shutil

import pyarrow.parquet as pq
import pytest
import yaml
from typer.testing import CliRunner

from hcid import hcfit, tables
from hcid.cli import app
from hcid.selection.criteria import w_bic

from .conftest import report_without_figures

runner = CliRunner()

# Small optimiser sizes keep the test fast; the settings' effect on results is the core's tests' matter.
FAST = {"starts": 1, "popsize": 4, "maxiter": 8}


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    """configs/ci.yaml, seeds 1-2, run and fitted with --jobs 1 and with --jobs 2."""
    from .conftest import CI_CONFIG

    base = tmp_path_factory.mktemp("fit")
    raw = yaml.safe_load(CI_CONFIG.read_text())
    raw["seeds"] = [1, 2]
    raw["fit_hc"] = FAST
    config = base / "ci.yaml"
    config.write_text(yaml.safe_dump(raw))
    identified = base / "identified"
    result = runner.invoke(app, ["run", str(config), "--run", str(identified), "--quiet"])
    assert result.exit_code == 0, result.output
    out = {}
    for jobs in (1, 2):
        run = base / f"jobs{jobs}"
        shutil.copytree(identified, run)
        args = ["fit-hc", str(config), "--run", str(run), "--jobs", str(jobs), "--quiet"]
        result = runner.invoke(app, args)
        assert result.exit_code == 0, result.output
        out[jobs] = (run, result.output)
    return config, out


def test_tables_hold_one_row_per_record_method_w_and_parameter(fitted):
    _, out = fitted
    run, output = out[1]
    params = pq.read_table(run / tables.HC_PARAMETERS.file)
    assert tables.HC_PARAMETERS.problem(params) is None
    rows = params.to_pylist()
    # 2 models x 2 seeds x 2 methods at one W each (no calibration: W_BIC, Nf = 960).
    fits = {(r["model"], r["seed"], r["method"], r["w"]) for r in rows}
    assert len(fits) == 8
    assert sorted({r["w"] for r in rows}) == [pytest.approx(w_bic(960), rel=1e-12)]
    assert {r["w_source"] for r in rows} == {"W_BIC"}
    for key in fits:
        group = [r for r in rows if (r["model"], r["seed"], r["method"], r["w"]) == key]
        names = tuple(r["parameter"] for r in group)
        # Feedforward parameters exactly when the selected model has a feedforward path.
        expected = hcfit.PARAMETERS if group[0]["nb_ft"] > 0 else hcfit.FEEDBACK_PARAMETERS
        assert names == expected
        assert all(r["status"] == "fitted" for r in group)
    # True values: configs/ci.yaml's models (SPEC 1) and the loop's NMS.
    ff = {r["parameter"]: r["true_value"] for r in rows if r["model"] == "FF"}
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
    res = pq.read_table(run / tables.RESIDUALS.file)
    assert tables.RESIDUALS.problem(res) is None
    # 1 s of lags at 25 Hz: 25 autocorrelation lags and 51 per input (ft_s, e), per fit.
    assert res.num_rows == 8 * (25 + 2 * 51)
    assert set(res.column("signal").to_pylist()) == {"eps", "ft_s", "e"}
    # The 99% band of a white residual over the 960 validation rows: 2.5758 / sqrt(960).
    assert sorted(set(res.column("bound").to_pylist())) == [pytest.approx(2.5758293035489 / 960**0.5)]
    assert "fitted 8 record-methods, reused 0" in output


def test_estimates_carry_standard_errors_and_the_loop_is_described(fitted):
    # Sources: the 95% interval is estimate +- 1.96 se (hc_parameters' definition); the true
    # loop's crossover and phase margin are SPEC 1's FB/FF feedback loop with the paper's plant,
    # 1.9277 rad/s and 49.29 deg (tests/test_descriptors.py checks them against control.margin).
    _, out = fitted
    run, output = out[1]
    params = pq.read_table(run / tables.HC_PARAMETERS.file).to_pylist()
    assert {r["target"] for r in params} == {"time"}  # the default (docs/parametric-fit.md)
    assert {r["covariance"] for r in params} == {"sandwich"}
    free = [r for r in params if not r["at_bound"]]
    assert free and all(r["se"] > 0 for r in free)
    for r in free:
        assert r["ci_low"] == pytest.approx(r["estimate"] - 1.959963984540054 * r["se"], rel=1e-12)
        assert r["ci_high"] == pytest.approx(r["estimate"] + 1.959963984540054 * r["se"], rel=1e-12)
    loop = pq.read_table(run / tables.HC_LOOP.file)
    assert tables.HC_LOOP.problem(loop) is None
    rows = loop.to_pylist()
    assert len(rows) == 8 * 2  # an arx and a fitted row per record, method and W
    assert {r["source"] for r in rows} == {"arx", "fitted"}
    for r in rows:
        assert r["true_crossover"] == pytest.approx(1.9277, abs=1e-4)
        assert r["true_phase_margin"] == pytest.approx(49.29, abs=0.01)
        # A fitted or selected model of this loop crosses over within 20% of it.
        assert r["crossover"] == pytest.approx(r["true_crossover"], rel=0.2)
        assert 0 < r["share_remnant"] < 0.1  # var(n)/var(u): 0.027 in this task (0.157 disturbance-only)
        assert r["kn_rate"] == 100.0
    spectrum = pq.read_table(run / tables.REMNANT_SPECTRUM.file)
    assert tables.REMNANT_SPECTRUM.problem(spectrum) is None
    assert spectrum.num_rows > 0
    assert "wc rad/s" in output and "95% interval" in output


def test_a_bad_target_is_one_line_and_writes_nothing(fitted, tmp_path):
    config, out = fitted
    run = tmp_path / "run"
    shutil.copytree(out[1][0], run)
    before = {p.name: p.read_bytes() for p in run.iterdir() if p.is_file()}
    result = runner.invoke(app, ["fit-hc", str(config), "--run", str(run), "--target", "ml", "--quiet"])
    assert result.exit_code == 2
    assert result.stderr.strip().splitlines() == [
        "hcid: error: target (--target): must be one of auto, lines, time, closed_loop, frequency, got 'ml'"
    ]
    assert {p.name: p.read_bytes() for p in run.iterdir() if p.is_file()} == before


FIT_TABLES = [
    t.file for t in (tables.HC_PARAMETERS, tables.RESIDUALS, tables.HC_LOOP, tables.REMNANT_SPECTRUM)
]


@pytest.mark.parametrize("name", FIT_TABLES)
def test_tables_identical_for_jobs_1_and_2(fitted, name):
    _, out = fitted
    # Byte for byte (Table.equals would call NaN unequal: a FB fit has no true TI).
    assert (out[1][0] / name).read_bytes() == (out[2][0] / name).read_bytes()


def test_second_call_reuses_everything_and_another_w_adds_rows(fitted, tmp_path):
    config, out = fitted
    run = out[1][0]
    before = (run / tables.HC_PARAMETERS.file).read_bytes()
    result = runner.invoke(app, ["fit-hc", str(config), "--run", str(run), "--quiet"])
    assert result.exit_code == 0, result.output
    assert "fitted 0 record-methods, reused 8" in result.output
    assert (run / tables.HC_PARAMETERS.file).read_bytes() == before
    # A new W is fitted for the direct method only; the W_BIC rows stay.
    result = runner.invoke(
        app, ["fit-hc", str(config), "--run", str(run), "--w", "0.47", "--method", "direct", "--quiet"]
    )
    assert result.exit_code == 0, result.output
    assert "fitted 4 record-methods" in result.output
    after = pq.read_table(run / tables.HC_PARAMETERS.file).to_pylist()
    assert {(r["method"], r["w_source"]) for r in after} == {
        ("direct", "W_BIC"),
        ("indirect", "W_BIC"),
        ("direct", "--w"),
    }


def test_changed_settings_refit_instead_of_reusing(fitted, tmp_path):
    config, out = fitted
    run = tmp_path / "copy"
    shutil.copytree(out[2][0], run)
    raw = yaml.safe_load(config.read_text())
    raw["fit_hc"] = {**FAST, "seed": 1}
    changed = tmp_path / "ci.yaml"
    changed.write_text(yaml.safe_dump(raw))
    result = runner.invoke(app, ["fit-hc", str(changed), "--run", str(run), "--method", "direct", "--quiet"])
    assert result.exit_code == 0, result.output
    assert "fitted 4 record-methods, reused 0" in result.output


def test_a_fit_on_a_bound_is_flagged_in_the_table(fitted, tmp_path):
    # Kpe bounds [0.2, 0.5] exclude the true 0.75 (configs/ci.yaml): every estimate lies on
    # the upper bound, and the table says so.
    config, out = fitted
    run = tmp_path / "copy"
    shutil.copytree(out[1][0], run)
    raw = yaml.safe_load(config.read_text())
    raw["fit_hc"] = {**FAST, "bounds": {"Kpe": [0.2, 0.5]}}
    narrowed = tmp_path / "ci.yaml"
    narrowed.write_text(yaml.safe_dump(raw))
    result = runner.invoke(app, ["fit-hc", str(narrowed), "--run", str(run), "--method", "direct", "--quiet"])
    assert result.exit_code == 0, result.output
    rows = [
        r
        for r in pq.read_table(run / tables.HC_PARAMETERS.file).to_pylist()
        if r["parameter"] == "Kpe" and r["method"] == "direct"
    ]
    assert len(rows) == 4
    assert all(r["at_bound"] and r["estimate"] == pytest.approx(0.5, abs=1e-4) for r in rows)


@pytest.mark.parametrize(
    ("fit_hc", "message"),
    [
        ({"bounds": {"TL": [2, 1]}}, "fit_hc.bounds.TL: lower 2 above upper 1"),
        ({"bounds": {"w_nms": [0, 10]}}, "fit_hc.bounds.w_nms: lower must be > 0 rad/s, got 0"),
        ({"start_ranges": {"Kpe": [0.001, 1]}}, "fit_hc.start_ranges.Kpe: [0.001, 1] outside the bounds"),
        ({"target": "both"}, "fit_hc.target: must be one of auto, lines, time, closed_loop, frequency"),
    ],
)
def test_bad_bounds_give_one_line_and_exit_2(ci_raw, tmp_path, fit_hc, message):
    ci_raw["fit_hc"] = fit_hc
    config = tmp_path / "bad.yaml"
    config.write_text(yaml.safe_dump(ci_raw))
    run = tmp_path / "run"
    result = runner.invoke(app, ["fit-hc", str(config), "--run", str(run), "--quiet"])
    assert result.exit_code == 2
    assert message in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    assert not run.exists()


def test_without_identification_one_line_and_exit_2(ci_raw, tmp_path):
    config = tmp_path / "ci.yaml"
    config.write_text(yaml.safe_dump(ci_raw))
    result = runner.invoke(app, ["fit-hc", str(config), "--run", str(tmp_path / "run"), "--quiet"])
    assert result.exit_code == 2
    assert "run: missing; make it first with `hcid run CONFIG`" in result.stderr
    (tmp_path / "run").mkdir()
    result = runner.invoke(app, ["fit-hc", str(config), "--run", str(tmp_path / "run"), "--quiet"])
    assert result.exit_code == 2
    assert "frontier.parquet: missing; run `hcid identify` first" in result.stderr
    result = runner.invoke(app, ["fit-hc", str(config), "--run", str(tmp_path / "run"), "--w", "-1"])
    assert result.exit_code == 2


def test_report_shows_the_section(fitted, tmp_path):
    _, out = fitted
    drawn = ("hc_parameters_W_BIC.png", "hc_residuals.png")
    text, figures = report_without_figures(out[1][0], draw=drawn, out=tmp_path)
    assert "## 10. Parametric HC model" in text
    assert "| FF | direct | 0.007153 | Kpt | - | 2 | 0.8 |" in text
    assert set(drawn) <= figures and all((tmp_path / name).stat().st_size > 0 for name in drawn)


def test_interrupted_fit_resumes_from_its_parts(fitted, tmp_path, monkeypatch):
    # Parts (Arrow IPC, RUN/.parts/fit_hc/) keep the finished record-methods of an
    # interrupted run; the resumed run fits only the rest and ends with the same bytes.
    from hcid.pipeline import fit_hc as fit

    from .conftest import interrupt_after

    config, out = fitted
    run = tmp_path / "run"
    shutil.copytree(out[2][0], run)  # the uninterrupted run (W_BIC only; other tests add rows to out[1])
    for name in FIT_TABLES:
        (run / name).unlink()
    real = interrupt_after(monkeypatch, fit, "_fit_task", 3)
    result = runner.invoke(app, ["fit-hc", str(config), "--run", str(run), "--jobs", "1", "--quiet"])
    assert result.exit_code != 0
    assert len(list((run / ".parts" / "fit_hc").glob("*/*.parameters.arrow"))) == 3
    monkeypatch.setattr(fit, "_fit_task", real)
    result = runner.invoke(app, ["fit-hc", str(config), "--run", str(run), "--jobs", "1", "--quiet"])
    assert result.exit_code == 0, result.output
    assert "fitted 5 record-methods, reused 3" in result.output
    for name in FIT_TABLES:
        assert (run / name).read_bytes() == (out[2][0] / name).read_bytes()
    assert not (run / ".parts" / "fit_hc").exists()


def test_fit_hc_on_a_data_only_config_is_one_line(tmp_path):
    # Before: AttributeError 'NoneType' object has no attribute 'plant', exit 1 (issue 24, 4).
    # The fit inverts the plant (Inverse Feedforward Model), which a data-only config lacks.
    from .conftest import CI_CONFIG, ROOT

    raw = yaml.safe_load(CI_CONFIG.read_text())
    columns = {
        "run": "trial",
        "time": "time_s",
        "ft": "target",
        "fd": "disturbance",
        "e": "error",
        "u": "stick",
    }
    doc = {"name": "lab", "identify": raw["identify"], "selection": raw["selection"],
           "data": {"analysis_rate": 25.0, "window": 81.92, "columns": columns}}  # fmt: skip
    config = tmp_path / "lab.yaml"
    config.write_text(yaml.safe_dump(doc))
    run = tmp_path / "run"
    data = ROOT / "configs" / "example_data" / "subject_synthetic.csv"
    for argv in (["identify", "--data", str(data), "--method", "direct", "--quiet"], ["sweep-w"]):
        result = runner.invoke(app, [argv[0], str(config), "--run", str(run), *argv[1:]])
        assert result.exit_code == 0, result.output
    before = sorted(p.name for p in run.iterdir())
    result = runner.invoke(app, ["fit-hc", str(config), "--run", str(run), "--quiet"])
    assert result.exit_code == 2, result.output
    assert result.stderr.startswith("hcid: error: loop: missing; `hcid fit-hc` needs the plant")
    assert len(result.stderr.strip().splitlines()) == 1 and sorted(p.name for p in run.iterdir()) == before


def test_the_summary_of_a_parameter_over_records_the_cli_and_the_report_share():
    # hcid.pipeline.summary.summarise_fits, by hand: four records of one parameter, one without a
    # feedback path (no estimate), one whose parameter the data do not see (infinite se).
    import math

    import numpy as np
    import pyarrow as pa

    from hcid.pipeline.summary import summarise_fits

    def row(estimate, se, at_bound=False):
        low, high = estimate - 1.96 * se, estimate + 1.96 * se
        key = {"model": "FB", "method": "direct", "w": 0.1, "parameter": "Kpe", "true_value": 2.0}
        return {**key, "estimate": estimate, "se": se, "ci_low": low, "ci_high": high, "at_bound": at_bound}

    nan = math.nan
    rows = [row(2.1, 0.1), row(1.5, 0.1), row(2.6, math.inf, True), row(nan, nan)]
    ((key, f),) = summarise_fits(pa.Table.from_pylist(rows)).items()
    assert key == ("FB", "direct", 0.1, "Kpe") and (f.records, f.fitted) == (4, 3)
    x = np.array([2.1, 1.5, 2.6])
    assert f.mean == pytest.approx(x.mean()) and f.median == 2.1
    assert f.sd == pytest.approx(np.std(x, ddof=1))
    assert f.rmse == pytest.approx(np.sqrt(np.mean((x - 2) ** 2)))
    assert f.median_se == 0.1  # of 0.1, 0.1, inf: the infinite one counts
    assert f.rms_se == pytest.approx(0.1)  # over the finite ones
    # 2.0 in [1.904, 2.296], not in [1.304, 1.696]; the infinite se gives no interval.
    assert (f.covered, f.n_se, f.at_bound) == (1, 2, 1)
    assert f.scored and f.bias == pytest.approx(x.mean() - 2)
    assert f.percent(f.bias) == pytest.approx(50 * f.bias)  # in % of the true 2
    assert f.se_ratio == pytest.approx(0.1 / np.std(x, ddof=1))
