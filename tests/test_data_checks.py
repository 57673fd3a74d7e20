"""What a newcomer's walkthrough found (2026-11-27): data of another plant analysed silently, a
refused command writing into an empty folder, refusals naming a derived key or the wrong command,
and report text that did not render. Each test fails on the code before the fix."""

from __future__ import annotations

import glob
import math
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from hcid.analysis.fourier import plant_mismatch
from hcid.cli import app
from hcid.errors import DataError
from hcid.io.resolve import read_study
from hcid.pipeline import rundir
from hcid.pipeline.studies import PLANT_MISMATCH_LIMIT, _check_plant
from hcid.report.document import _inline_md
from hcid.report.sections.study import _with_se

ROOT = Path(__file__).resolve().parents[1]
LAB = ROOT / "configs" / "lab_example.yaml"
LAB_DATA = ROOT / "configs" / "lab_example"
CPHS = ROOT.parent / "shared" / "data" / "cphs2017"
runner = CliRunner()


@pytest.fixture(scope="module")
def lab():
    return read_study(LAB, [str(LAB_DATA)], None)


def _lab_with(tmp_path: Path, old: str, new: str) -> Path:
    text = LAB.read_text()
    assert old in text
    path = tmp_path / "lab.yaml"
    path.write_text(text.replace(old, new))
    return path


def test_the_lab_examples_are_their_plant(lab):
    """Measured on the shipped example (hcid's simulator at 60 Hz, resampled to 20 Hz): 0.4% to
    6.1% of theta at the lines is resampling error; the limit is 30%."""
    config, data = lab
    p = config.loop.plant
    found = [plant_mismatch(r, data.rate, p.num, p.den, "input") for r in data.records.values()]
    assert max(found) < 0.07 < PLANT_MISMATCH_LIMIT
    _check_plant(config, data)  # accepted
    # Twice the gain leaves theta - 2 theta = -theta: exactly 100% (the formula).
    doubled = [plant_mismatch(r, data.rate, [2 * p.num[0]], p.den, "input") for r in data.records.values()]
    assert np.allclose(doubled, 1.0, atol=0.07)


@pytest.mark.parametrize(
    ("old", "new"),
    [("disturbance_at: input", "disturbance_at: output"), ("K: 1.5}", "K: 3.0}")],
    ids=["disturbance at the output", "twice the gain"],
)
def test_data_of_another_loop_is_refused_in_one_line(tmp_path, old, new):
    config = _lab_with(tmp_path, old, new)
    run = tmp_path / "run"
    result = runner.invoke(
        app, ["identify", str(config), "--data", str(LAB_DATA), "--run", str(run), "--quiet"]
    )
    assert result.exit_code == 2, result.output
    assert "is not the configured plant" in result.stderr and "24 of 24 runs over 30%" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    assert not run.exists()


@pytest.mark.skipif(not CPHS.is_dir(), reason=f"no recordings at {CPHS}")
def test_recordings_of_both_plants_under_one_plant_are_refused(tmp_path):
    """The walkthrough's case: every file of the recordings with the integrator's config analysed
    the second-order plant's six runs as the integrator and reversed their verdicts."""
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
        config, data = read_study(
            ROOT / "configs" / f"cphs2017_{plant}.yaml", glob.glob(str(CPHS / f"*_{plant}_*.csv")), None
        )
        _check_plant(config, data)


@pytest.mark.parametrize(
    "command", [["report"], ["sweep-w", str(ROOT / "configs" / "example_data.yaml"), "--run"]]
)
def test_a_refused_command_leaves_an_empty_folder_empty(tmp_path, command):
    folder = tmp_path / "empty"
    folder.mkdir()
    result = runner.invoke(app, [*command, str(folder)])
    assert result.exit_code == 2, result.output
    assert list(folder.iterdir()) == []


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
    """The identify grids follow from data.analysis_rate: the refusal names what the user changed,
    and the --force of whichever command runs, not `hcid identify --force`."""
    before, _ = read_study(LAB, [str(LAB_DATA)], None)
    after, _ = read_study(
        _lab_with(tmp_path, "analysis_rate: 20.0", "analysis_rate: 25.0"), [str(LAB_DATA)], None
    )
    run = tmp_path / "run"
    run.mkdir()
    (run / "config.yaml").write_text(before.to_yaml())
    with pytest.raises(
        DataError, match=r"\(data\.analysis_rate differs\); redo it with --force \(hcid identify"
    ):
        rundir.check_run_dir(after, run, "identify")


def test_report_text_renders_emphasis_and_literal_asterisks():
    html = _inline_md("*Words used here.* A run's **W\\*** is ... reach its W\\*; x * y * z")
    assert html.startswith("<i>Words used here.</i> A run's <b>W*</b>")
    assert "\\" not in html and "reach its W*;" in html and "x * y * z" in html


def test_an_undetermined_value_at_zero_reads_as_zero():
    row = {"TL": 1.69e-08, "TL_status": "at a search bound (0)", "TL_se": math.nan}
    assert _with_se(row, "TL") == "0†"
    row = {"TL": 0.25, "TL_status": "at a search bound (0.25)", "TL_se": math.nan}
    assert _with_se(row, "TL") == "0.25†"
