"""``make bench``'s scripts run in their smoke mode (``--smoke``), so that a broken benchmark
fails ``make test`` instead of the next person who times something.

Each script runs as ``make bench`` runs it, a subprocess of this venv's python from the
project root with BLAS on one thread; all five start at once (about 50 s of wall on two
idle cores, measured 2026-11-28 on a 2-core Xeon), and
each test checks its exit code and the lines its script must print.
"""

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
#: The scripts of ``make bench``, in its order, and their arguments besides ``--smoke``; then
#: serial_part (issue 47: where ``hcid analyse``'s serial part lies) and null_study (SPEC 13's
#: null study end to end) and forcing_share (issue 47 item 2: what a forcing set's twins share)
#: and structure_counts (issue 48: how hcid analyse passes results between its steps).
SCRIPTS = {
    "arx_engine": [],
    "fit_hc": [],
    "cold_start": ["--json", "{tmp}/cold_start.json"],
    "serial_part": [],
    "null_study": ["--out", "{tmp}/null_study.csv"],
    "forcing_share": [],
    "structure_counts": [],
}
TIMEOUT_S = 600

pytestmark = pytest.mark.skipif(
    os.environ.get("NUMBA_DISABLE_JIT", "0") not in ("", "0"),
    reason="NUMBA_DISABLE_JIT: the benchmarks time and count compiled kernels",
)


@pytest.fixture(scope="module")
def smoke_runs(tmp_path_factory):
    """Every script started at once; per script, a function that waits for it and returns
    (exit code, stdout, stderr)."""
    tmp = tmp_path_factory.mktemp("bench-smoke")
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    started = {}
    for name, extra in SCRIPTS.items():
        out, err = open(tmp / f"{name}.out", "w"), open(tmp / f"{name}.err", "w")  # noqa: SIM115
        args = [a.format(tmp=tmp) for a in extra]
        command = [sys.executable, str(ROOT / "benchmarks" / f"{name}.py"), "--smoke", *args]
        started[name] = (subprocess.Popen(command, cwd=ROOT, env=env, stdout=out, stderr=err), out, err)

    def result(name):
        proc, out, err = started[name]
        try:
            code = proc.wait(TIMEOUT_S)
        except subprocess.TimeoutExpired:
            proc.kill()
            raise
        finally:
            out.close()
            err.close()
        return code, (tmp / f"{name}.out").read_text(), (tmp / f"{name}.err").read_text()

    result.tmp = tmp
    yield result
    for proc, out, err in started.values():
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        out.close()
        err.close()


def _lines(text: str, pattern: str) -> list[str]:
    return [line for line in text.splitlines() if re.match(pattern, line)]


def test_arx_engine_smoke(smoke_runs):
    code, out, err = smoke_runs("arx_engine")
    assert code == 0, out + err
    # Both engines (fused, unfused) against the old kernel on the direct, stage-1 and stage-2 grids.
    identical = _lines(
        out, r"(direct|stage 1|stage 2), engine, (fused|unfused) vs old .* frontier identical: "
    )
    assert len(identical) == 6, out
    assert all(line.endswith("frontier identical: True") for line in identical), out
    assert _lines(out, r"agreement on the sample +unstable flags equal: True, max relative V difference"), out
    assert _lines(out, r"per candidate vs reference loop +engine +[0-9.]+ x"), out
    assert _lines(out, r"stage 1 vs stage 2 per candidate +[0-9.]+ x the stage-2 rate"), out


def test_fit_hc_smoke(smoke_runs):
    code, out, err = smoke_runs("fit_hc")
    assert code == 0, out + err
    assert out.count("\n\nintegrator_example (") == 1, out
    ci, integrator = out.split("\n\nintegrator_example (")
    row = r"{} +1 +[0-9.]+ +[0-9.]+ +[0-9.]+"
    # The CI config's record (the paper's forcing functions) has no forcing lines: every
    # estimator but lines is timed, lines is skipped with hcid's reason.
    for target in ("auto", "time", "closed_loop", "frequency"):
        assert _lines(ci, row.format(target)), ci
    assert _lines(ci, r"lines +skipped on 1 of 1 models, their records: no forcing lines: "), ci
    assert not _lines(ci, row.format("lines")), ci
    # The integrator example's multisines have them: every estimator is timed, auto as lines.
    for target in ("lines", "time", "closed_loop", "frequency"):
        assert _lines(integrator, row.format(target)), integrator
    assert _lines(integrator, row.format("auto") + r" +ran as lines on 1$"), integrator
    assert "skipped" not in integrator, integrator
    assert out.count("the config's estimator (auto), whole task per model and method:") == 2, out


def test_cold_start_smoke(smoke_runs):
    code, out, err = smoke_runs("cold_start")
    assert code == 0, out + err
    for pattern in (
        r"cold --jobs 1, recorded: [0-9.]+ s compiling of [0-9.]+ s wall",
        r"hcid\.arx\._kernels +\d+ +\d+",
        r"warm --jobs 1, recorded: .* 0 functions compiled \(0 signatures\)",
        r"install's warm-up on a fresh cache: [0-9.]+ s wall",
        r"first run after it, --jobs 1, recorded: [0-9.]+ s wall",
        r"round 1 +[0-9.]+ / +[0-9.]+",
        r"cold start over warm, --jobs 2: -?[0-9.]+ s \(",
        r"first run after the install's warm-up over warm, --jobs 2: -?[0-9.]+ s \(",
        r"load after ",
    ):
        assert _lines(out, pattern), f"no line matching {pattern!r} in:\n{out}"
    result = json.loads((smoke_runs.tmp / "cold_start.json").read_text())
    assert result["smoke"] is True
    # The cold run compiled the engine's kernels; the warm one, on that cache, compiled nothing
    # (a kernel compiled again there is a cache miss: its @njit lacks cache=True, or its cache
    # entry does not load).
    assert {f["module"] for f in result["recorded_cold"]["functions"]} >= {"hcid.arx._kernels"}
    assert result["recorded_warm"]["functions"] == []
    assert set(result["wall_s"]) == {"cold --jobs 2", "warm --jobs 2", "cold --jobs 1", "installed --jobs 2"}


def test_serial_part_smoke(smoke_runs):
    # hcid analyse with --jobs 1 and 2, each phase named with its wall, pool and outside times;
    # every phase's pool time within its wall (both measured on one clock, the pool's spans
    # clipped to the phase).
    code, out, err = smoke_runs("serial_part")
    assert code == 0, out + err
    phases = ("read the data", "identify", "fit runs", "twins", "line statistics", "more FB twins")
    phases += ("fit selected", "tables", "report")
    for jobs in (1, 2):
        assert _lines(out, rf"--jobs {jobs}: wall [0-9.]+ s, in the pool [0-9.]+ s \(.*\), outside it"), out
    for name in phases:
        found = _lines(out, rf"    {name}: wall ")
        assert len(found) == 2, out
        for line in found:
            wall, inside, outside = (float(x) for x in re.findall(r"([0-9.]+) s", line))
            assert inside <= wall + 0.05 and abs(wall - inside - outside) <= 0.15, line
    assert _lines(out, r"Amdahl from the two walls .*: serial S = 2 T2 - T1 = -?[0-9.]+ s"), out


def test_null_study_smoke(smoke_runs):
    # One study of 4 feedback-only runs through hcid analyse (4 + 8 twins): the table has a row per
    # method and statistic (W*, Fourier, LR and the deciding p), and the per-run CSV a row per run
    # and method with every p-value a probability.
    import csv

    code, out, err = smoke_runs("null_study")
    assert code == 0, out + err
    for method in ("direct", "indirect"):
        for statistic in (r"W\*", "Fourier", "LR", r"p_value \(.*\)"):
            assert _lines(out, rf"\| {method} \| {statistic} \| 4 \| "), out
    with open(smoke_runs.tmp / "null_study.csv") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 8 and {r["method"] for r in rows} == {"direct", "indirect"}
    for r in rows:
        for column in ("p_w_star", "p_fourier", "p_lr", "p_value"):
            assert 0.0 < float(r[column]) <= 1.0, (column, r)


def test_forcing_share_smoke(smoke_runs):
    # Both methods' identification timed, and the forcing-only part with its share, a percentage.
    code, out, err = smoke_runs("forcing_share")
    assert code == 0, out + err
    assert _lines(out, r"identification: direct [0-9.]+ ms, indirect [0-9.]+ ms \(stage 1 [0-9.]+ ms\)"), out
    (line,) = _lines(out, r"forcing-only work .*: [0-9.]+ ms, [0-9.]+% of both methods' identification")
    share = float(re.search(r"([0-9.]+)% of both", line).group(1))
    assert 0 < share < 100, line


def test_structure_counts_smoke(smoke_runs):
    # Issue 48's refactor, pinned (docs/contributing.md, "One hcid analyse run"; before it, at
    # e68c3ba: 10 functions took (study, found), 4 tables were read back by the analysis that had
    # written them, the study's config file was read twice).
    code, out, err = smoke_runs("structure_counts")
    assert code == 0, out + err
    assert _lines(out, r"functions taking \(study, found\) +0$"), out
    assert _lines(out, r"tables read back by the analysis +0$"), out
    assert _lines(out, r"study config file reads +1$"), out
