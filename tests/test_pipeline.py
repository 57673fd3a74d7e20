"""The identify / sweep-w pipeline on configs/ci.yaml: determinism, resume, backends, bad data."""

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
import yaml
from typer.testing import CliRunner

from hcid import pipeline, tables
from hcid.cli import app
from hcid.io import results
from hcid.pipeline import Execution, studies

from . import naive
from .conftest import CI_CONFIG, interrupt_after

runner = CliRunner()
TABLES = (
    "frontier.parquet",
    "stage1.parquet",
    "selection.parquet",
    "breakpoints.parquet",
    "thresholds.parquet",
)


def _run(args):
    result = runner.invoke(app, [*args, "--quiet"] if args[0] != "sweep-w" else args)
    assert result.exit_code == 0, result.output
    return result


@pytest.fixture(scope="module")
def ci_runs(tmp_path_factory):
    """configs/ci.yaml run end to end with --jobs 1 and --jobs 2."""
    base = tmp_path_factory.mktemp("pipe")
    runs = {}
    for jobs in (1, 2):
        run = base / f"jobs{jobs}"
        _run(["run", str(CI_CONFIG), "--run", str(run), "--jobs", str(jobs)])
        runs[jobs] = run
    return runs


def test_tables_written(ci_runs, ci_config):
    run = ci_runs[1]
    frontier = pq.read_table(run / "frontier.parquet")
    g = ci_config.identify.stage("direct").grid
    triples = (g.na[1] - g.na[0] + 1) * (g.nb1[1] - g.nb1[0] + 1) * (g.nb2[1] - g.nb2[0] + 1)
    # one row per model, seed, method and (na, nb_ft, nb_e)
    assert frontier.num_rows == 2 * 3 * 2 * triples
    assert pq.read_table(run / "stage1.parquet").num_rows == 2 * 3
    assert pq.read_table(run / "selection.parquet").num_rows == 2 * 3 * 2 * len(ci_config.selection.w_grid)
    thresholds = pq.read_table(run / "thresholds.parquet").to_pylist()
    assert {(r["method"], r["model"]) for r in thresholds} == {
        (m, mo) for m in ("direct", "indirect") for mo in ("FB", "FF")
    }


@pytest.mark.parametrize("name", TABLES)
def test_identical_across_jobs(ci_runs, name):
    assert (ci_runs[1] / name).read_bytes() == (ci_runs[2] / name).read_bytes()


def test_selection_table_is_brute_force_argmin(ci_runs, ci_config):
    # Every stored selection equals the row-by-row argmin of log V + W d over the frontier.
    run = ci_runs[1]
    frontier = results.split_by_key(pq.read_table(run / "frontier.parquet"), tables.FRONTIER.key)
    chosen = pq.read_table(run / "selection.parquet").to_pylist()
    cols = ("na", "nb_ft", "nb_e", "nk_ft", "nk_e")
    for row in chosen[::7]:
        t = frontier[(row["model"], row["seed"], row["method"])]
        d = t.column("d").to_numpy()
        v = t.column("v").to_numpy()
        orders = np.column_stack([t.column(c).to_numpy() for c in cols])
        i = naive.select_brute_force(d, v, orders, row["w"])
        assert tuple(orders[i]) == tuple(row[c] for c in cols)


def test_thresholds_match_fine_grid(ci_runs):
    # W_FP / W_FN from exact breakpoints bracket the values seen on a fine W grid.
    run = ci_runs[1]
    frontier = results.split_by_key(pq.read_table(run / "frontier.parquet"), tables.FRONTIER.key)
    w = np.geomspace(1e-5, 20, 3000)
    thresholds = {(r["method"], r["model"]): r for r in pq.read_table(run / "thresholds.parquet").to_pylist()}
    cols = ("na", "nb_ft", "nb_e", "nk_ft", "nk_e")
    for method in ("direct", "indirect"):
        nb = {}
        for (model, _seed, m), t in frontier.items():
            if m != method:
                continue
            d, v = t.column("d").to_numpy(), t.column("v").to_numpy()
            orders = np.column_stack([t.column(c).to_numpy() for c in cols])
            nb.setdefault(model, []).append(
                np.array([orders[naive.select_brute_force(d, v, orders, x), 1] for x in w])
            )
        fp = np.flatnonzero(np.any(np.array(nb["FB"]) > 0, axis=0))
        w_fp = thresholds[(method, "FB")]["w_fp"]
        if fp.size:
            assert w[fp[-1]] < w_fp <= w[fp[-1] + 1]
        fn = np.flatnonzero(np.mean(np.array(nb["FF"]), axis=0) < 2)
        w_fn = thresholds[(method, "FF")]["w_fn"]
        assert fn[0] > 0  # the mean starts at 2 or more on this grid
        assert w[fn[0] - 1] < w_fn <= w[fn[0]]


def test_resume_after_interruption_gives_identical_tables(ci_runs, tmp_path, monkeypatch, ci_config):
    run = tmp_path / "resumed"
    run.mkdir()
    for name in ("simulations.parquet", "config.yaml"):
        shutil.copy(ci_runs[1] / name, run / name)
    real = interrupt_after(monkeypatch, studies, "_identify_task", 5)
    with pytest.raises(KeyboardInterrupt):
        pipeline.identify_study(ci_config, run, execution=Execution(1, progress=False))
    assert not (run / "frontier.parquet").exists()
    assert len(list((run / ".parts").glob("*/*.frontier.arrow"))) == 5
    monkeypatch.setattr(studies, "_identify_task", real)
    resumed = pipeline.identify_study(ci_config, run, execution=Execution(1, progress=False))
    assert (resumed.computed, resumed.reused) == (7, 5)
    for name in ("frontier.parquet", "stage1.parquet"):
        assert (run / name).read_bytes() == (ci_runs[1] / name).read_bytes()
    assert not (run / ".parts").exists()


def test_done_realizations_are_not_recomputed(ci_runs, ci_config, monkeypatch):
    def fail(*args):
        raise AssertionError("recomputed a finished realization")

    monkeypatch.setattr(studies, "_identify_task", fail)
    again = pipeline.identify_study(ci_config, ci_runs[2], execution=Execution(1, progress=False))
    assert again.computed == 0


def test_dask_local_cluster_gives_identical_tables(ci_runs, tmp_path):
    pytest.importorskip("dask.distributed")
    run = tmp_path / "dask"
    run.mkdir()
    for name in ("simulations.parquet", "config.yaml"):
        shutil.copy(ci_runs[1] / name, run / name)
    _run(["identify", str(CI_CONFIG), "--run", str(run), "--backend", "dask", "--jobs", "2"])
    for name in ("frontier.parquet", "stage1.parquet"):
        assert (run / name).read_bytes() == (ci_runs[1] / name).read_bytes()
    # Every task ran on a worker of the cluster, none in this (the client's) process.
    workers = pq.read_table(run / "identify_log.parquet").column("worker").to_pylist()
    pids = {int(w.rsplit(":", 1)[1]) for w in workers}
    assert os.getpid() not in pids and len(pids) >= 1


def _dask_worker(address: str) -> subprocess.Popen:
    dask = Path(sys.executable).parent / "dask"
    return subprocess.Popen(
        [str(dask), "worker", address, "--nworkers", "1", "--nthreads", "1", "--no-nanny", "--no-dashboard"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )


def test_dask_all_workers_lost_fails_in_one_line_within_the_timeout(ci_runs, tmp_path):
    # Two workers without nannies on a loopback scheduler; both are killed (-9) once the
    # first task is done: hcid must end with one line within --worker-timeout (plus polling).
    # The tasks fit the paper's grids (SPEC 3: ~1.4 s each on one core, 12 tasks), so that
    # most are still pending at the kill however fast the machine is.
    distributed = pytest.importorskip("dask.distributed")
    run = tmp_path / "lost"
    run.mkdir()
    for name in ("simulations.parquet", "config.yaml"):
        shutil.copy(ci_runs[1] / name, run / name)
    raw = yaml.safe_load(CI_CONFIG.read_text())
    raw["identify"] = {"target_shift": raw["identify"]["target_shift"]}  # the paper's grids
    config = tmp_path / "ci_paper_grids.yaml"
    config.write_text(yaml.safe_dump(raw))
    with distributed.LocalCluster(
        n_workers=0, processes=True, dashboard_address=None, host="127.0.0.1"
    ) as cluster:
        workers = [_dask_worker(cluster.scheduler_address) for _ in range(2)]
        try:
            # Both joined before hcid starts: --worker-timeout 4 also bounds its first wait for one.
            with distributed.Client(cluster) as client:
                client.wait_for_workers(2, timeout=120)
            cmd = [str(Path(sys.executable).parent / "hcid"), "identify", str(config), "--run", str(run),
                   "--backend", "dask", "--scheduler", cluster.scheduler_address, "--worker-timeout", "4",
                   "--force", "--quiet"]  # fmt: skip
            proc = subprocess.Popen(cmd, stderr=subprocess.PIPE, text=True)
            deadline = time.monotonic() + 240
            while not list((run / ".parts").glob("*/*.log.arrow")) and time.monotonic() < deadline:
                time.sleep(0.2)
            for w in workers:
                w.kill()
            killed = time.monotonic()
            _, err = proc.communicate(timeout=120)
            elapsed = time.monotonic() - killed
        finally:
            for w in workers:
                w.kill()
    assert proc.returncode == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("hcid: error: dask: no worker for 4 s")
    assert elapsed < 4 + 30  # the timeout, one poll and shutdown


def test_dask_scheduler_without_workers_is_one_line(tmp_path, ci_runs):
    distributed = pytest.importorskip("dask.distributed")
    run = tmp_path / "none"
    run.mkdir()
    for name in ("simulations.parquet", "config.yaml"):
        shutil.copy(ci_runs[1] / name, run / name)
    with distributed.LocalCluster(
        n_workers=0, processes=True, dashboard_address=None, host="127.0.0.1"
    ) as cluster:
        result = runner.invoke(
            app,
            ["identify", str(CI_CONFIG), "--run", str(run), "--backend", "dask",
             "--scheduler", cluster.scheduler_address, "--worker-timeout", "3", "--quiet"],
        )  # fmt: skip
    assert result.exit_code == 2
    assert "no worker joined within 3 s" in result.stderr


def _bad_run(tmp_path, ci_runs, damage):
    run = tmp_path / "bad"
    shutil.copytree(ci_runs[1], run)
    (run / "frontier.parquet").unlink()
    damage(run / "simulations.parquet")
    return run


@pytest.mark.parametrize(
    "damage, message",
    [
        (lambda p: p.write_bytes(b"not parquet at all"), "simulations.parquet: not a readable Parquet table"),
        (lambda p: p.write_bytes(p.read_bytes()[: len(p.read_bytes()) // 2]), "not a readable Parquet table"),
        (lambda p: pq.write_table(pq.read_table(p).drop_columns(["e"]), p), "missing columns ['e']"),
        (
            lambda p: pq.write_table(
                pq.read_table(p).set_column(
                    6,
                    "e",
                    [np.where(np.arange(12288) == 77, np.nan, pq.read_table(p).column("e").to_numpy())],
                ),
                p,
            ),
            "column 'e' holds nan at model FB, seed 1, k 77",
        ),
    ],
)
def test_corrupt_simulations_exit_2(tmp_path, ci_runs, damage, message):
    run = _bad_run(tmp_path, ci_runs, damage)
    result = runner.invoke(app, ["identify", str(CI_CONFIG), "--run", str(run), "--quiet"])
    assert result.exit_code == 2
    assert message in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    assert not (run / "frontier.parquet").exists()


def test_sweep_without_frontier_exit_2(tmp_path):
    result = runner.invoke(app, ["sweep-w", str(CI_CONFIG), "--run", str(tmp_path / "empty")])
    assert result.exit_code == 2
    assert "empty: missing; make it first with `hcid run CONFIG` (a simulated study) or" in result.stderr
    assert "`hcid analyse CONFIG --data DATA` (measured data)" in result.stderr
    assert not (tmp_path / "empty").exists()
    (tmp_path / "empty").mkdir()
    result = runner.invoke(app, ["sweep-w", str(CI_CONFIG), "--run", str(tmp_path / "empty")])
    assert result.exit_code == 2
    assert "frontier.parquet: missing; run `hcid identify` first" in result.stderr


def test_identify_simulates_when_missing(tmp_path):
    run = tmp_path / "fresh"
    result = runner.invoke(
        app, ["identify", str(CI_CONFIG), "--run", str(run), "--method", "direct", "--jobs", "1", "--quiet"]
    )
    assert result.exit_code == 0, result.output
    assert (run / "simulations.parquet").is_file()
    methods = set(pq.read_table(run / "frontier.parquet").column("method").to_pylist())
    assert methods == {"direct"}


def test_other_config_in_same_run_dir_is_refused(ci_runs, tmp_path):
    other = tmp_path / "other.yaml"
    other.write_text(CI_CONFIG.read_text().replace("remnant_ratio: 0.15", "remnant_ratio: 0.2"))
    before = (ci_runs[1] / "frontier.parquet").read_bytes()
    result = runner.invoke(app, ["simulate", str(other), "--run", str(ci_runs[1]), "--quiet"])
    assert result.exit_code == 2
    assert "made with another config (loop.remnant_ratio differs)" in result.stderr
    assert (ci_runs[1] / "frontier.parquet").read_bytes() == before


def test_sweep_with_a_new_w_grid_is_accepted(ci_runs, tmp_path):
    run = tmp_path / "regrid"
    shutil.copytree(ci_runs[1], run)
    other = tmp_path / "ci.yaml"
    other.write_text(CI_CONFIG.read_text().replace("points: 61", "points: 31"))
    result = runner.invoke(app, ["sweep-w", str(other), "--run", str(run)])
    assert result.exit_code == 0, result.output
    assert pq.read_table(run / "selection.parquet").num_rows == 2 * 3 * 2 * 31
    assert "points: 31" in (run / "config.yaml").read_text()


def test_identify_force_recovers_damaged_tables(ci_runs, tmp_path):
    run = tmp_path / "damaged"
    shutil.copytree(ci_runs[1], run)
    (run / "frontier.parquet").write_bytes(b"garbage")
    result = runner.invoke(app, ["identify", str(CI_CONFIG), "--run", str(run), "--quiet"])
    assert result.exit_code == 2
    assert "frontier.parquet: not a readable Parquet table" in result.stderr
    result = runner.invoke(app, ["identify", str(CI_CONFIG), "--run", str(run), "--force", "--quiet"])
    assert result.exit_code == 0, result.output
    assert (run / "frontier.parquet").read_bytes() == (ci_runs[1] / "frontier.parquet").read_bytes()


def test_wrong_column_type_in_simulations_exit_2(tmp_path, ci_runs):
    run = _bad_run(
        tmp_path,
        ci_runs,
        lambda p: pq.write_table(
            pq.read_table(p).set_column(1, "seed", [pq.read_table(p).column("seed").cast("string")]), p
        ),
    )
    result = runner.invoke(app, ["identify", str(CI_CONFIG), "--run", str(run), "--quiet"])
    assert result.exit_code == 2
    assert "column 'seed' is string, expected int64" in result.stderr


def test_run_dir_that_is_a_file_exit_2(tmp_path):
    target = tmp_path / "afile"
    target.write_text("not a directory")
    result = runner.invoke(app, ["simulate", str(CI_CONFIG), "--run", str(target), "--quiet"])
    assert result.exit_code == 2
    assert "not a directory" in result.stderr
    assert target.read_text() == "not a directory"


def test_bad_backend_exit_2_before_any_work(tmp_path):
    run = tmp_path / "nothing"
    result = runner.invoke(app, ["run", str(CI_CONFIG), "--run", str(run), "--backend", "spark", "--quiet"])
    assert result.exit_code == 2
    assert "backend (--backend): must be one of loky, dask, got 'spark'" in result.stderr
    assert not run.exists()
