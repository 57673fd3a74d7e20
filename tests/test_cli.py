"""The command line: simulate, determinism across --jobs, bad input."""

import re

import pyarrow.parquet as pq
import pytest
from typer.testing import CliRunner

from hcid.cli import app

from .conftest import CI_CONFIG

runner = CliRunner()

#: The plant lines of configs/ci.yaml, replaced by a loop.plant in the bad-input cases.
_PAPER_PLANT = "  Kc: 2.75                    # plant Yc = Kc*wb / (s (s + wb))\n  wb: 2.0"


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    base = tmp_path_factory.mktemp("sim")
    out = {}
    for jobs in (1, 2):
        run = base / f"jobs{jobs}"
        result = runner.invoke(
            app, ["simulate", str(CI_CONFIG), "--run", str(run), "--jobs", str(jobs), "--quiet"]
        )
        assert result.exit_code == 0, result.output
        out[jobs] = (run, result.output)
    return out


def test_simulate_writes_tables(simulated):
    run, output = simulated[1]
    table = pq.read_table(run / "simulations.parquet")
    assert table.column_names == ["model", "seed", "k", "t", "ft", "fd", "e", "u", "theta", "n"]
    assert table.num_rows == 2 * 3 * 2048  # ci.yaml: 2 models x 3 seeds x 2048 samples
    summary = pq.read_table(run / "simulation_summary.parquet")
    assert summary.num_rows == 6
    assert (run / "config.yaml").is_file()
    assert re.search(r"FB\s+3\s+2\.\d+ \+- ", output)


@pytest.mark.parametrize("name", ["simulations.parquet", "simulation_summary.parquet", "config.yaml"])
def test_simulate_identical_across_jobs(simulated, name):
    assert (simulated[1][0] / name).read_bytes() == (simulated[2][0] / name).read_bytes()


@pytest.mark.parametrize(
    "edit, message",
    [
        (("seeds: [1, 2, 3]", "seeds: []"), "seeds: must be a non-empty list"),
        (("zeta_n: 0.26", "zeta_n: 0.26\n  extra: 1"), "loop.extra: unknown key"),
        (
            (
                "estimation: [129, 1088], validation: [1089, 2048]}\n  stage1",
                "estimation: [129, 1088], validation: [1089, 3000]}\n  stage1",
            ),
            "identify.direct.validation",
        ),
        (("Kc: 2.75", "Kc: [2.75]"), "loop.Kc: must be a number"),
        # SPEC 7: plants and hypotheses that cannot be simulated.
        (
            (_PAPER_PLANT, "  plant: {kind: triple_integrator, K: 1}"),
            "loop.plant.kind: unknown plant shorthand",
        ),
        (
            (_PAPER_PLANT, "  plant: {kind: tf, num: [1], den: [1, 0, 0, 0, 0, 0]}"),
            "models.FF: the feedforward path Ynms Kpt / Yc / (TI s + 1)^2 is improper",
        ),
        (
            (_PAPER_PLANT, "  plant: {kind: integrator, K: 3}\n  disturbance_at: input"),
            "models.FB: the closed loop with this plant is unstable (pole at z = 1.0047-0.0788j",
        ),
    ],
)
def test_bad_config_exit_2_one_line_nothing_written(tmp_path, edit, message):
    text = CI_CONFIG.read_text()
    assert edit[0] in text
    bad = tmp_path / "bad.yaml"
    bad.write_text(text.replace(edit[0], edit[1], 1))
    run = tmp_path / "run"
    result = runner.invoke(app, ["simulate", str(bad), "--run", str(run), "--quiet"])
    assert result.exit_code == 2
    assert message in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    assert not run.exists()


def test_bad_config_keeps_earlier_results(simulated, tmp_path):
    run = simulated[1][0]
    before = (run / "simulations.parquet").read_bytes()
    bad = tmp_path / "bad.yaml"
    bad.write_text(CI_CONFIG.read_text().replace("seeds: [1, 2, 3]", "seeds: [1, -2]"))
    result = runner.invoke(app, ["simulate", str(bad), "--run", str(run), "--quiet"])
    assert result.exit_code == 2
    assert "seeds[1]: must be an integer in [0, 2147483647], got -2" in result.stderr
    assert (run / "simulations.parquet").read_bytes() == before


def test_forcing_file_missing_its_column_exit_2_nothing_written(tmp_path):
    (tmp_path / "sig.csv").write_text("t,fd\n" + "".join(f"{i / 25},0.01\n" for i in range(2048)))
    text = CI_CONFIG.read_text()
    start, end = text.index("  disturbance:"), text.index("  target:")
    bad = tmp_path / "bad.yaml"
    bad.write_text(
        text[:start] + "  disturbance: {kind: file, path: sig.csv, column: fdx, rate: 25}\n" + text[end:]
    )
    run = tmp_path / "run"
    result = runner.invoke(app, ["simulate", str(bad), "--run", str(run), "--quiet"])
    assert result.exit_code == 2
    assert "signals.disturbance: " in result.stderr and "has no column 'fdx'" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    assert not run.exists()


def test_window_not_whole_samples_exit_2_nothing_written(tmp_path):
    text = CI_CONFIG.read_text()
    text = text.replace("  target_shift: 1.0\n", "  target_shift: 1.0\n  windows_in: seconds\n", 1)
    text = text.replace(
        "estimation: [129, 1088], validation: [1089, 2048]",
        "estimation: [5.13, 43.52], validation: [43.52, 81.92]",
        1,
    )
    bad = tmp_path / "bad.yaml"
    bad.write_text(text)
    run = tmp_path / "run"
    result = runner.invoke(app, ["simulate", str(bad), "--run", str(run), "--quiet"])
    assert result.exit_code == 2
    assert "identify.direct.estimation: 5.13 s is not a whole number of samples" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    assert not run.exists()


# --------------------------------------------------------------------------- command-line misuse (issue 24)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["fit-hc", "c.yaml", "--w", "abc"], "hcid: error: Invalid value for '--w': "),
        (["simulate", "c.yaml", "--jobs", "0"], "hcid: error: Invalid value for '--jobs': "),
        (["run"], "hcid: error: Missing argument 'config'."),
        (["identify", "c.yaml", "--backend", "loky", "--scheduler", "tcp://127.0.0.1:1"],
         "hcid: error: scheduler (--scheduler): only with backend dask (got loky)"),
        (["analyse", "c.yaml", "--data", "a.csv", "b.csv"],  # an unquoted glob, as the shell expands it
         "hcid: error: Got unexpected extra argument(s) (b.csv) (a glob the shell expanded? quote it"),
    ],
)  # fmt: skip
def test_misuse_is_one_line_exit_2(tmp_path, argv, message):
    # The real command (its entry point hcid.cli:main), not CliRunner: before, click's usage box
    # of 5-6 lines. python -m hcid is the same command.
    import subprocess
    import sys

    (tmp_path / "c.yaml").write_text(CI_CONFIG.read_text())
    for command in ([sys.executable, "-m", "hcid"],):
        proc = subprocess.run([*command, *argv], cwd=tmp_path, capture_output=True, text=True, timeout=120)
        assert proc.returncode == 2, proc.stderr
        assert proc.stderr.startswith(message) and len(proc.stderr.strip().splitlines()) == 1, proc.stderr
    assert not (tmp_path / "runs").exists()


def test_help_text_has_no_stray_spaces():
    # Unstyled: with FORCE_COLOR, PY_COLORS, TTY_COMPATIBLE or GITHUB_ACTIONS set, typer and rich
    # colour the help text, whose codes would split the sentence (a CI setting, not a defect).
    import click

    result = runner.invoke(app, ["run", "--help"], env={"COLUMNS": "200", "TERMINAL_WIDTH": "200"})
    text = click.unstyle(result.output)
    assert "Run directory (default: runs/<config name>)." in text and " ." not in text


def test_commands_do_not_silence_warnings():
    # Before, every command ignored every RuntimeWarning; a warning now reaches the user.
    import warnings

    from hcid.cli import _user_errors

    with pytest.warns(RuntimeWarning, match="reaches the user"):
        _user_errors(lambda: warnings.warn("reaches the user", RuntimeWarning, stacklevel=1))()


def test_version_prints_the_installed_version():
    # Source: the package's own metadata (pyproject.toml's version, as installed).
    from importlib.metadata import version

    from typer.testing import CliRunner

    from hcid.cli import app

    result = CliRunner().invoke(app, ["--version"])
    assert result.exit_code == 0 and result.output.strip() == f"hcid {version('hcid')}"


def test_a_tiny_p_value_reads_p_below_not_p_equals_below():
    # Issue 46 (9): lab_weak printed "p = < 1e-15". Source: the wording rule of
    # hcid.hcfit.consistency.p_text, below what double precision resolves.
    from hcid.cli.answers import _data_check_line

    g = {
        "fc_dof": 40, "fc_verdict": "contradicted by the data", "n_contradicted": 3, "n_runs": 12,
        "fc_chi2": 400.0, "fc_p": 1e-30, "fc_spread": "across 12 runs", "he_error_db": 0.6,
        "he_error_deg": 3.0, "ht_error_db": float("nan"), "ht_error_deg": float("nan"),
        "twin_source": "medians of the values its runs determine",
    }  # fmt: skip
    line = _data_check_line(g, full=True)
    assert "p < 1e-15," in line and "p = <" not in line
