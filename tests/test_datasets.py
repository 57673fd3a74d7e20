"""A measured study's data set (issue 27): many files, factors from names and manifests, one
line for every bad set."""

import csv
import shutil
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
import yaml
from typer.testing import CliRunner

from hcid import tables
from hcid.assembly.resolve import parse_config
from hcid.cli import app
from hcid.errors import DataError
from hcid.io import datasets
from hcid.io.measured import samples_needed

from .conftest import CI_CONFIG, load_data
from .test_measured import COLUMNS, EXAMPLE

runner = CliRunner()
# The example file's three trials as a logger writes them: one file per trial, the factors in
# its name, the column names on the last '#' line (no header row).
LAYOUT = {1: ("P01", "easy", "1"), 2: ("P01", "hard", "1"), 3: ("P02", "easy", "2")}
PATTERN = "{subject}_{condition}_trial{trial}.csv"
NAMES = ["time_s", "target", "disturbance", "error", "stick"]


def _trials():
    with open(EXAMPLE, newline="") as f:
        rows = list(csv.reader(f))[1:]
    by_trial = {}
    for row in rows:
        by_trial.setdefault(int(row[0]), []).append(row[1:])
    return by_trial


@pytest.fixture(scope="module")
def trial_folder(tmp_path_factory):
    folder = tmp_path_factory.mktemp("trials")
    for trial, rows in _trials().items():
        subject, condition, number = LAYOUT[trial]
        path = folder / f"{subject}_{condition}_trial{number}.csv"
        with open(path, "w", newline="") as f:
            f.write(f"# logger v3, subject {subject}\n# {','.join(NAMES)}\n")
            csv.writer(f).writerows(rows)
    with open(folder / "manifest.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["file", "subject", "condition", "trial"])
        for trial in sorted(LAYOUT, key=lambda t: f"{LAYOUT[t][0]}_{LAYOUT[t][1]}_trial{LAYOUT[t][2]}.csv"):
            s, c, n = LAYOUT[trial]
            w.writerow([f"{s}_{c}_trial{n}.csv", s, c, n])
    return folder


def _config(tmp_path, pattern=PATTERN, columns=None):
    raw = yaml.safe_load(CI_CONFIG.read_text())
    raw["name"] = "lab"
    raw["seeds"] = [1]
    cols = {k: v for k, v in COLUMNS.items() if k != "run"} if columns is None else columns
    raw["data"] = {"name": "lab", "columns": cols, "w_report": [0.00715]}
    if pattern is not None:
        raw["data"]["pattern"] = pattern
    path = tmp_path / "lab.yaml"
    path.write_text(yaml.safe_dump(raw, sort_keys=False))
    return path


def test_factors_come_from_the_names_and_the_manifest(trial_folder, tmp_path):
    config = parse_config(yaml.safe_load(_config(tmp_path).read_text()), "lab")
    by_glob = datasets.data_files([str(trial_folder / "*_trial*.csv")], config.data.pattern)
    assert [dict(f.factors) for f in by_glob] == [
        {"subject": "P01", "condition": "easy", "trial": "1"},
        {"subject": "P01", "condition": "hard", "trial": "1"},
        {"subject": "P02", "condition": "easy", "trial": "2"},
    ]
    by_manifest = datasets.data_files([trial_folder / "manifest.csv"])
    assert [(f.path.name, f.factors) for f in by_manifest] == [(f.path.name, f.factors) for f in by_glob]
    # A folder: every data file in it but the manifest.
    assert [f.path.name for f in datasets.data_files([trial_folder], PATTERN)] == [
        f.path.name for f in by_glob
    ]


def test_header_on_the_last_comment_line_and_an_extra_column(trial_folder, tmp_path):
    # Source: the example file itself (one run per trial), read through its header row.
    config = parse_config(yaml.safe_load(_config(tmp_path).read_text()), "lab")
    expected = load_data(EXAMPLE, parse_config(
        yaml.safe_load(_config(tmp_path, None, COLUMNS).read_text()), "lab"))  # fmt: skip
    files = datasets.data_files([trial_folder], PATTERN)
    got = datasets.read_set(files, config.data, 25.0)
    assert list(got.records) == [1, 2, 3]
    for run, f in zip(got.records, files, strict=True):
        trial = {v: k for k, v in LAYOUT.items()}[tuple(v for _, v in f.factors)]
        for name in ("ft", "fd", "e", "u"):
            np.testing.assert_array_equal(got.records[run][name], expected[trial][name])
    # One column more in the rows than the '#' header names, read by position.
    extra = tmp_path / "extra"
    extra.mkdir()
    for f in files:
        lines = f.path.read_text().splitlines()
        (extra / f.path.name).write_text("\n".join(lines[:2] + [line + ",7" for line in lines[2:]]) + "\n")
    by_position = {"time": 1, "ft": 2, "fd": 3, "e": 4, "u": 5}
    config = parse_config(yaml.safe_load(_config(tmp_path, PATTERN, by_position).read_text()), "lab")
    again = datasets.read_set(datasets.data_files([extra], PATTERN), config.data, 25.0)
    for run in got.records:
        np.testing.assert_array_equal(again.records[run]["u"], got.records[run]["u"])


def test_glob_folder_manifest_and_pattern_give_identical_tables(trial_folder, tmp_path):
    config = _config(tmp_path)
    (tmp_path / "m").mkdir()
    manifest_config = _config(tmp_path / "m", pattern=None)
    ways = {
        "glob": (config, [str(trial_folder / "*_trial*.csv")]),
        "folder": (config, [str(trial_folder)]),
        "manifest": (manifest_config, [str(trial_folder / "manifest.csv")]),
        "files": (config, [str(p) for p in sorted(trial_folder.glob("*_trial*.csv"))]),
    }
    digests = {}
    for way, (cfg, sources) in ways.items():
        run = tmp_path / f"run_{way}"
        args = ["identify", str(cfg), "--run", str(run), "--method", "direct", "--quiet", "--jobs", "1"]
        for source in sources:
            args += ["--data", source]
        result = runner.invoke(app, args)
        assert result.exit_code == 0, result.output
        digests[way] = {
            name: pq.read_table(run / name)
            for name in ("measured.parquet", "runs.parquet", "frontier.parquet")
        }
    first = digests["glob"]
    for way, found in digests.items():
        for name, table in found.items():
            assert table.equals(first[name]), (way, name)
    runs = first["runs.parquet"].to_pylist()
    assert tables.RUNS.problem(first["runs.parquet"]) is None
    assert [
        (r["seed"], r["file"], r["file_run"], r["subject"], r["condition"], r["trial"]) for r in runs
    ] == [
        (1, "P01_easy_trial1.csv", 1, "P01", "easy", "1"),
        (2, "P01_hard_trial1.csv", 1, "P01", "hard", "1"),
        (3, "P02_easy_trial2.csv", 1, "P02", "easy", "2"),
    ]


def _bad_sets(folder, tmp):
    """(description, sources, pattern, message) of sets a lab might give by mistake."""
    odd = tmp / "odd"
    odd.mkdir()
    for f in sorted(folder.glob("*_trial*.csv")):
        shutil.copy(f, odd / f.name)
    (odd / "P03-easy-trial1.csv").write_text((folder / "P01_easy_trial1.csv").read_text())
    cols = tmp / "cols"
    shutil.copytree(odd, cols)
    (cols / "P03-easy-trial1.csv").unlink()
    text = (folder / "P01_easy_trial1.csv").read_text().replace("stick", "joystick")
    (cols / "P04_easy_trial1.csv").write_text(text)
    rate = tmp / "rate"
    shutil.copytree(folder, rate)
    lines = (folder / "P02_easy_trial2.csv").read_text().splitlines()
    fast = [",".join([str(float(line.split(",")[0]) / 2)] + line.split(",")[1:]) for line in lines[2:]]
    (rate / "P02_easy_trial2.csv").write_text("\n".join(lines[:2] + fast) + "\n")
    manifest = tmp / "manifest.csv"
    manifest.write_text(f"file,subject\n{folder / 'P01_easy_trial1.csv'},\n")
    empty = tmp / "empty"
    empty.mkdir()
    ambiguous = tmp / "P_1_easy_trial1.csv"
    ambiguous.write_text((folder / "P01_easy_trial1.csv").read_text())
    return [
        ("a name the pattern does not match", [odd], PATTERN, "P03-easy-trial1.csv: its name does not match"),
        ("files with other columns", [cols], PATTERN, "differ from"),
        ("files at other rates", [rate], PATTERN, "a set's files share one rate"),
        ("a manifest row without its factor", [manifest], None, "row 2: factor 'subject' is empty"),
        ("an empty folder", [empty], PATTERN, "holds no data file"),
        ("a glob matching nothing", [str(tmp / "*.parquet")], PATTERN, "matches no data file"),
        ("a file named twice", [folder / "P01_easy_trial1.csv"] * 2, PATTERN, "named twice"),
        (
            "a name the pattern reads two ways",
            [ambiguous],
            "{subject}_{condition}_trial{trial}.csv",
            "matches data.pattern .* in more than one way",
        ),
    ]


def test_every_bad_set_is_one_line_and_writes_nothing(trial_folder, tmp_path):
    for described, sources, pattern, message in _bad_sets(trial_folder, tmp_path):
        config = parse_config(yaml.safe_load(_config(tmp_path, pattern).read_text()), "lab")
        with pytest.raises(DataError, match=message):
            files = datasets.data_files(sources, config.data.pattern)
            datasets.read_set(files, config.data, 25.0)
        run = tmp_path / "run"
        args = ["identify", str(_config(tmp_path, pattern)), "--run", str(run), "--quiet"]
        for source in sources:
            args += ["--data", str(source)]
        result = runner.invoke(app, args)
        assert result.exit_code == 2, described
        assert len(result.stderr.strip().splitlines()) == 1, described
        assert not run.exists(), described


def test_other_data_into_a_run_with_results_is_refused(trial_folder, tmp_path):
    # Before: results of one file were silently reused for another file with the same run ids.
    config = _config(tmp_path)
    run = tmp_path / "run"
    base = ["identify", str(config), "--run", str(run), "--method", "direct", "--quiet", "--jobs", "1"]
    assert runner.invoke(app, [*base, "--data", str(trial_folder)]).exit_code == 0
    before = (run / "frontier.parquet").read_bytes()
    other = tmp_path / "other"
    shutil.copytree(trial_folder, other)
    path = other / "P01_easy_trial1.csv"
    lines = path.read_text().splitlines()
    scaled = [",".join(line.split(",")[:4] + [str(2 * float(line.split(",")[4]))]) for line in lines[2:]]
    path.write_text("\n".join(lines[:2] + scaled) + "\n")
    result = runner.invoke(app, [*base, "--data", str(other)])
    assert result.exit_code == 2
    assert "holds identification results of other measured data" in result.stderr
    assert (run / "frontier.parquet").read_bytes() == before
    forced = runner.invoke(app, [*base, "--data", str(other), "--force"])
    assert forced.exit_code == 0 and "identified 3" in forced.output


@pytest.mark.parametrize(
    ("pattern", "message"),
    [
        ("trial.csv", "names no factor"),
        ("{run}_{x}.csv", "factor 'run' must be an identifier other than"),
        ("{a}{b}.csv", "nothing between them"),
        ("{a}_{a}.csv", "appears twice"),
        ("data\\{a}.csv", "separated by '/'"),
    ],
)
def test_a_bad_pattern_names_the_key(tmp_path, pattern, message):
    from hcid.errors import ConfigError

    with pytest.raises(ConfigError, match=f"data.pattern: .*{message}"):
        parse_config(yaml.safe_load(_config(tmp_path, pattern).read_text()), "lab")


def test_a_matlab_struct_of_samples_x_trials_x_subjects(tmp_path):
    # Source: the example file's three trials, laid out as published lab data sets do: one
    # struct per condition file with arrays samples x repeats x participants. Read back, every
    # run's signals equal the trial's, and its factors are its indices (1-based).
    import scipy.io

    config = parse_config(yaml.safe_load(_config(tmp_path, None, COLUMNS).read_text()), "lab")
    trials = load_data(EXAMPLE, config)
    n = 2048
    cube = {k: np.zeros((n, 1, 3)) for k in ("target", "disturbance", "error", "stick")}
    for subject, trial in enumerate(sorted(trials)):
        for k, name in (("target", "ft"), ("disturbance", "fd"), ("error", "e"), ("stick", "u")):
            cube[k][:, 0, subject] = trials[trial][name]
    path = tmp_path / "pursuit.mat"
    scipy.io.savemat(path, {"exp": {**cube, "fs": 25.0}})
    columns = {"ft": "target", "fd": "disturbance", "e": "error", "u": "stick", "rate": "fs"}
    raw = yaml.safe_load(_config(tmp_path, "{condition}.mat", columns).read_text())
    raw["data"]["struct"] = "exp"
    raw["data"]["dimensions"] = ["sample", "trial", "subject"]
    mat_config = parse_config(raw, "lab")
    got = datasets.read_set(datasets.data_files([path], mat_config.data.pattern), mat_config.data, 25.0)
    assert [(r["run"], r["condition"], r["trial"], r["subject"]) for r in got.runs] == [
        (1, "pursuit", "1", "1"), (2, "pursuit", "1", "2"), (3, "pursuit", "1", "3")
    ]  # fmt: skip
    for run, trial in zip(got.records, sorted(trials), strict=True):
        np.testing.assert_array_equal(got.records[run]["u"], trials[trial]["u"])
    # The same as MATLAB v7.3 writes it: HDF5 with a 512-byte user block holding the MAT header,
    # every array column-major (its dimensions reversed in HDF5), the struct a group.
    import h5py

    v73 = tmp_path / "pursuit73" / "pursuit.mat"
    v73.parent.mkdir()
    with h5py.File(v73, "w", userblock_size=512) as f:
        group = f.create_group("exp")
        for k, x in cube.items():
            group.create_dataset(k, data=x.T)
        group.create_dataset("fs", data=np.array([[25.0]]))
    header = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, HDF5 schema 1.00 ."
    with open(v73, "r+b") as f:
        f.write(header.ljust(116) + b"\0" * 8 + b"\x00\x02IM")
    again = datasets.read_set(datasets.data_files([v73], mat_config.data.pattern), mat_config.data, 25.0)
    assert again.runs == got.runs | {} if False else [{**r, "file": "pursuit.mat"} for r in got.runs]
    for run in got.records:
        np.testing.assert_array_equal(again.records[run]["u"], got.records[run]["u"])


def test_the_analysis_rate_and_window_come_from_the_data(trial_folder, tmp_path):
    # Source: the example file's trials: 25 Hz (at most 25 Hz: kept), 2048 samples each, so the
    # window is 81.92 s; recorded in the run's config.yaml, which later commands read back.
    raw = yaml.safe_load(_config(tmp_path).read_text())
    for key in ("models", "loop", "signals", "timing", "seeds", "identify", "selection", "fit_hc"):
        raw.pop(key, None)
    config = tmp_path / "lab_min.yaml"
    config.write_text(yaml.safe_dump(raw))
    run = tmp_path / "run"
    args = ["identify", str(config), "--run", str(run), "--data", str(trial_folder), "--method", "direct",
            "--quiet", "--jobs", "1"]  # fmt: skip
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    recorded = yaml.safe_load((run / "config.yaml").read_text())["data"]
    assert recorded["analysis_rate"] == 25.0 and recorded["window"] == pytest.approx(81.92)
    assert runner.invoke(app, ["sweep-w", str(config), "--run", str(run)]).exit_code == 0
    result = runner.invoke(app, ["sweep-w", str(config), "--run", str(tmp_path / "elsewhere")])
    assert result.exit_code == 2 and "data.analysis_rate, data.window: missing" in result.stderr


def test_a_corrupt_parquet_file_is_one_line(tmp_path):
    # The battery found it: the set's column check read the schema outside the reader's guard.
    bad = tmp_path / "data.parquet"
    bad.write_bytes(b"not parquet at all")
    with pytest.raises(DataError, match="data.parquet: cannot read"):
        datasets.read_set(
            datasets.data_files([bad]),
            parse_config(yaml.safe_load(_config(tmp_path).read_text()), "lab").data,
        )


def test_a_pipe_or_a_csv_without_rows_is_one_line_and_nothing_is_written(tmp_path):
    # Found by the hostile battery (issue 35): a named pipe given to --data blocked hcid after it
    # had marked the run directory; a CSV with its header and a run column but no data rows ended
    # in a traceback (run_blocks' zip).
    import os

    import hcid

    pipe = tmp_path / "S1_pursuit_trial1.csv"
    os.mkfifo(pipe)
    with pytest.raises(DataError, match="not a regular file"):
        datasets.data_files([pipe])
    with pytest.raises(DataError, match="not a regular file"):
        hcid.read_records(pipe)
    empty = tmp_path / "S1_pursuit_trial2.csv"
    empty.write_text("run,time,target,disturbance,error,stick\n")
    runner = CliRunner()
    for source in (pipe, empty):
        run = tmp_path / f"run_{source.stem}"
        config = str(Path(__file__).resolve().parents[1] / "configs" / "lab_example.yaml")
        result = runner.invoke(app, ["analyse", config, "--data", str(source), "--run", str(run), "--quiet"])
        assert result.exit_code == 2, result.output
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and str(source) in lines[0], lines
        assert not run.exists()


def test_a_first_file_set_aside_is_not_the_sets_reference(trial_folder, tmp_path):
    # Source: the rule "each file against the set's first kept file": a first file too short for
    # the windows is set aside, and the next, with a column more, is then the reference and kept.
    folder = tmp_path / "set"
    folder.mkdir()
    lines = (trial_folder / "P01_easy_trial1.csv").read_text().splitlines()
    (folder / "P00_easy_trial0.csv").write_text("\n".join(lines[:102]) + "\n")  # 100 samples
    extra = [lines[0], f"{lines[1]},extra"] + [f"{row},0" for row in lines[2:]]
    (folder / "P01_easy_trial1.csv").write_text("\n".join(extra) + "\n")
    config = parse_config(yaml.safe_load(_config(tmp_path).read_text()), "lab")
    files = datasets.data_files([folder], config.data.pattern)
    got = datasets.read_set(files, config.data, 25.0, need=samples_needed(config), skip=True)
    assert [Path(p).name for p, _ in got.set_aside] == ["P00_easy_trial0.csv"]
    assert [r["file"] for r in got.runs] == ["P01_easy_trial1.csv"]


def test_one_readable_file_beside_unreadable_ones_keeps_its_own_run_ids(tmp_path):
    # Source: SPEC's run ids are the file's own for one file; a set aside file does not make the
    # survivor a set of several (the run ids 13, 11, 12 stay, as with that file alone).
    text = EXAMPLE.read_text().splitlines()
    renumber = {"1": "13", "2": "11", "3": "12"}
    rows = [text[0]] + [renumber[r.split(",", 1)[0]] + "," + r.split(",", 1)[1] for r in text[1:]]
    (tmp_path / "a_runs.csv").write_text("\n".join(rows) + "\n")
    (tmp_path / "b_junk.csv").write_text("not,a\ndata,file\n")
    config = parse_config(yaml.safe_load(_config(tmp_path, None, COLUMNS).read_text()), "lab")
    files = datasets.data_files([str(tmp_path / "*.csv")], config.data.pattern)
    got = datasets.read_set(files, config.data, 25.0, need=samples_needed(config), skip=True)
    assert sorted(got.records) == [11, 12, 13]
    assert [Path(p).name for p, _ in got.set_aside] == ["b_junk.csv"]


def test_a_data_set_read_for_another_rate_or_too_short_is_refused(trial_folder, tmp_path):
    # Source: identify_study's own check (a library caller may build a DataSet otherwise than
    # read_study does): the config's analysis rate, and the samples its windows need.
    import dataclasses

    from hcid.pipeline import identify_study

    config = parse_config(yaml.safe_load(_config(tmp_path).read_text()), "lab")
    files = datasets.data_files([trial_folder], config.data.pattern)
    good = datasets.read_set(files, config.data, 25.0, need=samples_needed(config))
    with pytest.raises(DataError, match="the data set is at 50 Hz, the config analyses at 25 Hz"):
        identify_study(config, tmp_path / "a", data=dataclasses.replace(good, rate=50.0))
    short = {run: {k: v[:100] for k, v in rec.items()} for run, rec in good.records.items()}
    with pytest.raises(DataError, match="run 1 holds 100 samples"):
        identify_study(config, tmp_path / "b", data=dataclasses.replace(good, records=short))
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()


def test_a_config_given_as_a_mapping_reads_as_its_yaml_file(monkeypatch):
    # hcid.analyse(config=dict): the mapping a YAML file holds gives that file's study (the same
    # resolved config and records; relative paths from the working folder), and a value no YAML
    # file could hold is refused naming its key.
    from hcid.assembly.resolve import read_study
    from hcid.errors import ConfigError

    root = Path(__file__).resolve().parents[1]
    monkeypatch.chdir(root)
    path = root / "configs" / "lab_example.yaml"
    files = sorted(str(p) for p in (root / "configs" / "lab_example").glob("S1_*_trial1.csv"))
    raw = yaml.safe_load(path.read_text())
    from_file, file_data = read_study(path, files)
    from_dict, dict_data = read_study(raw, files)
    assert from_dict.identify == from_file.identify and from_dict.loop == from_file.loop
    assert from_dict.data == from_file.data and from_dict.name == from_file.name
    assert list(dict_data.records) == list(file_data.records)
    for run, record in file_data.records.items():
        assert all(np.array_equal(record[k], dict_data.records[run][k]) for k in ("ft", "fd", "e", "u"))
    raw["data"]["window"] = np.float64(40.0)
    with pytest.raises(ConfigError, match=r"^data.window: must be a number, .* got a float64"):
        read_study(raw, files)


# --------------------------------------------------------------------------- a lab's session folders


@pytest.fixture()
def session_folders(trial_folder, tmp_path):
    """The example's trials as a logger leaves a session: one folder per subject, a reset segment
    beside each trial, a stray desktop.ini, and one trial again as Parquet beside its CSV."""
    root = tmp_path / "sessions"
    for subject, condition, number in LAYOUT.values():
        folder = root / subject
        folder.mkdir(parents=True, exist_ok=True)
        source = trial_folder / f"{subject}_{condition}_trial{number}.csv"
        shutil.copy(source, folder / f"{condition}_trial{number}.csv")
        shutil.copy(source, folder / f"{condition}_trial{number}_rst1.csv")
        (folder / "desktop.ini").write_text("[.ShellClassInfo]\n")
    return root


def test_a_pattern_with_a_folder_gives_the_subject_from_the_folder(session_folders):
    found = datasets.find_files(
        [str(session_folders / "*" / "*.csv")], "{subject}/{condition}_trial{trial}.csv", ["*_rst?.csv"]
    )
    assert [dict(f.factors) for f in found.files] == [
        {"subject": "P01", "condition": "easy", "trial": "1"},
        {"subject": "P01", "condition": "hard", "trial": "1"},
        {"subject": "P02", "condition": "easy", "trial": "2"},
    ]
    assert sorted(Path(p).name for p, _ in found.skipped) == [
        "easy_trial1_rst1.csv",
        "easy_trial2_rst1.csv",
        "hard_trial1_rst1.csv",
    ]
    assert {why for _, why in found.skipped} == {"left out by data.exclude '*_rst?.csv'"}


def test_a_folder_lists_what_it_skips_and_why(session_folders):
    folder = session_folders / "P01"
    pq.write_table(_as_parquet(folder / "easy_trial1.csv"), folder / "easy_trial1.parquet")
    found = datasets.find_files([folder], "{condition}_trial{trial}.csv", ["*_rst?.csv"])
    assert [f.path.name for f in found.files] == ["easy_trial1.csv", "hard_trial1.csv"]
    why = {Path(p).name: reason for p, reason in found.skipped}
    assert why["desktop.ini"].startswith("not a data file (.ini")
    assert why["easy_trial1.parquet"] == "a copy in another format of easy_trial1.csv"
    assert why["easy_trial1_rst1.csv"] == "left out by data.exclude '*_rst?.csv'"
    # Without the exclude list, a reset segment is read as a run of its own (trial '1_rst1'):
    # what data.exclude is for.
    found = datasets.find_files([folder], "{condition}_trial{trial}.csv")
    assert ("trial", "1_rst1") in found.files[1].factors


def _as_parquet(csv_path: Path):
    import pyarrow as pa

    with open(csv_path, newline="") as f:
        rows = [r for r in csv.reader(f) if r and not r[0].startswith("#")]
    return pa.table({name: pa.array([float(r[i]) for r in rows]) for i, name in enumerate(NAMES)})


def test_a_set_whose_every_file_is_left_out_is_refused_in_one_line(session_folders):
    with pytest.raises(DataError, match=r"every file it names is left out \(3: .*data.exclude"):
        datasets.find_files([str(session_folders / "*" / "*_rst1.csv")], None, ["*_rst?.csv"])


@pytest.mark.parametrize(
    ("key", "value", "message"),
    [
        ("pattern", "../{subject}/{trial}.csv", r"data.pattern: .*no empty, '.' or '..' part"),
        ("pattern", "{subject}//{trial}.csv", r"data.pattern: .*no empty"),
        ("exclude", [3], r"data.exclude: must be a list of file-name globs"),
        ("exclude", [""], r"data.exclude: must be a list of file-name globs"),
    ],
)
def test_bad_folder_patterns_and_exclude_lists_name_the_key(tmp_path, key, value, message):
    from hcid.errors import ConfigError

    raw = yaml.safe_load(_config(tmp_path).read_text())
    raw["data"][key] = value
    with pytest.raises(ConfigError, match=message):
        parse_config(raw, "lab")


def test_identify_lists_the_files_it_skips(session_folders, tmp_path):
    raw = yaml.safe_load(_config(tmp_path, "{subject}/{condition}_trial{trial}.csv").read_text())
    raw["data"]["exclude"] = ["*_rst?.csv"]
    config = tmp_path / "lab.yaml"
    config.write_text(yaml.safe_dump(raw, sort_keys=False))
    run = tmp_path / "run"
    args = ["identify", str(config), "--data", str(session_folders / "P01"), "--run", str(run), "--quiet"]
    result = runner.invoke(app, [*args, "--method", "direct"])
    assert result.exit_code == 0, result.output
    assert "read 2 measured run(s)" in result.output
    assert (
        f"SKIPPED: 3 file(s) found are not runs ({run}/skipped.parquet): 1 not a data file "
        "(e.g. desktop.ini); 2 left out by data.exclude '*_rst?.csv' (e.g. easy_trial1_rst1.csv)"
    ) in result.output
    factors = pq.read_table(run / "runs.parquet").column("subject").to_pylist()
    assert factors == ["P01", "P01"]
    assert pq.read_table(run / "skipped.parquet").num_rows == 3
