"""Measured data: import checks, file formats, mapped names, and W calibration."""

import copy
import dataclasses
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute  # noqa: F401  (pa.compute)
import pyarrow.csv as pacsv
import pyarrow.parquet as pq
import pytest
import scipy.io
import yaml
from typer.testing import CliRunner

from hcid.assembly.resolve import parse_config
from hcid.cli import app
from hcid.errors import ConfigError, DataError

from .conftest import CI_CONFIG, ROOT, load_data, report_without_figures

runner = CliRunner()
EXAMPLE = ROOT / "configs" / "example_data" / "subject_synthetic.csv"
COLUMNS = {"time": "time_s", "ft": "target", "fd": "disturbance", "e": "error", "u": "stick", "run": "trial"}


@pytest.fixture(scope="module")
def data_config_path(tmp_path_factory):
    """configs/ci.yaml plus a data section mapping the example file's column names."""
    raw = yaml.safe_load(CI_CONFIG.read_text())
    raw["name"] = "ci_data"
    raw["data"] = {"name": "subject01", "columns": COLUMNS, "w_report": [0.00715]}
    path = tmp_path_factory.mktemp("cfg") / "ci_data.yaml"
    path.write_text(yaml.safe_dump(raw, sort_keys=False))
    return path


@pytest.fixture(scope="module")
def data_config(data_config_path):
    return parse_config(yaml.safe_load(data_config_path.read_text()), "ci_data")


@pytest.fixture(scope="module")
def example_table():
    return pacsv.read_csv(EXAMPLE)


def test_example_file_reads_as_three_runs(data_config):
    records = load_data(EXAMPLE, data_config)
    assert sorted(records) == [1, 2, 3]
    assert all(r["u"].size == 2048 for r in records.values())


def _write(table: pa.Table, path):
    if path.suffix == ".csv":
        pacsv.write_csv(table, path)
    else:
        pq.write_table(table, path)


def _one_run(table):
    return table.filter(pa.compute.equal(table.column("trial"), 1))


@pytest.mark.parametrize(
    "damage, message",
    [
        (lambda t: t.drop_columns(["stick"]), "missing columns ['stick']"),
        (
            lambda t: t.set_column(
                4, "error", [np.where(np.arange(t.num_rows) == 9, np.inf, t.column("error").to_numpy())]
            ),
            "run 1: error holds inf at sample 9",
        ),
        (
            lambda t: t.set_column(
                1,
                "time_s",
                [t.column("time_s").to_numpy() + np.where(np.arange(t.num_rows) >= 100, 0.01, 0.0)],
            ),
            "time is not uniformly sampled",
        ),
        (
            lambda t: t.set_column(1, "time_s", [t.column("time_s").to_numpy() * 2]),
            "sample rate 12.5 Hz, below the config's analysis rate (timing.output_rate) 25 Hz",
        ),
        (
            lambda t: t.slice(0, 1500),
            "1500 samples at 25 Hz, the identification windows (data.window, or identify's "
            "estimation and validation rows) need 2048",
        ),
    ],
)
@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_bad_data_exit_2_nothing_written(tmp_path, data_config_path, example_table, damage, message, suffix):
    bad = tmp_path / f"bad{suffix}"
    _write(damage(_one_run(example_table)), bad)
    run = tmp_path / "run"
    result = runner.invoke(
        app, ["identify", str(data_config_path), "--data", str(bad), "--run", str(run), "--quiet"]
    )
    assert result.exit_code == 2, result.output
    assert message in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    assert not run.exists()


def test_unequal_lengths_in_mat(tmp_path, data_config):
    path = tmp_path / "bad.mat"
    scipy.io.savemat(
        path,
        {
            "target": np.zeros(2048),
            "disturbance": np.zeros(2048),
            "error": np.zeros(2048),
            "stick": np.zeros(2000),
            "rate": 25.0,
        },
    )
    with pytest.raises(DataError, match="signals of unequal length"):
        load_data(path, data_config)


def test_missing_and_corrupt_files(tmp_path, data_config):
    with pytest.raises(DataError, match="missing"):
        load_data(tmp_path / "none.csv", data_config)
    junk = tmp_path / "junk.parquet"
    junk.write_bytes(b"PAR1 not really")
    with pytest.raises(DataError, match="cannot read"):
        load_data(junk, data_config)
    with pytest.raises(DataError, match="unknown data format '.txt'"):
        (tmp_path / "x.txt").write_text("1")
        load_data(tmp_path / "x.txt", data_config)


@pytest.fixture(scope="module")
def three_formats(tmp_path_factory, data_config_path, example_table):
    """The same two runs as CSV, Parquet and .mat (samples x runs matrices and a rate)."""
    base = tmp_path_factory.mktemp("formats")
    two = example_table.filter(pa.compute.less_equal(example_table.column("trial"), 2))
    _write(two, base / "d.csv")
    _write(two, base / "d.parquet")
    cols = {c: two.column(c).to_numpy().reshape(2, -1).T for c in ("target", "disturbance", "error", "stick")}
    scipy.io.savemat(base / "d.mat", {**cols, "rate": 25.0})
    frontiers = {}
    for name in ("d.csv", "d.parquet", "d.mat"):
        run = base / f"run_{name}"
        result = runner.invoke(
            app,
            [
                "identify",
                str(data_config_path),
                "--data",
                str(base / name),
                "--run",
                str(run),
                "--jobs",
                "1",
                "--quiet",
            ],
        )
        assert result.exit_code == 0, result.output
        frontiers[name] = run
    return frontiers


def test_three_formats_give_identical_frontiers(three_formats):
    # CSV round-trips float64 exactly (shortest representation), so all three are the same data.
    ref = (three_formats["d.parquet"] / "frontier.parquet").read_bytes()
    assert (three_formats["d.csv"] / "frontier.parquet").read_bytes() == ref
    assert (three_formats["d.mat"] / "frontier.parquet").read_bytes() == ref


def test_mapped_names_identify_the_runs(three_formats):
    t = pq.read_table(three_formats["d.csv"] / "frontier.parquet")
    assert set(t.column("model").to_pylist()) == {"subject01"}
    assert set(t.column("seed").to_pylist()) == {1, 2}


def test_sweep_and_report_on_data_run(three_formats, data_config_path):
    run = three_formats["d.csv"]
    assert runner.invoke(app, ["sweep-w", str(data_config_path), "--run", str(run)]).exit_code == 0
    sel = pq.read_table(run / "selection.parquet")
    assert set(sel.column("model").to_pylist()) == {"subject01"}
    assert pq.read_table(run / "thresholds.parquet").num_rows == 0  # no truth, no thresholds
    # report.md as `hcid report` writes it, and the data section's own figure drawn
    md, figures = report_without_figures(run, draw=["data_structure.png"], out=run)
    assert "## 9. Measured data: subject01" in md
    assert {"data_structure.png", "bode_data_w0.00715.png"} <= figures
    assert (run / "data_structure.png").stat().st_size > 0
    assert "true" not in md.split("## 9.")[1].lower().replace("no true dynamics", "")


def test_calibrate_w_interval_from_thresholds(tmp_path, data_config_path):
    run = tmp_path / "cal"
    result = runner.invoke(app, ["calibrate-w", str(data_config_path), "--run", str(run), "--quiet"])
    assert result.exit_code == 0, result.output
    cal = pq.read_table(run / "calibration.parquet").to_pylist()
    th = {(r["method"], r["model"]): r for r in pq.read_table(run / "thresholds.parquet").to_pylist()}
    for method in ("direct", "indirect"):
        row = next(r for r in cal if r["method"] == method)
        # Target rate 0: the lower end is W_FP exactly (the same breakpoint); the upper end
        # is where the first FF realization drops below nb_ft = 2, never after the mean does.
        assert row["safe_low"] == th[(method, "FB")]["w_fp"]
        assert row["safe_high"] <= th[(method, "FF")]["w_fn"]
        if row["safe_low"] < row["safe_high"]:
            assert row["recommended"] == pytest.approx(np.sqrt(row["safe_low"] * row["safe_high"]))
    # 95% Clopper-Pearson band holds the rate
    assert all(r["fp_low"] <= r["fp_rate"] <= r["fp_high"] for r in cal)


def test_data_section_errors(data_config_path):
    raw = yaml.safe_load(data_config_path.read_text())
    bad = copy.deepcopy(raw)
    bad["data"]["columns"]["speed"] = "x"
    from hcid.errors import ConfigError

    with pytest.raises(ConfigError, match="data.columns.speed: unknown key"):
        parse_config(bad, "x")
    bad = copy.deepcopy(raw)
    bad["data"]["name"] = "FB"
    with pytest.raises(ConfigError, match="data.name: must be an identifier other than the model names"):
        parse_config(bad, "x")


def test_mat_with_shared_time_vector(tmp_path, data_config, example_table):
    # samples x runs matrices and one time vector for all runs (the documented .mat layout)
    two = example_table.filter(pa.compute.less_equal(example_table.column("trial"), 2))
    cols = {c: two.column(c).to_numpy().reshape(2, -1).T for c in ("target", "disturbance", "error", "stick")}
    path = tmp_path / "shared_time.mat"
    scipy.io.savemat(path, {**cols, "time_s": np.arange(2048) / 25.0})
    records = load_data(path, data_config)
    assert sorted(records) == [1, 2]
    np.testing.assert_array_equal(records[2]["u"], cols["stick"][:, 1])


def test_data_at_another_rate_with_matching_config(tmp_path, data_config_path, example_table):
    # A 50 Hz file is accepted as is when timing.output_rate and the windows (in samples)
    # match it: the config's record is then 81.92 s * 50 Hz = 4096 samples. With the
    # 25 Hz config it is resampled to 25 Hz on import (2048 samples).
    one = _one_run(example_table)
    cols = {c: np.repeat(one.column(c).to_numpy(), 2) for c in ("target", "disturbance", "error", "stick")}
    path = tmp_path / "fifty.csv"
    _write(pa.table({"time_s": np.arange(4096) / 50.0, **cols}), path)
    raw = yaml.safe_load(data_config_path.read_text())
    raw["timing"]["output_rate"] = 50.0
    for stage in ("direct", "stage2"):
        raw["identify"][stage].update(estimation=[257, 2176], validation=[2177, 4096])
    config = parse_config(raw, "fifty")
    records = load_data(path, config)
    assert records[1]["u"].size == 4096
    resampled = load_data(path, parse_config(yaml.safe_load(data_config_path.read_text()), "x"))
    assert resampled[1]["u"].size == 2048


# --------------------------------------------------------------------------- hostile files (issue 10)


def _mat_signals(example_table, shape_runs):
    """The example's first 2048 samples of each signal as a samples x runs (x 1) array."""
    out = {}
    for key in ("ft", "fd", "e", "u"):
        x = example_table.column(COLUMNS[key]).to_numpy()[:2048]
        out[COLUMNS[key]] = shape_runs(x)
    return out


def test_mat_samples_x_runs_x_1_is_split_into_runs(tmp_path, data_config, example_table):
    # A 3-D variable of shape (2048, 2, 1) holds two runs, never interleaved sample by sample.
    path = tmp_path / "d.mat"
    scipy.io.savemat(
        path, {**_mat_signals(example_table, lambda x: np.stack([x, 2 * x], 1)[:, :, None]), "rate": 25.0}
    )
    records = load_data(path, data_config)
    assert sorted(records) == [1, 2]
    np.testing.assert_array_equal(records[2]["u"], 2 * records[1]["u"])


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda x: np.stack([x, x], 1)[:, :, None].repeat(2, 2), "more than two non-singleton dimensions"),
        (lambda x: x * (1 + 1j), "holds complex values"),
    ],
)
def test_mat_shapes_and_types_refused(tmp_path, data_config, example_table, make, message):
    path = tmp_path / "d.mat"
    scipy.io.savemat(path, {**_mat_signals(example_table, make), "rate": 25.0})
    with pytest.raises(DataError, match=message):
        load_data(path, data_config)


def test_mat_empty_rate_refused(tmp_path, data_config, example_table):
    path = tmp_path / "d.mat"
    scipy.io.savemat(path, {**_mat_signals(example_table, lambda x: x), "rate": np.array([])})
    with pytest.raises(DataError, match="run 1: the rate 'rate' is empty or not a positive number"):
        load_data(path, data_config)


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda c: c.__setitem__("stick", np.where(np.arange(c["stick"].size) == 7, 1e308, c["stick"])),
         "run 1: stick holds 1e\\+308 at sample 7 \\(values must be finite and at most 1e\\+100"),
        (lambda c: c.__setitem__("stick", np.zeros(c["stick"].size)), "stick is constant \\(0\\) over"),
    ],
)  # fmt: skip
def test_values_that_cannot_be_identified_are_refused(tmp_path, data_config, example_table, edit, message):
    cols = {c: example_table.column(c).to_numpy() for c in example_table.column_names}
    edit(cols)
    path = tmp_path / "d.csv"
    pacsv.write_csv(pa.table(cols), path)
    with pytest.raises(DataError, match=message):
        load_data(path, data_config)


def test_only_the_windows_samples_are_identified(data_config, example_table):
    # Appending 10,000 samples after the windows changes nothing: identification uses the
    # rows up to the last window sample plus the target shift (SPEC 3: ft_s(k) = ft(k + 25)).
    from hcid.methods import identify

    # 2048 + 25 samples: the windows' rows and the shift's look-ahead.
    cols = {
        k: np.append(example_table.column(COLUMNS[k]).to_numpy()[:2048], [0.1] * 25)
        for k in COLUMNS
        if k in ["ft", "fd", "e", "u"]
    }
    longer = {k: np.concatenate([v, np.full(10_000, 0.3)]) for k, v in cols.items()}
    a = identify(cols, data_config.identify, "direct", rate=25.0)
    b = identify(longer, data_config.identify, "direct", rate=25.0)
    assert a.fit.to_arrow().equals(b.fit.to_arrow())


# --------------------------------------------------------------------------- any experiment's data (issue 11)

DEFAULT_NAMES = {
    "trial": "run",
    "time_s": "t",
    "target": "ft",
    "disturbance": "fd",
    "error": "e",
    "stick": "u",
}


def _data_only_config(tmp_path, last=2048, **data):
    """The ci identification and selection sections and a data section: no simulation sections.

    ``last`` is the last sample of the direct and stage-2 validation windows."""
    raw = yaml.safe_load(CI_CONFIG.read_text())
    for stage in ("direct", "stage2"):
        raw["identify"][stage]["validation"] = [1089, last]
    doc = {"name": "lab", "identify": raw["identify"], "selection": raw["selection"]}
    doc["data"] = {"analysis_rate": 25.0, "window": 81.92, **data}
    path = tmp_path / "lab.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def test_data_only_config_with_default_names(tmp_path, example_table, data_config):
    # A file whose columns are t, ft, fd, e, u, run needs no mapping, and a config with only
    # the data, identify and selection sections identifies it; the records are the mapped
    # example's, sample for sample. Commands that simulate refuse it in one line.
    renamed = example_table.rename_columns([DEFAULT_NAMES[c] for c in example_table.column_names])
    path = tmp_path / "plain.csv"
    pacsv.write_csv(renamed, path)
    config_path = _data_only_config(tmp_path)
    config = parse_config(yaml.safe_load(config_path.read_text()), "lab")
    assert not config.simulates and config.models == ()
    got, expected = load_data(path, config), load_data(EXAMPLE, data_config)
    for run in (1, 2, 3):
        for name in ("ft", "fd", "e", "u", "t"):
            np.testing.assert_array_equal(got[run][name], expected[run][name])
    run_dir = tmp_path / "run"
    result = runner.invoke(
        app, ["identify", str(config_path), "--data", str(path), "--run", str(run_dir), "--quiet"]
    )
    assert result.exit_code == 0, result.output
    assert set(pq.read_table(run_dir / "frontier.parquet").column("model").to_pylist()) == {"data"}
    for command in ("simulate", "calibrate-w", "run"):
        other = tmp_path / f"run_{command}"
        result = runner.invoke(app, [command, str(config_path), "--run", str(other), "--quiet"])
        assert result.exit_code == 2
        assert f"`hcid {command}` simulates and needs them" in result.stderr
        assert len(result.stderr.strip().splitlines()) == 1 and not other.exists()


def test_default_grids_refuse_an_analysis_rate_above_60_hz():
    # Source: stage 1's default nb1 is 1 s of lags (hcid.config.parse.data_identify_defaults) and a
    # grid holds at most MOST_LAGS = 60 (hcid.config.stages): 60 Hz is accepted, 61 Hz refused in
    # one line naming data.analysis_rate (before, it named identify.stage1.nb1, which no one wrote).
    from hcid.config.stages import MOST_LAGS

    raw = {"name": "lab", "data": {"analysis_rate": 60.0, "window": 40.0}}
    assert parse_config(raw, "lab").identify.stage("stage1").grid.nb1 == (0, MOST_LAGS)
    raw["data"]["analysis_rate"] = 61.0
    with pytest.raises(
        ConfigError, match=r"^data.analysis_rate: the default identification grids .* reach 60 Hz"
    ):
        parse_config(raw, "lab")
    # A timing section's rate is named as such.
    timed = {"name": "lab", "data": {}, "timing": {"sim_rate": 100.0, "output_rate": 100.0, "run_in": 0.0,
                                                   "window": 40.0, "periods": 1}}  # fmt: skip
    with pytest.raises(ConfigError, match=r"^timing.output_rate: the default identification grids"):
        parse_config(timed, "lab")


def test_an_analysis_rate_whose_probe_window_is_no_whole_samples_reads():
    # The data section is described at a placeholder timing to read the files: at 12.5 Hz its 1 s
    # was no whole number of samples, and a valid config was refused naming data.window.
    from hcid.assembly.resolve import read_study

    root = Path(__file__).resolve().parents[1]
    raw = yaml.safe_load((root / "configs" / "lab_example.yaml").read_text())
    raw["data"].update(analysis_rate=12.5, window=40.0, lead_in=4.0)
    files = sorted(str(p) for p in (root / "configs" / "lab_example").glob("S1_*_trial1.csv"))
    config, data = read_study(raw, files)
    assert config.timing.output_rate == 12.5 and all(r["u"].size >= 500 for r in data.records.values())


def test_paper_config_reads_a_file_with_default_names(tmp_path, example_table, ci_config):
    # configs/ci.yaml has no data section: a file with the default names (time as 'time',
    # the other spelling) is read with them, under the data name 'data'.
    names = {**DEFAULT_NAMES, "time_s": "time"}
    path = tmp_path / "plain.csv"
    pacsv.write_csv(example_table.rename_columns([names[c] for c in example_table.column_names]), path)
    records = load_data(path, ci_config)
    assert sorted(records) == [1, 2, 3] and records[1]["u"].size == 2048
    assert ci_config.data.name == "data"


def test_e_derived_from_theta_and_comment_lines(tmp_path, example_table, data_config):
    # e = ft - theta when the file has the system output instead of e (SPEC 1: e = ft - theta);
    # a logger's '#' header lines are skipped.
    one = _one_run(example_table)
    theta = one.column("target").to_numpy() - one.column("error").to_numpy()
    table = pa.table(
        {
            "t": one.column("time_s"),
            "ft": one.column("target"),
            "fd": one.column("disturbance"),
            "theta": theta,
            "u": one.column("stick"),
        }
    )
    path = tmp_path / "theta.csv"
    pacsv.write_csv(table, path)
    path.write_text("# logger v2\n# subject 7, condition A\n" + path.read_text())
    config = parse_config(yaml.safe_load(_data_only_config(tmp_path).read_text()), "lab")
    record = load_data(path, config)[1]
    np.testing.assert_allclose(record["e"], one.column("error").to_numpy(), rtol=0, atol=1e-15)


def test_resampling_keeps_a_slow_sine_and_removes_a_fast_one():
    # resample_poly (Kaiser beta 5) 60 Hz -> 20 Hz: a 2 Hz sine (a fifth of the new Nyquist
    # frequency 10 Hz) keeps its amplitude to 0.1% and its phase to 0.1 deg away from the
    # record's ends (the filter spans 10 max(up, down) = 30 input samples, 0.5 s); one at 15 Hz,
    # above the new Nyquist frequency, is removed (left below 0.1% of its amplitude).
    from hcid.io.measured import resample, resampling_factors

    up, down = resampling_factors(60.0, 20.0)
    t = np.arange(0, 45.0, 1 / 60)
    t_out = np.arange(0, 45.0, 1 / 20)
    inner = (t_out > 1.0) & (t_out < 44.0)
    slow = resample(np.sin(2 * np.pi * 2.0 * t + 0.3), up, down)
    basis = np.c_[np.sin(2 * np.pi * 2.0 * t_out), np.cos(2 * np.pi * 2.0 * t_out)][inner]
    a, b = np.linalg.lstsq(basis, slow[inner], rcond=None)[0]  # a sin + b cos = r sin(. + phi)
    assert np.hypot(a, b) == pytest.approx(1.0, rel=1e-3)
    assert np.degrees(np.arctan2(b, a)) == pytest.approx(np.degrees(0.3), abs=0.1)
    fast = resample(np.sin(2 * np.pi * 15.0 * t), up, down)
    assert np.max(np.abs(fast[inner])) < 1e-3
    assert slow.size == t_out.size


@pytest.mark.parametrize(
    ("rates", "ok"),
    [((60.0, 20.0), (1, 3)), ((60.0, 25.0), (5, 12)), ((59.94, 20.0), None), ((1000.0, 3.0), None)],
)
def test_resampling_ratios(rates, ok):
    from hcid.io.measured import resampling_factors

    if ok is not None:
        assert resampling_factors(*rates) == ok
    else:
        with pytest.raises(DataError, match="exactly"):
            resampling_factors(*rates)


def test_lead_in_is_skipped_after_resampling(tmp_path, example_table):
    # A 75 Hz file (the 25 Hz example repeated x3 in time, so 3 x 25 Hz) with a 2 s lead-in:
    # resampled to 25 Hz, then the first 50 samples are dropped.
    one = _one_run(example_table)
    cols = {
        n: np.repeat(one.column(c).to_numpy(), 3) for c, n in DEFAULT_NAMES.items() if n not in ("run", "t")
    }
    path = tmp_path / "fast.csv"
    pacsv.write_csv(pa.table({"t": np.arange(3 * 2048) / 75.0, **cols}), path)
    config = parse_config(
        yaml.safe_load(_data_only_config(tmp_path, 1998, lead_in=2.0, window=79.92).read_text()), "lab"
    )
    full = parse_config(yaml.safe_load(_data_only_config(tmp_path, 1998, window=79.92).read_text()), "lab")
    cut, whole = load_data(path, config)[1], load_data(path, full)[1]
    assert whole["u"].size == 2048 and cut["u"].size == 2048 - 50
    np.testing.assert_array_equal(cut["u"], whole["u"][50:])
    with pytest.raises(
        ConfigError, match=r"data.lead_in: must be whole samples at the analysis rate \(25 Hz\), got 0.01 s"
    ):
        parse_config(yaml.safe_load(_data_only_config(tmp_path, lead_in=0.01).read_text()), "lab")


# ---------------------------------------------------------------------- no silent wrong answers (issue 24)


def _trials_csv(tmp_path, example_table, ids, *, rate: bool):
    """The example's three trials (repeated as needed) under the run ids ``ids``, one block each."""
    trials = np.asarray(example_table.column("trial").to_numpy())
    parts = []
    for i, run_id in enumerate(ids):
        block = example_table.filter(pa.array(trials == (i % 3) + 1))
        block = block.set_column(0, "trial", pa.array(np.full(block.num_rows, run_id)))
        if rate:
            block = block.drop_columns(["time_s"]).append_column(
                "rate", pa.array(np.full(block.num_rows, 25.0))
            )
        parts.append(block)
    path = tmp_path / "trials.csv"
    pacsv.write_csv(pa.concat_tables(parts), path)
    return path


def _rate_config(data_config):
    columns = {k: v for k, v in COLUMNS.items() if k != "time"} | {"rate": "rate"}
    return dataclasses.replace(data_config, data=dataclasses.replace(data_config.data, columns={
        **data_config.data.columns, **columns}, time_default=False))  # fmt: skip


@pytest.mark.parametrize("rate", [True, False], ids=["rate column", "time column"])
def test_a_run_id_in_two_blocks_is_refused_not_merged(tmp_path, data_config, example_table, rate):
    # Four trials, the third labelled 1 again: before, with a rate column, trial 3's rows were
    # appended to trial 1 (one record of 4096 samples). A trial's rows are one block.
    path = _trials_csv(tmp_path, example_table, [1, 2, 1, 4], rate=rate)
    config = _rate_config(data_config) if rate else data_config
    with pytest.raises(
        DataError, match=r"run 1 appears in two separate blocks of rows \(0-2047 and 4096-6143"
    ):
        load_data(path, config)


def test_the_files_run_ids_are_kept(tmp_path, data_config, example_table):
    # A lab's trial numbers are data: runs 11..13 stay 11..13 (before: renumbered 1..3).
    path = _trials_csv(tmp_path, example_table, [13, 11, 12], rate=True)
    records = load_data(path, _rate_config(data_config))
    assert list(records) == [11, 12, 13]
    expected = load_data(EXAMPLE, data_config)
    np.testing.assert_array_equal(records[13]["u"], expected[1]["u"])  # file order: 13 holds trial 1
    from hcid.io.measured import records_table

    assert sorted(set(records_table("s", records).column("seed").to_pylist())) == [11, 12, 13]


def test_run_ids_must_be_integers(tmp_path, data_config, example_table):
    table = example_table.set_column(0, "trial", pa.array(example_table.column("trial").to_numpy() + 0.5))
    path = tmp_path / "d.csv"
    pacsv.write_csv(table, path)
    with pytest.raises(DataError, match="'trial' holds 1.5 at row 0; run ids must be integers"):
        load_data(path, data_config)


def test_byte_order_mark_before_comment_lines(tmp_path, data_config):
    # A UTF-8 BOM then '#' lines: before, the first comment line was read as the header
    # ("Expected 2 columns, got 6"); the records equal the plain file's.
    path = tmp_path / "bom.csv"
    path.write_bytes(b"\xef\xbb\xbf# logger v2, 25 Hz\n# subject 01\n" + EXAMPLE.read_bytes())
    got, expected = load_data(path, data_config), load_data(EXAMPLE, data_config)
    assert list(got) == [1, 2, 3]
    for run in got:
        np.testing.assert_array_equal(got[run]["e"], expected[run]["e"])


def test_comment_lines_across_read_blocks(tmp_path, monkeypatch, data_config):
    # The comment filter reads block by block: lines cut by a block edge and comment lines
    # in the middle of the data give the same records as the plain file.
    from hcid.io import formats

    monkeypatch.setattr(formats, "_BLOCK", 97)
    lines = EXAMPLE.read_bytes().splitlines(keepends=True)
    path = tmp_path / "mid.csv"
    path.write_bytes(b"# head\n" + b"".join(lines[:500]) + b"  # a note mid-file\n" + b"".join(lines[500:]))
    got, expected = load_data(path, data_config), load_data(EXAMPLE, data_config)
    for run in got:
        np.testing.assert_array_equal(got[run]["u"], expected[run]["u"])


def test_a_file_above_the_size_limit_is_refused_before_reading(tmp_path, monkeypatch, data_config):
    # The limit is checked with stat(): a sparse file of 2 GiB is refused without reading a byte
    # (before: read whole, 17-22 s and 4.5 GB). MAX_FILE_BYTES is lowered here to test the edge.
    from hcid.io import formats

    path = tmp_path / "big.csv"
    with open(path, "wb") as f:
        f.truncate(2 << 30)
    with pytest.raises(DataError, match="2,147,483,648 bytes, above the 1,073,741,824-byte limit"):
        load_data(path, data_config)
    monkeypatch.setattr(formats, "MAX_FILE_BYTES", EXAMPLE.stat().st_size - 1)
    with pytest.raises(DataError, match="-byte limit on a data file"):
        load_data(EXAMPLE, data_config)
    monkeypatch.setattr(formats, "MAX_FILE_BYTES", EXAMPLE.stat().st_size)
    assert list(load_data(EXAMPLE, data_config)) == [1, 2, 3]


def test_only_the_named_columns_are_read(tmp_path, monkeypatch, data_config, example_table):
    # The CSV parser is asked for the mapped columns only (a logger's extra columns are skipped).
    import pyarrow.csv as pacsv_module

    asked = []
    real = pacsv_module.read_csv

    def spy(source, *args, convert_options=None, **kwargs):
        asked.append(None if convert_options is None else list(convert_options.include_columns))
        return real(source, *args, convert_options=convert_options, **kwargs)

    monkeypatch.setattr(pacsv_module, "read_csv", spy)
    table = example_table.append_column(
        "notes", pa.array(["free text, with a comma"] * example_table.num_rows)
    )
    path = tmp_path / "notes.csv"
    real_write = pacsv.write_csv
    real_write(table, path)
    assert list(load_data(path, data_config)) == [1, 2, 3]
    # The reader names the file's columns by position (_c1, _c2, ...): the mapped ones only.
    names = table.column_names
    assert asked == [sorted(f"_c{names.index(c) + 1}" for c in COLUMNS.values())]


def test_lead_in_longer_than_the_record(tmp_path, data_config):
    # Before: "-1100 samples after the 200 s lead-in"; now the record's length and none left.
    config = dataclasses.replace(data_config, data=dataclasses.replace(data_config.data, lead_in=200.0))
    with pytest.raises(DataError, match="run 1: 2048 samples at 25 Hz, none after the 200 s lead-in, the"):
        load_data(EXAMPLE, config)


def test_read_signal_needs_the_run_column_for_a_run(tmp_path):
    # Before: run 2 of a file without a run column silently gave the whole column (run 1's signal).
    from hcid.io.measured import read_signal

    path = tmp_path / "f.csv"
    pacsv.write_csv(pa.table({"fd": np.sin(np.arange(100.0))}), path)
    assert read_signal(path, "fd").size == 100
    for run in (1, 2):
        with pytest.raises(DataError, match=f"run {run} asked for, but the file has no run column 'run'"):
            read_signal(path, "fd", run)
    pacsv.write_csv(pa.table({"fd": np.arange(6.0), "run": [1, 1, 2, 2, 1, 1]}), path)
    with pytest.raises(DataError, match="run 1 appears in two separate blocks"):
        read_signal(path, "fd", 2)
    pacsv.write_csv(pa.table({"fd": np.arange(6.0), "run": [1, 1, 2, 2, 3, 3]}), path)
    np.testing.assert_array_equal(read_signal(path, "fd", 2), [2.0, 3.0])


def test_every_signal_from_a_file_passes_the_same_check(tmp_path):
    # One bound for data columns and forcing functions (measured.LARGEST).
    from hcid.io.measured import LARGEST, check_signal, read_signal

    path = tmp_path / "f.csv"
    pacsv.write_csv(pa.table({"fd": [0.0, 2 * LARGEST, 1.0]}), path)
    with pytest.raises(DataError, match=r"column 'fd' holds 2e\+100 at sample 1"):
        read_signal(path, "fd")
    np.testing.assert_array_equal(check_signal(np.array([LARGEST, -LARGEST]), "x"), [LARGEST, -LARGEST])
    with pytest.raises(DataError, match="x holds nan at sample 0"):
        check_signal(np.array([np.nan]), "x")


@pytest.mark.parametrize("layout", ["cr line endings", "blank line after the comments"])
def test_csv_line_layouts(tmp_path, data_config, layout):
    # Review: a CSV with CR-only line endings was a csv.Error traceback; a blank line between
    # the comments and the header made the header look empty ("missing columns").
    text = EXAMPLE.read_text()
    path = tmp_path / "f.csv"
    path.write_text(text.replace("\n", "\r") if layout == "cr line endings" else "# logger\n\n" + text)
    got, expected = load_data(path, data_config), load_data(EXAMPLE, data_config)
    for run in expected:
        np.testing.assert_array_equal(got[run]["u"], expected[run]["u"])


def test_a_forcing_file_of_several_runs_needs_its_run(tmp_path):
    # Review: without run:, a file of several trials was read as one signal, the trials end to end.
    from hcid.io.measured import read_signal

    path = tmp_path / "f.csv"
    pacsv.write_csv(pa.table({"fd": np.arange(6.0), "run": [1, 1, 2, 2, 3, 3]}), path)
    with pytest.raises(DataError, match="'fd' holds 3 runs .*name the one to use with run"):
        read_signal(path, "fd")
    mat = tmp_path / "f.mat"
    scipy.io.savemat(mat, {"fd": np.ones((10, 2)) * [[1.0, 2.0]]})
    with pytest.raises(DataError, match="'fd' holds 2 runs"):
        read_signal(mat, "fd")
    pacsv.write_csv(pa.table({"fd": np.arange(6.0), "run": [4] * 6}), path)
    np.testing.assert_array_equal(read_signal(path, "fd"), np.arange(6.0))  # one run: the file's


def test_identify_data_force_redoes_a_changed_identify(tmp_path, data_config_path):
    # Review: --force was not passed to the data import's run-directory check.
    raw = yaml.safe_load(data_config_path.read_text())
    run = tmp_path / "run"
    argv = ["identify", None, "--data", str(EXAMPLE), "--run", str(run), "--method", "direct", "--quiet"]
    first = tmp_path / "a.yaml"
    first.write_text(yaml.safe_dump(raw))
    assert runner.invoke(app, [argv[0], str(first), *argv[2:]]).exit_code == 0
    raw["identify"]["direct"]["nk1"] = [21, 30]
    second = tmp_path / "b.yaml"
    second.write_text(yaml.safe_dump(raw))
    refused = runner.invoke(app, [argv[0], str(second), *argv[2:]])
    assert refused.exit_code == 2 and "identify.direct.nk1 differs" in refused.stderr
    assert runner.invoke(app, [argv[0], str(second), *argv[2:], "--force"]).exit_code == 0


def test_a_missing_error_column_names_its_way_out_and_the_files_width(tmp_path, data_config):
    # Two mapping mistakes at once keep the e = ft - theta hint (it was dropped when e was not the
    # last missing column), and a position past the file's last column says how many it has.
    import dataclasses

    from hcid.errors import DataError
    from hcid.io.measured import read_runs

    path = tmp_path / "one.csv"
    _write(_one_run(pacsv.read_csv(EXAMPLE)).drop_columns(["error"]), path)  # 5 columns
    columns = {**data_config.data.columns, "u": "joystick", "theta": 9}  # e stays 'error': absent
    data = dataclasses.replace(data_config.data, columns=columns)
    with pytest.raises(DataError) as err:
        read_runs(path, data, 25.0, 2048)
    assert "missing columns" in str(err.value) and "joystick" in str(err.value)
    assert "(or a system output 'column 9' for e = ft - theta); the file has 5 columns" in str(err.value)


# --------------------------------------------------------------------------- recordings of another loop

LAB = ROOT / "configs" / "lab_example.yaml"
LAB_DATA = ROOT / "configs" / "lab_example"
CPHS = ROOT.parent / "shared" / "data" / "cphs2017"


def _lab_with(tmp_path, old: str, new: str):
    text = LAB.read_text()
    assert old in text
    path = tmp_path / "lab.yaml"
    path.write_text(text.replace(old, new))
    return path


@pytest.mark.parametrize(
    ("old", "new"),
    [("disturbance_at: input", "disturbance_at: output"), ("K: 1.5}", "K: 3.0}")],
    ids=["disturbance at the output", "twice the gain"],
)
def test_data_of_another_loop_is_refused_in_one_line(tmp_path, old, new):
    # Source: tests/test_fourier.py's plant_mismatch of these runs, 0.77 and more, 0.93 and more.
    run = tmp_path / "run"
    config = _lab_with(tmp_path, old, new)
    result = runner.invoke(
        app, ["identify", str(config), "--data", str(LAB_DATA), "--run", str(run), "--quiet"]
    )
    assert result.exit_code == 2, result.output
    assert "is not the configured plant" in result.stderr and "24 of 24 runs over 30%" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    assert not run.exists()


def test_a_run_longer_than_the_window_is_checked_over_the_window(tmp_path):
    """The multisines have whole periods over the window only: a run that goes on after it (10 s
    more here) is checked over the window, not skipped for having no lines (a review's find)."""
    from hcid.assembly.resolve import read_study
    from hcid.pipeline.measured_data import check_plant

    longer = tmp_path / "longer"
    longer.mkdir()
    for path in sorted(LAB_DATA.glob("S1_*.csv")):
        lines = path.read_text().splitlines(keepends=True)
        body = [x for x in lines if x.strip() and not x.startswith("#")]
        (longer / path.name).write_text("".join(lines) + "".join(_shifted(body, 45.0)))
    for config, refused in ((LAB, False), (_lab_with(tmp_path, "K: 1.5}", "K: 3.0}"), True)):
        cfg, data = read_study(config, [str(longer)], None)
        assert all(
            r["u"].size > round(cfg.timing.window * cfg.timing.output_rate) for r in data.records.values()
        )
        if refused:
            with pytest.raises(DataError, match="is not the configured plant"):
                check_plant(cfg, data)
        else:
            check_plant(cfg, data)


def _shifted(rows: list[str], dt: float) -> list[str]:
    """The first 10 s of a lab file's rows again, their times ``dt`` later (the file goes on)."""
    out = []
    for row in rows:
        t, *rest = row.split(",")
        if float(t) < 10.0:
            out.append(",".join([f"{float(t) + dt:.6f}", *rest]))
    return out


def test_a_refused_analyse_force_keeps_the_earlier_twins(tmp_path):
    from hcid.io import folders
    from hcid.pipeline import rundir

    run = tmp_path / "run"
    twin = run / "twins" / "g1"
    with rundir.using(run), rundir.using(twin):
        folders.atomic_write(twin / "frontier.parquet", lambda p: Path(p).write_text("x"))
    config = _lab_with(tmp_path, "K: 1.5}", "K: 3.0}")
    result = runner.invoke(
        app, ["analyse", str(config), "--data", str(LAB_DATA), "--run", str(run), "--force", "--quiet"]
    )
    assert result.exit_code == 2 and "is not the configured plant" in result.stderr
    assert (twin / "frontier.parquet").read_text() == "x"


@pytest.mark.skipif(not CPHS.is_dir(), reason=f"no recordings at {CPHS}")
def test_recordings_of_both_plants_under_one_plant_are_refused(tmp_path):
    """The walkthrough's case: every file of the recordings with the integrator's config analysed
    the second-order plant's six runs as the integrator and reversed their verdicts."""
    import glob

    from hcid.assembly.resolve import read_study
    from hcid.pipeline.measured_data import check_plant

    run = tmp_path / "mixed"
    result = runner.invoke(
        app,
        ["analyse", str(ROOT / "configs" / "cphs2017_fo.yaml"), "--data", str(CPHS / "*.csv"),
         "--by", "plant", "--run", str(run), "--quiet"],
    )  # fmt: skip
    assert result.exit_code == 2, result.output
    assert "_so_" in result.stderr and "6 of 12 runs over 30%" in result.stderr
    assert not run.exists()
    for plant in ("fo", "so"):  # each plant's own config accepts its files
        files = glob.glob(str(CPHS / f"*_{plant}_*.csv"))
        check_plant(*read_study(ROOT / "configs" / f"cphs2017_{plant}.yaml", files, None))


def test_plant_check_false_lets_recordings_the_plant_leaves_a_delay_out_through(tmp_path):
    config = tmp_path / "lab.yaml"
    text = (
        LAB.read_text()
        .replace("K: 1.5}", "K: 3.0}")
        .replace("  lead_in: 5.0", "  lead_in: 5.0\n  plant_check: false")
    )
    config.write_text(text)
    data, run = LAB_DATA / "S1_pursuit_trial1.csv", tmp_path / "run"
    result = runner.invoke(app, ["identify", str(config), "--data", str(data), "--run", str(run), "--quiet"])
    assert result.exit_code == 0, result.output
    config.write_text(text.replace("plant_check: false", "plant_check: maybe"))
    result = runner.invoke(
        app, ["identify", str(config), "--data", str(data), "--run", str(tmp_path / "r2"), "--quiet"]
    )
    assert result.exit_code == 2 and "data.plant_check: must be true or false, got 'maybe'" in result.stderr
