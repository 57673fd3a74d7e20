"""`hcid analyse` (issue 27): a measured study end to end on a slice of the example lab study."""

import shutil
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from typer.testing import CliRunner

from hcid import tables
from hcid.cli import app

runner = CliRunner()
LAB = Path(__file__).resolve().parents[1] / "configs" / "lab_example"
CONFIG = LAB.parent / "lab_example.yaml"


@pytest.fixture(scope="module")
def analysed(tmp_path_factory):
    """Subjects S1 and S2, trials 1 and 2 of both conditions (8 files), 4 twins each and at most 12 FB
    twins for the p-values: ``hcid analyse --jobs 1 --compare condition`` (tables, answer and
    report), and the same analysis through the public API on two workers, comparing nothing
    (tables only; its output is the empty string)."""
    import hcid

    base = tmp_path_factory.mktemp("lab")
    data = base / "data"
    data.mkdir()
    for path in sorted(LAB.glob("S[12]_*_trial[12].csv")):
        shutil.copy(path, data / path.name)
    run = base / "run1"
    args = ["analyse", str(CONFIG), "--data", str(data), "--run", str(run), "--twins", "4", "--quiet",
            "--max-fb-twins", "12", "--jobs", "1", "--compare", "condition"]  # fmt: skip
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    out = {1: (run, result.output)}
    options = hcid.AnalysisOptions(twins=4, max_fb_twins=12)
    found = hcid.analyse(
        CONFIG, data, base / "run2", options, execution=hcid.Execution(jobs=2, progress=False)
    )
    assert found.run_dir == base / "run2" and found.runs.num_rows == 16  # 8 runs, 2 methods
    out[2] = (base / "run2", "")
    return data, out


def test_every_run_and_group_is_answered_with_its_factors(analysed):
    _, out = analysed
    run, output = out[1]
    runs = pq.read_table(run / tables.ANALYSIS.file)
    assert tables.ANALYSIS.problem(runs) is None
    rows = runs.to_pylist()
    # 8 runs x 2 methods, every row with the file name's factors.
    assert len(rows) == 16
    assert {(r["subject"], r["condition"], r["trial"]) for r in rows} == {
        (s, c, t) for s in ("S1", "S2") for c in ("pursuit", "compensatory") for t in ("1", "2")
    }
    groups = pq.read_table(run / tables.ANALYSIS_GROUPS.file).to_pylist()
    assert {(g["group"], g["method"]) for g in groups} == {
        (f"condition={c}", m) for c in ("pursuit", "compensatory") for m in ("direct", "indirect")
    }
    for g in groups:
        mine = [r for r in rows if r["group"] == g["group"] and r["method"] == g["method"]]
        assert g["n_runs"] == 4 and g["n_feedforward_at_w"] == sum(r["feedforward_at_w"] for r in mine)
        assert all(r["w"] == g["w"] for r in mine)
        # A W outside a safe interval is certain only where both twins' rates there are within
        # the target rate (0): never presented as certain otherwise.
        if g["w_rule"] == "safe interval":
            assert not g["uncertain"] and g["safe_low"] <= g["w"] < g["safe_high"]
        else:  # no interval: none in the table either (not the calibration's backward pair)
            assert g["uncertain"] == (max(g["fp_rate"], g["fn_rate"]) > 0)
            assert np.isnan(g["safe_low"]) and np.isnan(g["safe_high"])
        assert 0 <= g["fp_low"] <= g["fp_rate"] <= g["fp_high"] <= 1
    # The pursuit condition's twins separate: there the direct method finds the feedforward
    # every subject used (Kpt 0.8 and 1.0, configs/lab_example/make.py).
    pursuit = next(g for g in groups if g["group"] == "condition=pursuit" and g["method"] == "direct")
    assert not pursuit["uncertain"] and pursuit["n_feedforward_at_w"] == 4
    assert (
        (run / "analysis.csv")
        .read_text()
        .splitlines()[0]
        .startswith('"data_set","run_id","file","file_run","group"')
    )
    # Units in the Parquet schema (docs/tables.md): a time constant in s, a share as 1, VAF in %.
    schema = pq.read_schema(run / tables.ANALYSIS.file)
    assert [schema.field(c).metadata for c in ("TL", "TL_se", "p_value", "vaf_validation", "crossover")] == [
        {b"unit": u} for u in (b"s", b"s", b"1", b"%", b"rad/s")
    ]
    assert "estimator" in schema.names and "target" not in schema.names
    assert "feedforward in 4 of 4 runs" in output
    # The answer line leads with the verdict; the command ends with the report it wrote.
    assert "condition=pursuit, direct: " in output
    assert output.strip().splitlines()[-1] == f"report: {run / 'report' / 'report.html'}"
    # The group's model is the same for both methods: its data check printed in full once per
    # group (2 groups), referred to under the other method.
    checks = [line for line in output.splitlines() if line.startswith("    data check: ")]
    assert len(checks) == 4 and sum("chi-square" in line for line in checks) == 2
    assert sum(line.startswith("    data check: the group's model as above; ") for line in checks) == 2
    assert (run / "report" / "report.html").is_file()
    # Every group and method names what each evidence statistic alone finds, in the answer (one
    # line each, the deciding statistic marked once) and the report's table (a row per statistic:
    # the likelihood ratio's rows counted, one per group and method).
    said = [
        line for line in output.splitlines() if line.startswith("    per statistic, runs at p <= 0.05 and")
    ]
    assert len(said) == 4 and all(line.count("; decides)") == 1 for line in said), said
    report = (run / "report" / "report.md").read_text()
    assert (
        sum(row.startswith("| condition=") and "| likelihood ratio" in row for row in report.splitlines())
        == 4
    )
    # The loop line gives the remnant's share from the data: the median of its runs' column.
    loops = [line for line in output.splitlines() if line.startswith("    loop: ")]
    for g, line in zip(groups, loops, strict=True):
        share = np.median(
            [r["remnant_share_data"] for r in rows if r["group"] == g["group"] and r["method"] == g["method"]]
        )
        assert f"; remnant {100 * share:.0f}% of var(u) by the data (medians over runs)" in line


def test_each_runs_p_value_is_sequential_over_its_fb_twins_in_the_order_drawn(analysed):
    # Source: Besag and Clifford (1991) as SPEC 11 states it here: FB twins are drawn (4 at a time, at
    # most 12) until 5 show at least the run's statistic; p = 5/m at the m-th draw that makes 5, else
    # (1 + k)/(1 + n) over the n drawn, and beyond every twin (k = 0) SPEC 13's generalized Pareto
    # tail of the n drawn (log W*), at most 1/(1 + n) (hcid.pipeline.evidence.run_p_value, whose
    # tail tests/test_tail.py checks). Recomputed from evidence_twins.parquet.
    from hcid.selection.calibration import run_p_value

    _, out = analysed
    run = out[1][0]
    rows = pq.read_table(run / tables.ANALYSIS.file).to_pylist()
    twins = pq.read_table(run / tables.EVIDENCE_TWINS.file).to_pylist()
    for r in rows:
        fb = [t for t in twins if (t["group"], t["method"], t["forcing_set"], t["twin"])
              == (r["group"], r["method"], r["forcing_set"], "FB")]  # fmt: skip
        fb.sort(key=lambda t: t["seed"])
        assert [t["seed"] for t in fb] == list(range(1, len(fb) + 1)) and len(fb) in (4, 8, 12)
        w = [t["w_star"] for t in fb if not np.isnan(t["w_star"])]
        hits = np.cumsum(np.array(w) >= r["w_star"])
        if hits.size and hits[-1] >= 5:
            m = int(np.argmax(hits >= 5)) + 1
            assert (r["p_w_star"], r["fb_twins_w_star"], r["p_w_star_method"]) == (5 / m, m, "monte carlo")
        else:  # never 5: every twin drawn for this method was needed, up to the most
            p, _, how = run_p_value(r["w_star"], np.array(w))
            assert (r["p_w_star"], r["p_w_star_method"]) == (p, how)
            if hits.size and hits[-1] > 0:  # not beyond every twin: the count's p
                assert how == "monte carlo"
            if how == "monte carlo":
                assert r["p_w_star"] == (1 + (hits[-1] if hits.size else 0)) / (1 + len(w))
            assert r["fb_twins_w_star"] == len(w)
            if r["decided_by"] == "W*":
                assert len(w) == 12
    # The pursuit runs' feedforward is above every FB twin: their p-values needed all 12, and the
    # tail gives them less than Monte Carlo's floor 1/13.
    pursuit = [r for r in rows if r["condition"] == "pursuit" and r["method"] == "direct"]
    assert {(r["fb_twins_w_star"], r["p_w_star_method"]) for r in pursuit} == {(12, "gpd tail")}
    assert all(0 < r["p_w_star"] < 1 / 13 for r in pursuit)
    groups = pq.read_table(run / tables.ANALYSIS_GROUPS.file).to_pylist()
    assert {
        g["fb_twins"] for g in groups if g["group"] == "condition=pursuit" and g["method"] == "direct"
    } == {12}


def test_the_line_statistics_p_values_and_the_deciding_statistic_come_from_the_twins(analysed):
    # Source: SPEC 11 as for W* (the test above): each line statistic's p-value over its set's FB
    # twins in evidence_twins.parquet, sequential where it decides, else over the calibration's 4;
    # the deciding statistic is the one whose calibration twins have the highest median power
    # over the group's runs (hcid.selection.calibration.evidence_power), the first of TIE_ORDER on a
    # tie (W*, the likelihood ratio, the Fourier size).
    from hcid.pipeline.evidence import STATISTICS, TIE_ORDER
    from hcid.pipeline.line_statistics import LINE_STATISTICS
    from hcid.selection.calibration import evidence_power, run_p_value

    _, out = analysed
    run = out[1][0]
    rows = pq.read_table(run / tables.ANALYSIS.file).to_pylist()
    twins = pq.read_table(run / tables.EVIDENCE_TWINS.file).to_pylist()
    assert all(np.isfinite(r["likelihood_ratio"]) for r in rows)  # below 0: a slope (hcid.hcfit.lr)
    for r in rows:
        mine = [
            t
            for t in twins
            if (t["group"], t["method"], t["forcing_set"]) == (r["group"], r["method"], r["forcing_set"])
        ]
        for name, (column, stem) in LINE_STATISTICS.items():
            fb = np.array([t[column] for t in sorted(mine, key=lambda t: t["seed"]) if t["twin"] == "FB"])
            fb = fb[np.isfinite(fb)]
            assert fb.size == (len([t for t in mine if t["twin"] == "FB"]) if r["decided_by"] == name else 4)
            hits = np.cumsum(fb >= r[column])
            if r["decided_by"] == name and hits[-1] >= 5:
                m = int(np.argmax(hits >= 5)) + 1
                assert (r[f"p_{stem}"], r[f"fb_twins_{stem}"]) == (5 / m, m)
            else:
                assert (r[f"p_{stem}"], r[f"fb_twins_{stem}"]) == (run_p_value(r[column], fb)[0], fb.size)
    # The pursuit runs' feedforward is strong: every FF twin's ratio is above every FB twin's.
    pursuit = [t for t in twins if t["group"] == "condition=pursuit"]
    assert min(t["likelihood_ratio"] for t in pursuit if t["twin"] == "FF") > max(
        t["likelihood_ratio"] for t in pursuit if t["twin"] == "FB"
    )
    for (group, method), group_rows in _by(rows, "group", "method").items():
        calibration = [t for t in twins if (t["group"], t["method"]) == (group, method)]
        ff = {n: np.array([t[c] for t in calibration if t["twin"] == "FF"]) for n, c in _COLUMNS.items()}
        fb = {
            n: np.array([t[c] for t in calibration if t["twin"] == "FB" and t["seed"] <= 4])
            for n, c in _COLUMNS.items()
        }
        power = {n: evidence_power(ff[n], fb[n], 0.05) for n in STATISTICS}
        best = max(power.values())
        assert group_rows[0]["decided_by"] == next(n for n in TIE_ORDER if power[n] == best)
    assert sorted(TIE_ORDER) == sorted(STATISTICS)


_COLUMNS = {"W*": "w_star", "Fourier coefficients": "fourier_size", "likelihood ratio": "likelihood_ratio"}


def _by(rows, *keys):
    out = {}
    for r in rows:
        out.setdefault(tuple(r[k] for k in keys), []).append(r)
    return out


def test_a_group_whose_own_twins_no_w_separates_is_calibrated_on_the_studys_feedforward(analysed):
    # --ff-twin auto (the default): the compensatory condition (nobody uses feedforward) has own
    # twins that nearly coincide; for every method where no W separates them, its FF twin takes
    # the pursuit condition's fitted feedforward path on its own feedback (module notes).
    _, out = analysed
    run = out[1][0]
    groups = pq.read_table(run / tables.ANALYSIS_GROUPS.file).to_pylist()
    pursuit = next(g for g in groups if g["group"] == "condition=pursuit")
    calibration = {}
    for g in groups:
        own = g["twins_folder"].removesuffix("-study")
        table = pq.read_table(run / own / tables.CALIBRATION.file).to_pylist()
        calibration[g["group"], g["method"]] = next(r for r in table if r["method"] == g["method"])
    for g in groups:
        own = calibration[g["group"], g["method"]]
        separated = np.isfinite(own["safe_low"]) and np.isfinite(own["recommended"])
        if g["group"] == "condition=pursuit":  # the strongest feedforward: its own twins always
            assert g["ff_twin"] == "own" and not g["twins_folder"].endswith("-study")
            continue
        assert g["ff_twin"] == ("own" if separated else "study")
        if g["ff_twin"] == "study":
            assert g["twins_folder"].endswith("-study")
            for p in ("Kpt", "TI", "tau_pt"):  # the pursuit condition's feedforward ...
                assert g[f"twin_{p}"] == pytest.approx(pursuit[f"twin_{p}"])
            assert g["twin_Kpe"] != pursuit["twin_Kpe"]  # ... on the group's own feedback
            assert g["fitted_Kpt"] < 0.5 * g["twin_Kpt"]
    assert any(g["ff_twin"] == "study" for g in groups)


def test_model_free_estimates_are_written_per_group(analysed):
    _, out = analysed
    fc = pq.read_table(out[1][0] / tables.FC_ESTIMATES.file).to_pylist()
    # The example's multisines: 10 disturbance and 10 target lines per group, no problem.
    for group in ("condition=pursuit", "condition=compensatory"):
        mine = [r for r in fc if r["group"] == group]
        assert sorted({r["path"] for r in mine}) == ["e", "ft"]
        assert sum(r["path"] == "e" for r in mine) == 10 and sum(r["path"] == "ft" for r in mine) == 10
        assert all(r["problem"] == "" for r in mine)
    # He at the disturbance lines: the fitted model within a few dB of the estimate below 10 rad/s.
    low = [r for r in fc if r["path"] == "e" and r["omega"] < 10]
    assert np.median([abs(r["magnitude_db"] - r["model_db"]) for r in low]) < 2.0


@pytest.mark.parametrize(
    "name", [tables.ANALYSIS.file, tables.ANALYSIS_GROUPS.file, tables.FC_ESTIMATES.file]
)
def test_the_same_bytes_for_any_number_of_workers(analysed, name):
    _, out = analysed
    assert (out[1][0] / name).read_bytes() == (out[2][0] / name).read_bytes()


def test_bad_requests_are_one_line(analysed, tmp_path):
    data, _ = analysed
    run = tmp_path / "run"
    manifest = tmp_path / "manifest.csv"
    manifest.write_text(
        "file,group\n" + "".join(f"{p},{i % 2}\n" for i, p in enumerate(sorted(data.glob("*.csv"))))
    )
    (tmp_path / "m2").mkdir()
    missing = tmp_path / "m2" / "manifest.csv"
    missing.write_text("file,subject\nS9_pursuit_trial1.csv,S9\n")
    frequency = tmp_path / "frequency.yaml"
    frequency.write_text(CONFIG.read_text() + "fit_hc: {target: frequency}\n")
    cases = [
        (
            [str(CONFIG), "--data", str(data), "--by", "session"],
            "--by session: the data set has no factor 'session'",
        ),
        (
            [str(CONFIG), "--data", str(data), "--twins", "1"],
            "twins (--twins): must be an integer in [2, 1000], got 1",
        ),
        # A factor named like a column of the analysis tables (the review found a traceback).
        (
            [str(CONFIG), "--data", str(manifest)],
            "factor 'group': the analysis tables have a column of that name",
        ),
        ([str(CONFIG), "--data", str(missing)], "row 2: S9_pursuit_trial1.csv: no such file"),
        ([str(frequency), "--data", str(data)], "fit_hc.target: frequency fits an ARX model's responses"),
    ]
    for args, message in cases:
        result = runner.invoke(app, ["analyse", *args, "--run", str(run)])
        assert result.exit_code == 2
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and message in lines[0]
        assert not run.exists()


def test_the_report_answers_first(analysed):
    # A measured study's report, written by `hcid analyse` itself (issue 35): the answer per group
    # first, no paper sections, no "missing".
    _, out = analysed
    run, output = out[1]
    report = run / "report"
    assert f"report: {report / 'report.html'}" in output
    text = (report / "report.md").read_text()
    assert text.index("## The study's answer") < text.index("| verdict |") < text.index("feedforward at W")
    assert "Missing stages" not in text and "Fig." not in text
    names = sorted(p.name for p in report.glob("*.png"))
    for stem in ("calibration_pursuit-", "calibration_compensatory-", "fc_pursuit-", "fc_compensatory-"):
        assert sum(n.startswith(stem) and "-study" not in n for n in names) == 1, (stem, names)
    # Each group's runs drawn on their twins' W* (SPEC 11), per method.
    assert sum(n.startswith("evidence_") for n in names) == 4
    # The compensatory condition's study twins (the test above) have their figure too.
    assert sum(n.startswith("calibration_compensatory-") and n.endswith("-study.png") for n in names) == 1
    assert "study's FF (Kpt" in text
    # Each calibration figure's caption says, per method, what it marks: a safe interval's
    # recommended W, or the W used where there is none (the groups table says which).
    for g in pq.read_table(run / tables.ANALYSIS_GROUPS.file).to_pylist():
        figure = f"calibration_{g['twins_folder'].split('/')[-1]}.png"
        caption = next(line for line in text.splitlines() if figure in line)
        safe = g["w_rule"] == "safe interval"
        said = "the safe interval and its recommended W" if safe else "the W used, the least total error"
        assert f"{g['method']}: {said}" in caption, (g["group"], g["method"], caption)


def test_compare_gives_each_quantitys_effect_across_subjects(analysed):
    # Issue 49: --compare condition writes study_effects.parquet (its schema) and .csv (the same
    # rows), per source (method) and quantity each test's effect of pursuit against compensatory (the first
    # level, sorted, is the reference); every run is counted once per quantity, as compared or left
    # out (8 runs per method); the answer names the effects at p <= 0.05 after Holm's correction,
    # and the report has its section with the forest plot. The API's run compared nothing: none.
    import pandas as pd

    from hcid.analysis.effects import CIRCULAR, MIXED, WILCOXON
    from hcid.pipeline.effects import MODEL_FREE

    _, out = analysed
    run, output = out[1]
    effects = pq.read_table(run / tables.STUDY_EFFECTS.file)
    assert tables.STUDY_EFFECTS.problem(effects) is None
    rows = effects.to_pylist()
    assert len(pd.read_csv(run / "study_effects.csv")) == len(rows)
    quantities = {*tables.HC_PARAMETER_NAMES, "crossover", "phase_margin", "remnant_share_data"}
    fitted = {(r["source"], r["quantity"]) for r in rows if r["source"] != MODEL_FREE}
    assert fitted == {(m, q) for m in ("direct", "indirect") for q in quantities}
    assert {r["effect"] for r in rows} == {"condition: pursuit - compensatory"}
    # Each run's Fourier-coefficient responses at the lines (SPEC 10), magnitude in dB and phase
    # in deg (the phase also by circular statistics), their own family: the source "model-free".
    free = [r for r in rows if r["source"] == MODEL_FREE]
    assert free and all(
        r["quantity"].startswith(("|He| at", "He phase at", "|Ht| at", "Ht phase at")) for r in free
    )
    phases = {r["quantity"] for r in free if "phase" in r["quantity"]}
    assert phases and {r["quantity"] for r in free if r["test"] == CIRCULAR} == phases
    assert {r["unit"] for r in free} == {"dB", "deg"}
    for r in rows:
        if r["test"] == MIXED:
            assert r["runs"] + r["left_out"] == 8, r
        assert r["test"] in (MIXED, WILCOXON, CIRCULAR)
        assert r["subjects"] <= 2
    holm = [r for r in rows if r["test"] == MIXED and np.isfinite(r["p"])]
    assert all(r["p_holm"] >= r["p"] for r in holm)
    assert "EFFECTS of condition (--compare" in output
    text = (run / "report" / "report.md").read_text()
    assert "## What differs between conditions" in text and (run / "report" / "effects_forest.png").is_file()
    assert not (out[2][0] / tables.STUDY_EFFECTS.file).exists()


@pytest.mark.parametrize(
    ("compare", "said"),
    [
        ("subject", "names the people"),
        ("session", "no factor 'session'"),
        ("trial x", "must be a factor"),
        ("run", "no factor 'run'"),  # a data set's row names its run: not a factor
        ("file", "no factor 'file'"),
    ],
)
def test_a_comparison_that_cannot_be_made_is_refused_before_anything_is_written(
    analysed, tmp_path, compare, said
):
    data, _ = analysed
    run = tmp_path / "run"
    args = ["analyse", str(CONFIG), "--data", str(data), "--run", str(run), "--compare", compare, "--quiet"]
    result = runner.invoke(app, args)
    assert result.exit_code == 2 and said in result.output, result.output
    assert "'model'" not in result.output and "'seed'" not in result.output  # hcid's columns, not factors
    assert not run.exists() or not any(run.iterdir())


def test_the_lab_example_report_fits_a_1400_px_page(analysed, tmp_path):
    # Issue 46 (1): the lab example's answer table was clipped at the page's right edge, inside a
    # scroll box wider than the page. Rendered in headless Chromium at 1400 px, no table, figure
    # or box of this study's report is wider than the page (skipped without Chromium; CI has it).
    from .test_report import wider_than_the_page

    _, out = analysed
    run, _ = out[1]
    found = wider_than_the_page(run / "report" / "report.html", tmp_path)
    if found is None:
        pytest.skip("Chromium is not installed")
    assert found == "0 ", found


def test_a_run_directory_of_another_measured_study_names_the_data_and_analyse_force(analysed, tmp_path):
    # Measured data are not simulated: another study's config in the same run directory (here the
    # plant changed) is refused naming the first key that differs and `hcid analyse --force`, not
    # "simulated with another config ... hcid simulate --force" as before.
    import yaml

    data, out = analysed
    run = tmp_path / "run"
    shutil.copytree(out[1][0], run)
    raw = yaml.safe_load(CONFIG.read_text())
    raw["loop"]["plant"]["K"] = 1.6
    other = tmp_path / "other.yaml"
    other.write_text(yaml.safe_dump(raw))
    args = ["analyse", str(other), "--data", str(data), "--run", str(run), "--twins", "4", "--quiet"]
    result = runner.invoke(app, args)
    assert result.exit_code == 2
    assert result.stderr.startswith(f"hcid: error: {run}: made with another config (loop.plant.K differs)")
    assert "`hcid analyse --force` for measured data" in result.stderr


def test_a_simulation_studys_run_directory_is_never_given_measured_results(analysed, tmp_path):
    # A reviewer's case: the refusal above must not open a simulated study's directory to measured
    # data, even with --force (its simulations would stay beside the measured results).
    data, _ = analysed
    run = tmp_path / "sim"
    from .conftest import CI_CONFIG

    assert runner.invoke(app, ["simulate", str(CI_CONFIG), "--run", str(run), "--quiet"]).exit_code == 0
    before = sorted(p.name for p in run.iterdir())
    args = [
        "analyse",
        str(CONFIG),
        "--data",
        str(data),
        "--run",
        str(run),
        "--twins",
        "4",
        "--quiet",
        "--force",
    ]
    result = runner.invoke(app, args)
    assert result.exit_code == 2 and "simulated with another config" in result.stderr
    assert sorted(p.name for p in run.iterdir()) == before


def test_every_group_has_its_own_twins_folder():
    # Source: the review's collision, "a b" and "a-b" (and ("x_y", "z") against ("x", "y_z")),
    # once made safe for a path, were one folder: the digest of the values tells them apart.
    from hcid.pipeline.twins import group_slug as _slug

    assert _slug(("a b",)) != _slug(("a-b",))
    assert _slug(("x_y", "z")) != _slug(("x", "y_z"))
    assert _slug(("pursuit",)).startswith("pursuit-")


def test_unreadable_files_are_refused_or_set_aside_and_listed(tmp_path):
    # Issue 35: by default a file that cannot be read refuses the data set in one line (exit 2,
    # nothing written); with --skip-unreadable it is left out and listed in the answer, the table
    # set_aside.parquet and the report, and the others are analysed.
    data = tmp_path / "data"
    data.mkdir()
    for path in sorted(LAB.glob("S1_*_trial1.csv")):
        shutil.copy(path, data / path.name)
    (data / "S2_pursuit_trial1.csv").write_text("this is not\na data file\n")
    # Readable, but 2 s long: too short for the analysis windows (refused when the set is read).
    lines = (LAB / "S1_pursuit_trial1.csv").read_text().splitlines()
    (data / "S2_compensatory_trial1.csv").write_text("\n".join(lines[:130]) + "\n")
    run = tmp_path / "run"
    args = ["analyse", str(CONFIG), "--data", str(data), "--run", str(run), "--twins", "2",
            "--max-fb-twins", "2", "--quiet"]  # fmt: skip
    refused = runner.invoke(app, args)
    # Every file is read once before any is taken to the analysis rate: the unreadable one is
    # named first (the short one's "run 1: 43 samples" comes with --skip-unreadable, below).
    assert refused.exit_code == 2
    assert "S2_pursuit_trial1.csv: columns ['this is not'] differ" in refused.output
    assert len(refused.output.strip().splitlines()) == 1 and not run.exists()
    result = runner.invoke(app, [*args, "--skip-unreadable"])
    assert result.exit_code == 0, result.output
    assert "SET ASIDE (--skip-unreadable): 2 file(s)" in result.output
    assert "S2_pursuit_trial1.csv" in result.output
    aside = pq.read_table(run / tables.SET_ASIDE.file).to_pylist()
    # Listed in the files' order, each with its reason.
    assert [Path(r["file"]).name for r in aside] == ["S2_compensatory_trial1.csv", "S2_pursuit_trial1.csv"]
    assert "run 1: 43 samples" in aside[0]["reason"] and "differ from" in aside[1]["reason"]
    assert {r["file"] for r in pq.read_table(run / tables.ANALYSIS.file).to_pylist()} == {
        "S1_compensatory_trial1.csv",
        "S1_pursuit_trial1.csv",
    }
    assert "**Set aside:** 2 file(s)" in (run / "report" / "report.md").read_text()


def test_undetermined_parameters_are_one_entry_per_parameter_with_each_reason_counted():
    # One entry per parameter: its runs left out in total, then the count of each reason
    # (a run has one status, so the counts add up; SPEC 11's reasons as the fits give them).
    from hcid.cli.answers import _analysis_parameters
    from hcid.pipeline.evidence import ParameterSummary

    reasons = {"correlated with Kpe": 4, "correlated with tau_pe": 4, "at a search bound": 1}
    tl = ParameterSummary("TL", "s", 12, 3, 0.091, 0.018, 0.01, reasons)
    kpe = ParameterSummary("Kpe", "-", 12, 12, 2.28, 0.16, 0.05, {})
    w_nms = ParameterSummary("w_nms", "rad/s", 12, 4, 11.6, 0.62, 1.0, {"fixed at a literature value": 8})
    text = _analysis_parameters([kpe, tl, w_nms])
    assert "Kpe 2.28 (12 of 12 runs, sd 0.16), TL 0.091 s (3 of 12 runs, sd 0.018)" in text
    assert text.endswith(
        "not determined, left out: TL in 9 of 12 runs (4\u00d7 correlated with Kpe, 4\u00d7 correlated with "
        "tau_pe, 1\u00d7 at a search bound); w_nms in 8 of 12 runs (fixed at a literature value)"
    )


def test_runs_without_any_path_at_w_are_counted_and_said():
    # The CPHS fo direct selection at its calibrated W of 0.288 (2af54b2's twins, which did not
    # anticipate): 5 of 6 runs kept neither path (na = 1, nb_ft = nb_e = 0); the answer line says
    # so instead of reading "no feedforward". A run with feedforward but no feedback path (CPHS
    # so gy +1, direct: nb_ft 1, nb_e 0) keeps a path: not counted.
    from hcid.cli.answers import _without_paths
    from hcid.pipeline.summary import GroupSummary

    runs = [{"nb_ft": 0, "nb_e": n} for n in (0, 1, 0, 0, 0, 0)] + [{"nb_ft": 1, "nb_e": 0}]
    summary = GroupSummary({}, runs, (0.9, 1.0), [], 1.5, 55.0)
    assert summary.without_paths == 5
    assert _without_paths(summary) == (
        "; at this W 5 of 7 runs keep no path at all (nb_ft = nb_e = 0): W is beyond what their data support"
    )
    assert _without_paths(GroupSummary({}, runs[1:2] + runs[-1:], (0.9, 1.0), [], 1.5, 55.0)) == ""


def test_feedforward_parameters_fitted_in_fewer_runs_say_so():
    # The lab example's pursuit direct group: Kpt "10 of 10 runs" read as the whole group of 12;
    # the two runs whose selection at W drops feedforward were fitted without it.
    from hcid.cli.answers import _analysis_parameters
    from hcid.pipeline.evidence import ParameterSummary

    kpe = ParameterSummary("Kpe", "-", 12, 12, 2.28, 0.16, 0.05, {})
    kpt = ParameterSummary("Kpt", "-", 10, 10, 0.891, 0.11, 0.04, {})
    text = _analysis_parameters([kpe, kpt], 12)
    assert text.endswith(
        "Kpt 0.891 (10 of 10 runs, sd 0.11); Kpt fitted only in the 10 of 12 runs whose selection at W "
        "keeps feedforward (the others' fits have none)"
    )
    assert "fitted only" not in _analysis_parameters([kpe, kpt], 10)


def test_flagged_values_are_counted_inside_their_entry_without_nested_parentheses():
    # A kept value outside its plausible range or not told from 0 is counted where it is shown
    # (SPEC 11's flags; the CPHS fo direct runs: tau_pe 0.053 s in 2 of its 4 runs).
    from hcid.cli.answers import _analysis_parameters
    from hcid.pipeline.evidence import ParameterSummary

    tau = ParameterSummary("tau_pe", "s", 6, 4, 0.0981, 0.064, 0.01, {}, {"outside its plausible range": 2})
    ti = ParameterSummary("TI", "s", 1, 1, 0.0843, 0.0, 0.1, {}, {"not told from 0 (se above |value|)": 1})
    assert _analysis_parameters([tau, ti]).endswith(
        "tau_pe 0.0981 s (4 of 6 runs, sd 0.064; 2 of them outside its plausible range), "
        "TI 0.0843 s (1 of 1 runs; 1 of them not told from 0: se above |value|)"
    )


def test_a_verdict_carried_by_one_subject_is_said_with_each_subjects_count():
    # The CPHS so direct group: 2 of 6 runs at p <= 0.05 (binomial p 0.033, FEEDFORWARD), both of
    # subject ef's two trials; the binomial counts runs, so the answer says it rests on one person.
    # Source for the per-subject p: Binomial(2, 0.05), P(2 of 2) = 0.0025.
    from hcid.cli.answers import _subjects_line
    from hcid.pipeline.summary import GroupSummary

    p = {"dp": (0.5, 0.3), "ef": (0.03, 0.01), "gy": (0.45, 0.71)}
    runs = [{"subject": s, "p_value": v} for s, pair in p.items() for v in pair]
    group = {"alpha": 0.05, "verdict": "FEEDFORWARD"}
    summary = GroupSummary(group, runs, (0.3, 0.3), [], 1.5, 55.0)
    assert [(s, k, n) for s, k, n, _ in summary.by_subject()] == [("dp", 0, 2), ("ef", 2, 2), ("gy", 0, 2)]
    assert summary.by_subject()[1][3] == pytest.approx(0.05**2)
    assert _subjects_line(summary) == (
        "    by subject, runs at p <= 0.05: dp 0 of 2, ef 2 of 2 (binomial p = 0.0025), gy 0 of 2; "
        "every run at p <= 0.05 is ef's: the verdict rests on one person"
    )
    # Several subjects with evidence, or no FEEDFORWARD verdict, or one subject only: not said.
    runs[0]["p_value"] = 0.01
    assert GroupSummary(group, runs, (0.3, 0.3), [], 1.5, 55.0).one_subject is None
    one = GroupSummary({**group, "verdict": "UNCERTAIN"}, runs[2:4], (0.3, 0.3), [], 1.5, 55.0)
    assert one.by_subject() == [] and one.one_subject is None  # runs of one subject: no split


def test_each_statistics_verdict_is_given_and_a_disagreement_with_power_said():
    # The sessions' gy fo group, direct method (docs/measured-studies.md): W* decides (power 0.95)
    # with 2 of 10 runs at p <= 0.05, binomial p 0.086: NO FEEDFORWARD SHOWN; the likelihood ratio
    # (power 0.90) has all 10 at p <= 0.05. Source for the binomial p's: P(X >= 2 | Bin(10, 0.05))
    # = 1 - 0.95**10 - 10 * 0.05 * 0.95**9 = 0.0861; P(X >= 10) = 0.05**10. The Fourier size has
    # no p in one run: one of the 10, never found (as the group's verdict counts it), so its count
    # (3 of 10 significant) has power 1 - 0.9**9 - 9 * 0.1 * 0.9**8 - 36 * 0.01 * 0.9**7 = 0.053.
    from hcid.cli.answers import _statistics_line
    from hcid.pipeline.summary import GroupSummary

    runs = [
        {"p_value": p, "power": 0.95, "p_w_star": p, "power_w_star": 0.95, "p_lr": 0.01, "power_lr": 0.9,
         "p_fourier": 0.5 if k else float("nan"), "power_fourier": 0.1}
        for k, p in enumerate([0.01, 0.04] + [0.5] * 8)
    ]  # fmt: skip
    group = {"alpha": 0.05, "verdict": "NO FEEDFORWARD SHOWN", "decided_by": "W*", "ff_twin": "own"}
    summary = GroupSummary(group, runs, (0.95, 0.95), [], 1.5, 55.0)
    got = {s.name: (s.verdict, s.n_evidence, s.n_runs, s.deciding) for s in summary.statistics}
    assert got == {
        "W*": ("NO FEEDFORWARD SHOWN", 2, 10, True),
        "Fourier coefficients": ("UNCERTAIN", 0, 10, False),  # the run without a p among the 10
        "likelihood ratio": ("FEEDFORWARD", 10, 10, False),
    }
    assert summary.statistics[0].binomial_p == pytest.approx(1 - 0.95**10 - 10 * 0.05 * 0.95**9)
    assert [s.name for s in summary.disagreeing] == ["likelihood ratio"]
    assert _statistics_line(summary) == (
        "    per statistic, runs at p <= 0.05 and their twins' median power: W* 2 of 10 (power 0.95, its "
        "count's 1.00; decides), Fourier coefficients 0 of 10 (power 0.10, its count's 0.05), likelihood "
        "ratio 10 of 10 (power 0.90, its count's 1.00); "
        "THE STATISTICS DISAGREE: the likelihood ratio alone, with power 0.90 (its count's 1.00), says "
        "FEEDFORWARD (10 of 10 runs; binomial p = 9.8e-14)"
    )
    # Without the power to tell, another verdict is not a disagreement: runs of power 0.2 make a count
    # of power 0.32 (3 of 10 are significant: P(X >= 3 | Bin(10, 0.2)) = 1 - 0.8**10 - 10 * 0.2 *
    # 0.8**9 - 45 * 0.04 * 0.8**8); runs of power 0.5 one of 0.95, which can tell.
    weak = [{**r, "power_lr": 0.2} for r in runs]
    assert GroupSummary(group, weak, (0.95, 0.95), [], 1.5, 55.0).statistics[2].group_power == pytest.approx(
        1 - 0.8**10 - 10 * 0.2 * 0.8**9 - 45 * 0.04 * 0.8**8
    )
    half = [{**r, "power_lr": 0.5} for r in runs]
    assert [s.name for s in GroupSummary(group, half, (0.95, 0.95), [], 1.5, 55.0).disagreeing] == [
        "likelihood ratio"
    ]
    assert GroupSummary(group, weak, (0.95, 0.95), [], 1.5, 55.0).disagreeing == []
    # The other way round: the ratio decides FEEDFORWARD, W* with power finds nothing.
    found = GroupSummary({**group, "verdict": "FEEDFORWARD", "decided_by": "likelihood ratio"}, runs,
                         (0.9, 0.9), [], 1.5, 55.0)  # fmt: skip
    assert [(s.name, s.verdict) for s in found.disagreeing] == [("W*", "NO FEEDFORWARD SHOWN")]


# --------------------------------------------------------------------------- twins of any group's fit

# Subject dp's two fo trials of assay a4 (../shared/data/cphs2017-sessions/dp, `hcid analyse --by assay`
# on the two-input trials, the issue's reproduction): both fits put tau_pe on its bound at 0 s (the
# neuromuscular lag, w_nms 2-3 rad/s, takes the delay's place), TI on its bound; the medians make
# an unstable loop with the plant 1/s, and the study stopped at this group.
A4_RUNS = {
    5: ({"Kpe": 5.3781, "TL": 0.3814, "tau_pe": 0.0, "w_nms": 2.0301, "zeta_nms": 1.4798,
         "Kpt": 1.0527, "TI": 0.01, "tau_pt": -0.2329}, ("tau_pe", "zeta_nms", "TI")),
    6: ({"Kpe": 3.2035, "TL": 0.1913, "tau_pe": 0.0, "w_nms": 3.0197, "zeta_nms": 2.0,
         "Kpt": 1.7384, "TI": 0.01, "tau_pt": -0.1995}, ("tau_pe", "zeta_nms", "TI")),
}  # fmt: skip
A4_SOURCE = (
    "run 5's own model (the medians make an unstable loop with the plant; tau_pe 0.000 s raised to one "
    "sample of the twins' simulation, 0.01 s at 100 Hz"
)


def _a4_fit(seed):
    from hcid.hcfit import HCFit

    values, on_bound = A4_RUNS[seed]
    names = tuple(values)
    return HCFit(
        target="lines", names=names, estimates=tuple(values.values()),
        at_bound=tuple(n in on_bound for n in names), cost=1.0, starts=1, start_costs=(1.0,),
        vaf_validation=50.0, se=tuple(0.01 for _ in names), partner=tuple("" for _ in names),
        correlation=tuple(0.1 for _ in names),
    )  # fmt: skip


@pytest.fixture(scope="module")
def fo_study():
    """The lab example's config with the CPHS fo plant (1/s, the disturbance at its input) and one
    of its records, whose ft and fd drive the twins."""
    from dataclasses import replace

    from hcid.assembly.resolve import read_study, with_data
    from hcid.config import Plant

    config, data = read_study(CONFIG, [str(LAB / "S1_pursuit_trial1.csv")])
    config = with_data(config)
    loop_raw = {**config.raw["loop"], "plant": {"kind": "integrator", "K": 1.0}}
    config = replace(
        config, loop=replace(config.loop, plant=Plant.integrator(1.0)), raw={**config.raw, "loop": loop_raw}
    )
    return config, next(iter(data.records.values()))


def _twins_config(config, record, values, remnant=(3.0, 8.0, 2.0)):
    """The twins' config of a model, parsed as hcid analyse parses it (ranges, whole samples,
    stable loops: hcid.pipeline.twins._twin_folder)."""
    from hcid.assembly.resolve import parse_config
    from hcid.pipeline.twins import twin_config_raw

    n = round(config.timing.window * config.timing.output_rate)
    raw = twin_config_raw(config, values, remnant, Path("forcing.csv"), 2, "twins")
    return parse_config(raw, "twins", forcing={"target": record["ft"][:n], "disturbance": record["fd"][:n]})


def test_a_group_whose_fallback_run_has_its_delay_at_0_gets_twins_the_config_takes(fo_study):
    from hcid.cli.answers import _model_source
    from hcid.hcfit.determined import group_model
    from hcid.pipeline.twin_values import twin_model, twin_values

    config, record = fo_study
    plant = (np.array(config.loop.plant.num), np.array(config.loop.plant.den))
    fits = [_a4_fit(5), _a4_fit(6)]
    model = group_model(fits, ["run 5", "run 6"], *plant, lambda v: twin_model(v, 100.0, config.loop))
    assert model.source == A4_SOURCE + ")"
    assert model.values == A4_RUNS[5][0]  # the table's fitted_tau_pe stays the fit's 0 s
    assert twin_values(model.values, 100.0)["tau_pe"] == 0.01
    twins = _twins_config(config, record, model.values)
    assert [(m.name, m.tau_pe, m.Kpe) for m in twins.models] == [("FB", 0.01, 5.3781), ("FF", 0.01, 5.3781)]
    # The answer line carries it, in its one pair of parentheses.
    said = _model_source({"twin_source": model.source})
    assert said.startswith(" (run 5's own model: the medians make") and said.count("(") == 1


def test_the_twins_ranges_are_those_their_config_takes(fo_study):
    # Source: hcid.config.parse (models and loop sections) refuses just beyond each end of
    # TWIN_RANGES, and takes each end it does not refuse.
    import copy

    from hcid.config.parse import describe_config
    from hcid.errors import ConfigError
    from hcid.pipeline.twin_values import TWIN_RANGES
    from hcid.pipeline.twins import twin_config_raw

    config, _ = fo_study
    base = twin_config_raw(config, A4_RUNS[6][0], (3.0, 8.0, 2.0), Path("forcing.csv"), 2, "twins")
    where = {"kn": ("loop", "remnant_gain"), "w_n": ("loop", "w_n"), "zeta_n": ("loop", "zeta_n"),
             "w_nms": ("loop", "w_nms"), "zeta_nms": ("loop", "zeta_nms")}  # fmt: skip

    def described(name, value):
        raw = copy.deepcopy(base)
        section, key = where.get(name, ("models", name))
        for target in [raw["loop"]] if section == "loop" else [raw["models"]["FF"]]:
            target[key] = value
        return describe_config(raw, "twins")

    for name, (lo, hi, open_lo) in TWIN_RANGES.items():
        described(name, hi)
        with pytest.raises(ConfigError, match=f"{name if name not in where else where[name][1]}: must be"):
            described(name, hi + 0.01)
        with pytest.raises(ConfigError):
            described(name, lo if open_lo else lo - 0.01)
        if not open_lo:
            described(name, lo)


def test_values_the_twins_cannot_take_are_brought_into_range_or_named(fo_study):
    from hcid.pipeline.twin_values import twin_model, twin_remnant

    config, record = fo_study
    far = {**A4_RUNS[6][0], "Kpe": 150.0, "tau_pt": -2.5, "tau_pe": 0.004}
    sim = twin_model(far, 100.0)
    assert (sim.values["Kpe"], sim.values["tau_pt"], sim.values["tau_pe"]) == (100.0, -2.0, 0.01)
    assert sim.changes == (
        "tau_pt -2.500 s raised to -2 s, the shortest the twins take",
        "Kpe 150 lowered to 100, the most the twins take",
        "tau_pe 0.004 s raised to one sample of the twins' simulation, 0.01 s at 100 Hz",
    )
    # No feedback gain has no nearest value the twins take. Kpe 15 with tau_pe 0.3 s on 1/s crosses
    # over near 15 rad/s with ~260 deg of delay lag: unstable (tests/test_hcfit_lines.py's source).
    assert twin_model({**far, "Kpe": 0.0}, 100.0).problem == "Kpe is 0, where the twins need a value above 0"
    late = {**far, "Kpe": 15.0, "tau_pe": 0.3, "w_nms": 10.1, "zeta_nms": 0.35}
    unstable = twin_model(late, 100.0, config.loop)
    assert unstable.problem == "the loop with the plant is unstable as the twins simulate it at 100 Hz"
    # What twin_model takes, the twins' config takes.
    taken = twin_model({**far, "Kpe": 3.2035}, 100.0, config.loop)
    assert taken.problem == "" and _twins_config(config, record, {**far, "Kpe": 3.2035}).models
    remnant = twin_remnant((2000.0, 8.0, 2.0))
    assert remnant.values == {"kn": 1000.0, "w_n": 8.0, "zeta_n": 2.0}
    assert remnant.changes == ("kn 2e+03 lowered to 1000, the most the twins take",)


def test_a_group_whose_remnant_fits_are_all_on_their_bounds_still_gets_twins(fo_study):
    # Before: "no run's remnant could be fitted; cannot build its twins" stopped the study. The
    # medians over the fits on their bounds are used (their level still measures the remnant), and
    # source says so; only a group without any remnant fit has no twins.

    from hcid.analysis.descriptors import RemnantFit
    from hcid.errors import DataError
    from hcid.pipeline.fit_hc import RunFits
    from hcid.pipeline.twins import group_models

    config, _ = fo_study
    spectrum = np.zeros(1)  # not read
    remnants = {5: RemnantFit(2.0, 0.5, 1.0, 100.0, True, spectrum, spectrum, spectrum),
                6: RemnantFit(4.0, 12.0, 5.0, 100.0, True, spectrum, spectrum, spectrum)}  # fmt: skip
    groups = {("4",): [5, 6]}
    fitted = {s: RunFits(s, _a4_fit(s), None, remnants[s]) for s in (5, 6)}
    models, remnant = group_models(config, groups, fitted)
    assert models[("4",)].source == A4_SOURCE + "; its remnant filter from fits on their search bounds)"
    assert remnant[("4",)] == (3.0, 6.25, 3.0)  # medians of the two
    assert remnant[("4",)].w_n == 6.25
    fitted = {s: RunFits(s, _a4_fit(s), None, None) for s in (5, 6)}
    with pytest.raises(DataError, match="group 4-.*: no run's remnant could be fitted"):
        group_models(config, groups, fitted)
    # With another group whose runs can: the study goes on, this group's twins with its own model
    # and the remnant filter of every run of the study (said so), the other group's its own.
    groups = {("4",): [5], ("5",): [6]}
    fitted = {5: RunFits(5, _a4_fit(5), None, None), 6: RunFits(6, _a4_fit(6), None, remnants[6])}
    models, remnant = group_models(config, groups, fitted)
    assert models[("4",)].source.endswith(
        "its own runs cannot make twins (no run's remnant could be fitted): the study's remnant filter)"
    )
    assert remnant[("4",)] == remnant[("5",)] == (4.0, 12.0, 5.0)


def test_the_issues_group_gets_twins_their_config_takes(fo_study):
    # The issue's failure, through the same calls as hcid analyse: the group's model, then its
    # twins' config parsed ("models.FB.tau_pe: must be a number in (0, 2], got 0.0" before).

    from hcid.analysis.descriptors import RemnantFit
    from hcid.pipeline.fit_hc import RunFits
    from hcid.pipeline.twins import group_models

    config, record = fo_study
    spectrum = np.zeros(1)  # not read
    fitted = {
        s: RunFits(s, _a4_fit(s), None, RemnantFit(3.0, 8.0, 2.0, 100.0, False, spectrum, spectrum, spectrum))
        for s in (5, 6)
    }
    models, remnants = group_models(config, {("4",): [5, 6]}, fitted)
    model = models[("4",)]
    twins = _twins_config(config, record, model.values, remnants[("4",)])
    assert {m.tau_pe for m in twins.models} == {0.01}
    assert model.source == A4_SOURCE + ")"


def test_few_twins_recomputes_every_stored_p(analysed):
    # Source: analysis.parquet's p_value, made by hcid analyse from evidence_twins.parquet's FB
    # twins in the order drawn: benchmarks/few_twins.py must get it back from the two tables.
    import importlib.util

    spec = importlib.util.spec_from_file_location("few_twins", LAB.parents[1] / "benchmarks" / "few_twins.py")
    few = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(few)
    _, out = analysed
    rows = few.runs_of(out[1][0], (5, 99))
    assert len(rows) == 16
    for r in rows:
        assert r["p_all"] == r["p_stored"], r
        assert r["p99"] == r["p_all"]  # the first 99 of at most 12: all of them


def test_each_groups_twins_draw_noise_of_their_own_that_its_folders_share(analysed):
    # Source: TwinSource.noise_stream: a digest of the group and its forcing set's first run's
    # record. Every twin folder of one group and set (the calibration's, the study's FF twin, the
    # more FB twins) has it, so a seed's FB and FF twins share their noise; no two groups do (with
    # remnant seeds 1, 2, ... alone, every group's and study's twins drew the same noise). The
    # API's run on two workers made the same.
    import yaml

    _, out = analysed
    found = []
    for run, _ in out.values():
        streams: dict[str, set] = {}
        for path in sorted((run / "twins").glob("*/config.yaml")):
            group = path.parent.name.split("-")[0]
            streams.setdefault(group, set()).add(yaml.safe_load(path.read_text())["seeds"]["stream"])
        assert sorted(streams) == ["compensatory", "pursuit"]  # one forcing set each
        assert all(len(s) == 1 and 0 not in s for s in streams.values())
        assert streams["compensatory"] != streams["pursuit"]
        found.append(streams)
    assert found[0] == found[1]


def test_two_forcing_sets_of_a_group_draw_other_noise_and_one_set_the_same():
    # Source: TwinSource.noise_stream digests the group's values and the set's first run's ft, fd
    # and u (nothing else: the config, model and run directory are not read).
    from hcid.pipeline.twins import TwinSource

    rng = np.random.default_rng(0)
    record = {k: rng.standard_normal(100) for k in ("ft", "fd", "u", "e")}
    other = {**record, "fd": -record["fd"]}

    def source(key, rec, number):
        return TwinSource(None, Path("run"), key, rec, {}, (1.0, 8.0, 0.5), 100.0, number)

    one = source(("pursuit",), record, 1).noise_stream
    assert one == source(("pursuit",), dict(record), 2).noise_stream  # the same samples
    assert one != source(("pursuit",), other, 2).noise_stream  # another set of the group
    assert one != source(("compensatory",), record, 1).noise_stream  # another group
    assert one != source(("pursuit",), {**record, "u": record["u"] + 1e-12}, 1).noise_stream


def test_each_groups_count_power_is_that_of_its_runs(analysed):
    # Source: group_verdict's rule, from the tables alone: a group's group_power is count_power of
    # its runs' power (0 for a run without a p) at its alpha, and its verdict UNCERTAIN exactly where
    # no feedforward is shown and that power is below 0.8.
    from hcid.selection.calibration import count_power

    _, out = analysed
    run = out[1][0]
    rows = pq.read_table(run / tables.ANALYSIS.file).to_pylist()
    for g in pq.read_table(run / tables.ANALYSIS_GROUPS.file).to_pylist():
        mine = [r for r in rows if (r["group"], r["method"]) == (g["group"], g["method"])]
        powers = np.array([0.0 if np.isnan(r["p_value"]) else r["power"] for r in mine])
        assert g["group_power"] == count_power(powers, g["alpha"])
        if g["verdict"] != "FEEDFORWARD":
            assert (g["verdict"] == "UNCERTAIN") == (not g["group_power"] >= 0.8)
