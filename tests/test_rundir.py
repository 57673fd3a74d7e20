"""Run directories (issue 10): the lock, the manifest-guarded delete, unsafe paths, tampered tables."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time

import pyarrow as pa
import pyarrow.parquet as pq
import pytest
import yaml
from typer.testing import CliRunner

from hcid.cli import app
from hcid.errors import DataError
from hcid.io import folders, results
from hcid.pipeline import rundir

from .conftest import ROOT, report_without_figures

runner = CliRunner()


@pytest.fixture(scope="module")
def small_run(tmp_path_factory):
    """configs/ci.yaml with seed 1, run end to end once (copied by the tests that change it)."""
    from .conftest import CI_CONFIG

    base = tmp_path_factory.mktemp("rundir")
    raw = yaml.safe_load(CI_CONFIG.read_text())
    raw["seeds"] = [1]
    config = base / "small.yaml"
    config.write_text(yaml.safe_dump(raw))
    run = base / "run"
    result = runner.invoke(app, ["run", str(config), "--run", str(run), "--jobs", "1", "--quiet"])
    assert result.exit_code == 0, result.output
    return config, run


def _copy(small_run, tmp_path):
    config, run = small_run
    shutil.copytree(run, tmp_path / "run")
    return config, tmp_path / "run"


def test_manifest_lists_what_hcid_wrote(small_run):
    _, run = small_run
    owned = set(folders.owned_files(run))
    assert {"config.yaml", "simulations.parquet", "frontier.parquet", "thresholds.parquet"} <= owned
    assert ".hcid.lock" not in owned and folders.MANIFEST not in owned


def test_second_command_on_a_held_directory_is_refused(small_run, tmp_path):
    # A process holding the lock (released by the OS when it ends, even by kill -9): the
    # command is refused in one line naming it, and the tables are unchanged.
    config, run = _copy(small_run, tmp_path)
    script = (
        "import sys, time\nfrom pathlib import Path\nfrom hcid.pipeline.rundir import using\n"
        "with using(Path(sys.argv[1])):\n    print('held', flush=True)\n    time.sleep(60)\n"
    )
    holder = subprocess.Popen([sys.executable, "-c", script, str(run)], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        before = (run / "frontier.parquet").read_bytes()
        result = runner.invoke(app, ["identify", str(config), "--run", str(run), "--force", "--quiet"])
        assert result.exit_code == 2
        assert f"in use by hcid pid {holder.pid}" in result.stderr
        assert len(result.stderr.strip().splitlines()) == 1
        assert (run / "frontier.parquet").read_bytes() == before
    finally:
        holder.kill()  # kill -9 semantics: the OS drops the lock
        holder.wait()
    result = runner.invoke(app, ["sweep-w", str(config), "--run", str(run)])
    assert result.exit_code == 0, result.output


def test_lock_is_reentrant_in_one_process(tmp_path):
    with rundir.using(tmp_path / "r"), rundir.using(tmp_path / "r"):
        assert (tmp_path / "r" / folders.MANIFEST).is_file()


def test_force_deletes_only_files_hcid_wrote(small_run, tmp_path):
    config, run = _copy(small_run, tmp_path)
    (run / "my_notes.parquet").write_bytes(b"mine")
    other = yaml.safe_load(config.read_text())
    other["seeds"] = [2]
    config2 = tmp_path / "other.yaml"
    config2.write_text(yaml.safe_dump(other))
    result = runner.invoke(
        app, ["simulate", str(config2), "--run", str(run), "--force", "--quiet", "--jobs", "1"]
    )
    assert result.exit_code == 0, result.output
    assert (run / "my_notes.parquet").read_bytes() == b"mine"
    assert not (run / "frontier.parquet").exists()  # hcid's, made from the old simulation


@pytest.mark.parametrize("where", ["/", ".", ".."])
def test_unsafe_run_paths_are_refused(small_run, where):
    config, _ = small_run
    result = runner.invoke(app, ["simulate", str(config), "--run", where, "--quiet"])
    assert result.exit_code == 2
    assert "refusing to use it as a run directory" in result.stderr


def test_foreign_directory_is_refused_and_untouched(small_run, tmp_path):
    config, _ = small_run
    (tmp_path / "data").mkdir()
    (tmp_path / "data" / "thesis.parquet").write_bytes(b"x")
    result = runner.invoke(
        app, ["simulate", str(config), "--run", str(tmp_path / "data"), "--force", "--quiet"]
    )
    assert result.exit_code == 2
    assert "not an hcid run directory" in result.stderr
    assert sorted(p.name for p in (tmp_path / "data").iterdir()) == ["thesis.parquet"]


@pytest.mark.parametrize(
    ("column", "values", "message"),
    [
        ("v", lambda n: [float("nan")] * n, "column 'v' holds nan"),
        ("v", lambda n: ["1"] * n, "column 'v' is string, expected double"),
        ("model", lambda n: ["ZZ"] * n, "holds model 'ZZ', which the run's config.yaml does not name"),
        ("seed", lambda n: [99] * n, "seed 99, not among the run's seeds"),
    ],
)
def test_tampered_frontier_is_refused(small_run, tmp_path, column, values, message):
    config, run = _copy(small_run, tmp_path)
    table = pq.read_table(run / "frontier.parquet")
    i = table.column_names.index(column)
    pq.write_table(table.set_column(i, column, pa.array(values(table.num_rows))), run / "frontier.parquet")
    before = (run / "frontier.parquet").read_bytes()
    commands = [["sweep-w", str(config), "--run", str(run)], ["report", str(run)]]
    if column == "v":  # `hcid run` keeps a realization's frontier rows: checked as a table read is
        commands.append(["run", str(config), "--run", str(run), "--quiet"])
    for args in commands:
        result = runner.invoke(app, args)
        assert result.exit_code == 2, args
        assert message in result.stderr, (args, result.stderr)
    assert (run / "frontier.parquet").read_bytes() == before


def test_report_md_escapes_user_strings(small_run, tmp_path):
    _, run = small_run
    target = tmp_path / "<b>run</b>"
    shutil.copytree(run, target)
    text, _ = report_without_figures(target)  # report.md as `hcid report` writes it
    assert "&lt;b&gt;run&lt;/b&gt;" in text and "<b>run</b>" not in text


def test_dollar_in_a_name_is_refused_and_titles_are_not_mathtext(small_run, tmp_path):
    # A name is one plain path component (no '$'); figure titles never parse mathtext anyway.
    import numpy as np

    from hcid.report import figures

    config, _ = small_run
    raw = yaml.safe_load(config.read_text())
    raw["name"] = "a$b$c"
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump(raw))
    result = runner.invoke(app, ["simulate", str(bad), "--run", str(tmp_path / "r"), "--quiet"])
    assert result.exit_code == 2 and "name: must be 1 to 100 letters" in result.stderr
    t = np.arange(10.0)
    fig = figures.plot_signals(t, {"ft": t, "u": t}, "a$b$c ^_{x}")
    figures.save(fig, tmp_path / "f.png")  # mathtext would fail on the unbalanced '$'
    assert (tmp_path / "f.png").stat().st_size > 0


def test_symlinked_parts_are_never_written_through(small_run, tmp_path):
    config, run = _copy(small_run, tmp_path)
    outside = tmp_path / "outside"
    outside.mkdir()
    (run / ".parts").symlink_to(outside)
    result = runner.invoke(
        app, ["identify", str(config), "--run", str(run), "--force", "--quiet", "--jobs", "1"]
    )
    assert result.exit_code == 0, result.output
    assert list(outside.iterdir()) == []
    assert not (run / ".parts").exists()


def test_full_disk_is_one_line_and_keeps_the_table(tmp_path, monkeypatch):
    import errno

    table = pa.table({"x": [1]})
    results.write_table(table, tmp_path / "t.parquet")

    def enospc(table, where, **options):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(pq, "write_table", enospc)
    with pytest.raises(
        DataError, match="cannot write \\(No space left on device\\); the previous file is intact"
    ):
        results.write_table(pa.table({"x": [2]}), tmp_path / "t.parquet")
    monkeypatch.undo()
    assert pq.read_table(tmp_path / "t.parquet").equals(table)


def test_complete_run_writes_nothing(small_run, tmp_path):
    config, run = _copy(small_run, tmp_path)
    stamps = {p.name: p.stat().st_mtime_ns for p in run.iterdir() if p.suffix in (".parquet", ".yaml")}
    time.sleep(0.01)
    result = runner.invoke(app, ["run", str(config), "--run", str(run), "--quiet", "--jobs", "1"])
    assert result.exit_code == 0, result.output
    assert {p: (run / p).stat().st_mtime_ns for p in stamps} == stamps


def test_lock_file_holds_the_pid(tmp_path):
    with rundir.using(tmp_path / "r"):
        assert f"pid {os.getpid()}" in (tmp_path / "r" / rundir.LOCK).read_text()


def test_a_refused_command_leaves_the_lock_file_as_it_was(small_run, tmp_path):
    # Before: a command refused after taking the lock (here: a config whose seeds differ)
    # left its own pid in .hcid.lock. Content and modification time are now restored.
    config, run = _copy(small_run, tmp_path)
    lock = run / rundir.LOCK
    lock.write_text("hcid pid 1 (earlier)")
    os.utime(lock, ns=(10**18, 10**18))
    other = tmp_path / "other.yaml"
    raw = yaml.safe_load(config.read_text())
    raw["seeds"] = [2]
    other.write_text(yaml.safe_dump(raw))
    result = runner.invoke(app, ["identify", str(other), "--run", str(run), "--quiet"])
    assert result.exit_code == 2 and "seeds differs" in result.stderr
    assert lock.read_text() == "hcid pid 1 (earlier)" and lock.stat().st_mtime_ns == 10**18
    lock.unlink()
    result = runner.invoke(app, ["identify", str(other), "--run", str(run), "--quiet"])
    assert result.exit_code == 2 and not lock.exists()  # a lock file the refusal created is removed


def test_hcid_never_replaces_a_file_it_did_not_write(tmp_path):
    # In an hcid folder a file of hcid's name that its manifest does not list is the user's.
    from hcid.io.folders import claim

    folder = tmp_path / "out"
    claim(folder, ["t.parquet"])
    (folder / "t.parquet").write_bytes(b"mine")
    with pytest.raises(DataError, match="t.parquet: not written by hcid; refusing to replace it"):
        results.write_table(pa.table({"x": [1]}), folder / "t.parquet")
    assert (folder / "t.parquet").read_bytes() == b"mine"


def test_a_folder_with_only_a_users_config_is_not_adopted(tmp_path):
    # Review of issue 24: a folder holding only config.yaml is the user's (their config beside
    # it), not an old hcid run directory: using it as --run is refused and the file kept.
    folder = tmp_path / "study"
    folder.mkdir()
    (folder / "config.yaml").write_text("# my own notes\nname: mine\n")
    with pytest.raises(DataError, match="not an hcid run directory"), rundir.using(folder):
        pass
    assert (folder / "config.yaml").read_text() == "# my own notes\nname: mine\n"


def test_a_foreign_mark_is_not_hcids(tmp_path):
    from hcid.io.folders import claim

    folder = tmp_path / "other"
    folder.mkdir()
    (folder / "hcid-run.json").write_text('{"name": "my other tool"}')
    with pytest.raises(DataError, match="its hcid-run.json is not hcid's"):
        claim(folder, [])
    assert (folder / "hcid-run.json").read_text() == '{"name": "my other tool"}'


def test_a_file_is_listed_before_it_appears(tmp_path, monkeypatch):
    # A kill between the rename and the listing would leave a file hcid then refuses to
    # replace; it is listed first, so an interrupted write leaves at most a listed absent file.
    from hcid.io import folders

    folder = tmp_path / "out"
    folders.claim(folder, [])

    real = folders.os.replace

    def killed(src, dst):
        if str(dst).endswith("t.parquet"):  # the kill comes as the table is renamed into place
            raise KeyboardInterrupt
        real(src, dst)

    monkeypatch.setattr(folders.os, "replace", killed)
    with pytest.raises(KeyboardInterrupt):
        results.write_table(pa.table({"x": [1]}), folder / "t.parquet")
    monkeypatch.undo()
    assert "t.parquet" in folders.owned_files(folder) and not (folder / "t.parquet").exists()
    results.write_table(pa.table({"x": [2]}), folder / "t.parquet")
    assert pq.read_table(folder / "t.parquet").column("x").to_pylist() == [2]


def test_the_record_keeps_earlier_stages_only_beside_their_results(small_run, tmp_path):
    # config.yaml holds the stages of the methods whose results the directory holds: after a
    # --force removed the tables, a command resolved for one method records that method only.
    from hcid.assembly.resolve import load_config

    config, run = _copy(small_run, tmp_path)
    direct_only = load_config(config, ("direct",))
    rundir.record_config(direct_only, run)  # frontier.parquet there: the indirect stages stay
    recorded = yaml.safe_load((run / "config.yaml").read_text())["identify"]
    assert {"direct", "stage1", "stage2"} <= set(recorded)
    (run / "frontier.parquet").unlink()
    rundir.record_config(direct_only, run)
    recorded = yaml.safe_load((run / "config.yaml").read_text())["identify"]
    assert set(recorded) == {"target_shift", "direct"}


# ------------------------------------------------------------- a newcomer's walkthrough (2026-11-27)


@pytest.mark.parametrize(
    "command", [["report"], ["sweep-w", str(ROOT / "configs" / "example_data.yaml"), "--run"]]
)
def test_a_refused_command_leaves_an_empty_folder_empty(tmp_path, command):
    folder = tmp_path / "empty"
    folder.mkdir()
    result = runner.invoke(app, [*command, str(folder)])
    assert result.exit_code == 2, result.output
    assert list(folder.iterdir()) == []


def test_a_folder_holding_only_a_lock_file_is_empty(tmp_path):
    folder = tmp_path / "left"
    folder.mkdir()
    (folder / rundir.LOCK).write_text("")
    with rundir.using(folder):
        assert (folder / folders.MANIFEST).is_file()


def test_a_folder_not_hcids_given_as_a_run_directory_is_named_as_such(tmp_path):
    folder = tmp_path / "mine"
    folder.mkdir()
    (folder / "notes.txt").write_text("mine\n")
    result = runner.invoke(app, ["report", str(folder)])
    assert result.exit_code == 2
    assert "give a run directory `hcid run` or `hcid analyse` made" in result.stderr
    assert "choose a new or empty folder" not in result.stderr
    assert [p.name for p in folder.iterdir()] == ["notes.txt"]


def test_a_changed_analysis_rate_is_named_not_the_grid_it_moved(tmp_path):
    """The identify grids follow from data.analysis_rate: the refusal names what the user changed."""
    from hcid.assembly.resolve import read_study

    lab, data = ROOT / "configs" / "lab_example.yaml", [str(ROOT / "configs" / "lab_example")]
    other = tmp_path / "lab.yaml"
    other.write_text(lab.read_text().replace("analysis_rate: 20.0", "analysis_rate: 25.0"))
    before, after = read_study(lab, data, None)[0], read_study(other, data, None)[0]
    run = tmp_path / "run"
    run.mkdir()
    (run / "config.yaml").write_text(before.to_yaml())
    with pytest.raises(
        DataError, match=r"\(data\.analysis_rate differs\); redo it with `hcid identify --force`"
    ):
        rundir.check_run_dir(after, run, "identify")
