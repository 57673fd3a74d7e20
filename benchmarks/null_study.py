"""Are the runs' p-values uniform when nobody uses feedforward? A simulated null study end to end
through `hcid analyse` (SPEC 13: "under feedback-only truth the p-values must be uniform").

    .venv/bin/python benchmarks/null_study.py                          # 50 studies x 20 runs
    .venv/bin/python benchmarks/null_study.py --studies 10 --jobs 2 --out /tmp/null.csv
    .venv/bin/python benchmarks/null_study.py --smoke                  # 1 study of 4 runs (a test)

Design. ``--studies`` studies, each of ONE condition (``compensatory``: Kpt = 0 in every run, so
one group, one forcing set and one set of twins per study), ``--runs-per-study`` SUBJECTSxTRIALS
runs (default 5x4 = 20). Each study's subjects are drawn as benchmarks/lab_study.py's ``large``
study draws them (its ``RANGES``, the example's, and its phase-margin check ``_margins_ok``;
only the feedback path matters here) and its files are written by configs/lab_example/make.py's
``make`` (hcid's simulator, 60 Hz, 45 s, the lab example's remnant: 1.0 x the integrator
example's gain), then analysed by ``hcid.analyse`` (the function ``hcid analyse`` runs; its
defaults except ``--twins`` and ``--max-fb-twins``, one worker per study: studies run side by
side on ``--jobs`` processes). Every study has its own seed, spawned from ``--seed`` with numpy's
SeedSequence (the results do not depend on ``--jobs``); every run its own remnant seed. make.py
takes the forcing functions from configs/integrator_example.yaml and has no option for their
phases, so every study has the SAME forcing functions (only the subjects and remnants differ).

Twins' noise. Every study here has the same forcing functions. Before hcid drew its twins'
remnants from a stream of their own (``seeds: stream``, a digest of the group and its data:
hcid.pipeline.twins.TwinSource.noise_stream), a study's twins took remnant seeds 1, 2, ... alone,
so the twins of all studies shared their noise and the table showed one draw of the twins'
quantiles (the share of p <= 0.05 over 1000 runs then had a spread of about 0.02, three times the
binomial's), not the p-values' level; this benchmark salted the simulator's noise per study then.
hcid as shipped now keeps the studies apart (each study's runs differ), and the benchmark runs it
as it is.

Discrete p-values. A Monte Carlo p is not uniform but exact on its support: ``(1 + k) / (1 + N)``
(k of N FB twins at or above the run) and Besag and Clifford's sequential ``5 / m`` (stopped at the
m-th twin, the 5th at or above), whose support together is ``1/(N+1) < ... < 5/(N+1) < 5/N < ... <
5/5``, and P(p <= s) = s at every support point s (continuous statistics). The KS test is of the
randomized p, uniform in (s_prev, p] with s_prev the support point below p: ``5 / (m + 1)`` for a
stopped p (``5 / m`` with m = ``fb_twins_*``), ``p - 1 / (N + 1)`` for a count over all N drawn
(N = ``fb_twins_*``); a ``gpd tail`` p (a run beyond every twin, below 1/(N+1)) is continuous and
kept. The randomized p is uniform exactly where no FB twin ties the run's statistic (W* clipped at
the grid's ends can tie: ties make the p larger, conservative): ``tied runs`` counts such runs.
The deciding ``p_value`` is randomized with the same draw as its statistic's p. P(p <= 0.01) and
P(p <= 0.05) are of hcid's own p (what a run's decision uses), beside their binomial 99%
acceptance band (``scipy.stats.binom.ppf`` at 0.005 and 0.995 for n runs at the nominal level,
over n); the randomized p's shares are in the summary CSV (``randomized_le_*``).

Shared twins. The binomial band and the KS test assume independent runs, but a study's runs are
judged against the same FB twins, so their p-values are correlated (under an exact null too):
the share and the KS statistic spread more than the binomial and Kolmogorov distributions say.
``{clustered}`` bands and ``KS p clustered`` are therefore given as well, from 1000 simulated
exact nulls of the same design (:func:`ideal_null`: per study its runs and its N FB twins i.i.d.,
the twins shared, hcid's sequential p, randomized): the 0.5% and 99.5% quantiles of the share,
and the share of simulated KS statistics at or above the observed one.

Targets (SPEC 13), per method (direct, indirect) and statistic (W*, Fourier size, likelihood
ratio, and the deciding ``p_value``), over at least 1,000 runs: KS of the randomized p not
rejected at 1%; P(p <= 0.01) and P(p <= 0.05) within their binomial 99% bands (``uniform: SPEC
13``); the same against the clustered KS p and bands (``clustered``). Measured on a 2-core Xeon
shared with other jobs (load 4 to 9): 50 studies x 20 runs in 33 min with ``--jobs 2``.

Output: one row per run and method (``--out``, CSV: the p-values, how each was made, the twins it
used, the randomized p, ties, the study and the subject's true feedback), and the table printed
and written beside it (``<out stem>_summary.csv``), with the wall time, CPU and load.
``--from-csv CSV`` makes the table again from such a per-run CSV, without running studies.
"""

from __future__ import annotations

import argparse
import csv
import importlib.util
import math
import os
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from multiprocessing import get_context
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
HERE = Path(__file__).resolve().parent

#: The statistics: name in the table -> the columns' stem (``p_<stem>``, ``p_<stem>_method``,
#: ``fb_twins_<stem>``) and the statistic's value column in analysis.parquet / evidence_twins.parquet.
STATISTICS = {
    "W*": ("w_star", "w_star"),
    "Fourier": ("fourier", "fourier_size"),
    "LR": ("lr", "likelihood_ratio"),
}
#: ``decided_by`` in analysis.parquet -> the statistic's name here.
DECIDED_BY = {"W*": "W*", "Fourier coefficients": "Fourier", "likelihood ratio": "LR"}
LEVELS = (0.01, 0.05)
#: Besag and Clifford's h (hcid.pipeline.evidence.EXCEEDANCES).
H = 5
FEEDBACK = ("Kpe", "TL", "tau_pe")


def _load(name: str, path: Path):
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _runs_per_study(text: str) -> tuple[int, int]:
    """``5x4`` (subjects x trials), or ``n`` (n subjects, one trial each)."""
    parts = text.lower().split("x")
    try:
        subjects, trials = (int(parts[0]), 1) if len(parts) == 1 else (int(parts[0]), int(parts[1]))
    except ValueError:
        raise argparse.ArgumentTypeError(f"SUBJECTSxTRIALS (e.g. 5x4), got {text!r}") from None
    if subjects < 1 or trials < 1 or len(parts) > 2:
        raise argparse.ArgumentTypeError(f"SUBJECTSxTRIALS (e.g. 5x4), got {text!r}")
    return subjects, trials


def study_spec(seq: np.random.SeedSequence, subjects: int, trials: int) -> dict:
    """The study's subjects (lab_study.py's ranges and check), its single compensatory condition,
    and its first remnant seed (make.py adds 1 per run), all from ``seq``."""
    lab_study = _load("lab_study", HERE / "lab_study.py")
    rng = np.random.default_rng(seq)
    truth = {}
    while len(truth) < subjects:
        p = {name: round(float(rng.uniform(lo, hi)), 3) for name, (lo, hi) in lab_study.RANGES.items()}
        if lab_study._margins_ok(p):
            truth[f"P{len(truth) + 1:02d}"] = p
    first = int(seq.generate_state(2, np.uint32)[0])  # as when a second word salted the noise
    return {
        "truth": truth,
        "remnant": 1.0,
        "seed": first * 1000,  # make.py's remnant seeds: first * 1000 + 1, + 2, ...
        "conditions": ("compensatory",),
        "trials": tuple(range(1, trials + 1)),
    }


def _ties(run_dir: Path, rows: list[dict]) -> dict[tuple[int, str, str], int]:
    """Per (run, method, statistic): the FB twins, as its p-value used them, equal to its value."""
    import pyarrow.parquet as pq

    twins = pq.read_table(run_dir / "evidence_twins.parquet").to_pylist()
    fb: dict[tuple, dict[str, list[float]]] = {}
    for t in twins:
        if t["twin"] == "FB":
            by = fb.setdefault((t["group"], t["method"], t["forcing_set"]), {})
            for _, column in STATISTICS.values():
                by.setdefault(column, []).append(t[column])
    out = {}
    for r in rows:
        values = fb.get((r["group"], r["method"], r["forcing_set"]), {})
        for name, (stem, column) in STATISTICS.items():
            x = np.asarray(values.get(column, [])[: r[f"fb_twins_{stem}"] or 0], dtype=float)
            out[(r["run_id"], r["method"], name)] = int(np.count_nonzero(x == r[column]))
    return out


def run_study(index: int, seq: np.random.SeedSequence, options: dict) -> tuple[list[dict], float]:
    """Make and analyse study ``index``: one row per run and method, and the wall seconds."""
    start = time.perf_counter()
    spec = study_spec(seq, *options["runs"])
    make = _load("lab_make", ROOT / "configs" / "lab_example" / "make.py")
    import pyarrow.parquet as pq

    import hcid

    with tempfile.TemporaryDirectory(prefix=f"hcid-null-{index}-") as tmp:
        tmp = Path(tmp)
        make.make(spec, tmp / "data")
        config = tmp / "null_study.yaml"
        text = (ROOT / "configs" / "lab_example.yaml").read_text()
        config.write_text(text.replace("name: lab_example", f"name: null_study_{index}"))
        analysis = hcid.AnalysisOptions(twins=options["twins"], max_fb_twins=options["max_fb_twins"])
        hcid.analyse(
            config, tmp / "data", tmp / "run", analysis, execution=hcid.Execution(jobs=1, progress=False)
        )
        table = pq.read_table(tmp / "run" / "analysis.parquet").to_pylist()
        groups = pq.read_table(tmp / "run" / "analysis_groups.parquet").to_pylist()
        ties = _ties(tmp / "run", table)
    group_of = {g["method"]: g for g in groups}
    rows = []
    for r in table:
        row = {
            "study": index,
            "run_id": r["run_id"],
            "subject": r["subject"],
            "trial": r["trial"],
            "method": r["method"],
            "forcing_set": r["forcing_set"],
            "decided_by": DECIDED_BY.get(r["decided_by"], r["decided_by"]),
            "p_value": r["p_value"],
            "p_method": r["p_method"],
            "ff_twin": group_of.get(r["method"], {}).get("ff_twin", ""),
        }
        for name, (stem, column) in STATISTICS.items():
            row[column] = r[column]
            for c in (f"p_{stem}", f"p_{stem}_method", f"fb_twins_{stem}", f"power_{stem}"):
                row[c] = r[c]
            row[f"ties_{stem}"] = ties[(r["run_id"], r["method"], name)]
        row.update({f"true_{p}": spec["truth"][r["subject"]][p] for p in FEEDBACK})
        row["remnant_seed_first"] = spec["seed"] + 1
        row["twins"], row["max_fb_twins"] = options["twins"], options["max_fb_twins"]
        rows.append(row)
    return rows, time.perf_counter() - start


def _worker(index: int, seq: np.random.SeedSequence, options: dict):
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, "1")
    return index, *run_study(index, seq, options)


def randomized(p: float, how: str, n: int, u: float) -> float:
    """The discrete p spread over its support step (module notes): ``u`` in [0, 1)."""
    if not math.isfinite(p) or how != "monte carlo" or not n:
        return p
    stopped = n >= H and abs(p * n - H) < 1e-9
    low = H / (n + 1) if stopped else p - 1 / (n + 1)
    return p - u * (p - max(low, 0.0))


def ideal_null(structure: list[tuple[int, int]], reps: int, rng: np.random.Generator) -> dict:
    """The KS statistic and the shares at :data:`LEVELS` of the randomized p over ``reps`` ideal
    null replications with this design: per study ``(runs, N)``, its runs' statistics and its N
    FB twins all i.i.d. continuous (an exact null), the twins shared by the study's runs, each p
    sequential (h = 5) up to N as hcid's, then randomized: what the study's shared twins alone
    do to the spread of the KS statistic and of the shares."""
    kinds: dict[tuple[int, int], int] = {}
    for key in structure:
        kinds[key] = kinds.get(key, 0) + 1
    out: dict = {"D": [], **{a: [] for a in LEVELS}}
    chunk = 50
    for first in range(0, reps, chunk):
        c = min(chunk, reps - first)
        us = []
        for (runs, n), count in kinds.items():
            x = rng.random((c, count, runs, 1))
            y = rng.random((c, count, 1, n))
            seen = np.cumsum(y >= x, axis=-1, dtype=np.int16)
            k = seen[..., -1]
            stop = k >= H
            m = np.argmax(seen >= H, axis=-1) + 1
            p = np.where(stop, H / m, (k + 1) / (n + 1))
            low = np.where(stop, H / (m + 1), k / (n + 1))
            us.append((p - rng.random(p.shape) * (p - low)).reshape(c, -1))
        u = np.sort(np.concatenate(us, axis=1), axis=1)
        i = np.arange(1, u.shape[1] + 1) / u.shape[1]
        out["D"].append(np.maximum((i - u).max(axis=1), (u - i + 1 / u.shape[1]).max(axis=1)))
        for a in LEVELS:
            out[a].append((u <= a).mean(axis=1))
    return {key: np.concatenate(v) for key, v in out.items()}


def summarise(rows: list[dict], seed: int, twins: int, max_fb: int, reps: int = 1000) -> list[dict]:
    """Per method and statistic: the runs, the shares at each level with their binomial and
    clustered (:func:`ideal_null`) 99% bands, the KS test of the randomized p (against the
    uniform, and against :func:`ideal_null`'s spread), how the p-values were made and the runs
    tied with some FB twin. Adds the randomized p (``u_<stem>``, ``u_value``) to ``rows``."""
    from scipy import stats

    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(2**31,)))
    for r in sorted(rows, key=lambda r: (r["study"], r["run_id"], r["method"])):
        u = rng.random()  # one draw per run and method: the deciding p_value shares its statistic's
        for stem, _ in STATISTICS.values():
            r[f"u_{stem}"] = randomized(r[f"p_{stem}"], r[f"p_{stem}_method"], r[f"fb_twins_{stem}"], u)
        stem = STATISTICS[r["decided_by"]][0] if r["decided_by"] in STATISTICS else None
        r["u_value"] = r[f"u_{stem}"] if stem else math.nan
        r["fb_twins_value"] = r[f"fb_twins_{stem}"] if stem else 0
        r["ties_value"] = r[f"ties_{stem}"] if stem else 0
    table = []
    for method in ("direct", "indirect"):
        for name in [*STATISTICS, "p_value"]:
            stem = STATISTICS[name][0] if name in STATISTICS else None
            p_col, u_col, how_col, n_col, tie_col = (
                (f"p_{stem}", f"u_{stem}", f"p_{stem}_method", f"fb_twins_{stem}", f"ties_{stem}")
                if stem
                else ("p_value", "u_value", "p_method", "fb_twins_value", "ties_value")
            )
            these = [r for r in rows if r["method"] == method and math.isfinite(r[p_col])]
            p = np.array([r[p_col] for r in these])
            u = np.array([r[u_col] for r in these])
            n = p.size
            out = {"method": method, "statistic": name, "runs": n}
            if not n:
                table.append(out)
                continue
            studies: dict[int, list[dict]] = {}
            for r in these:
                studies.setdefault(r["study"], []).append(r)
            # Each study's N: all drawn (up to max_fb) where this statistic decides, else the calibration's.
            structure = [
                (len(rs), max_fb if stem is None or rs[0]["decided_by"] == name else twins)
                for rs in studies.values()
            ]
            null = ideal_null(structure, reps, rng)
            if stem is None:
                deciding: dict[str, int] = {}
                for r in these:
                    deciding[r["decided_by"]] = deciding.get(r["decided_by"], 0) + 1
                out["decided_by"] = ", ".join(f"{k} {v}" for k, v in sorted(deciding.items()))
            spec_ok = clustered_ok = True
            for a in LEVELS:
                share = float(np.mean(p <= a))
                lo, hi = stats.binom.ppf([0.005, 0.995], n, a) / n
                c_lo, c_hi = np.quantile(null[a], [0.005, 0.995])
                tag = f"{a:g}".replace("0.", "")
                out.update(
                    {
                        f"p_le_{tag}": share,
                        f"band_{tag}_low": float(lo),
                        f"band_{tag}_high": float(hi),
                        f"clustered_{tag}_low": float(c_lo),
                        f"clustered_{tag}_high": float(c_hi),
                        f"randomized_le_{tag}": float(np.mean(u <= a)),
                    }
                )
                spec_ok = spec_ok and lo - 1e-12 <= share <= hi + 1e-12
                clustered_ok = clustered_ok and c_lo - 1e-12 <= share <= c_hi + 1e-12
            ks = stats.kstest(u, "uniform")
            out["ks_d"] = float(ks.statistic)
            out["ks_p"] = float(ks.pvalue)
            out["ks_p_clustered"] = float((1 + np.count_nonzero(null["D"] >= ks.statistic)) / (1 + reps))
            made = {"sequential": 0, "count": 0, "gpd tail": 0}
            for r in these:
                x, m = r[p_col], r[n_col]
                if r[how_col] != "monte carlo":
                    made["gpd tail"] += 1
                elif m >= H and abs(x * m - H) < 1e-9:
                    made["sequential"] += 1
                else:
                    made["count"] += 1
            out["made_by"] = ", ".join(f"{k} {v}" for k, v in made.items() if v)
            out["fb_twins_median"] = float(np.median([r[n_col] for r in these]))
            out["tied_runs"] = sum(r[tie_col] > 0 for r in these)
            out["uniform_spec13"] = "yes" if spec_ok and out["ks_p"] > 0.01 else "NO"
            out["uniform_clustered"] = "yes" if clustered_ok and out["ks_p_clustered"] > 0.01 else "NO"
            table.append(out)
    return table


def print_table(table: list[dict]) -> None:
    print(
        "| method | statistic | runs | P(p <= 0.01) [binomial 99% band] {clustered} | P(p <= 0.05) "
        "[binomial 99% band] {clustered} | KS p | KS p clustered | p made by | FB twins (median) | "
        "tied runs | uniform: SPEC 13 | clustered |"
    )
    print("|---" * 12 + "|")
    for t in table:
        if not t["runs"]:
            print(f"| {t['method']} | {t['statistic']} | 0 |" + " |" * 9)
            continue
        cells = []
        for tag in ("01", "05"):
            cells.append(
                f"{t[f'p_le_{tag}']:.3f} [{t[f'band_{tag}_low']:.3f}, {t[f'band_{tag}_high']:.3f}] "
                f"{{{t[f'clustered_{tag}_low']:.3f}, {t[f'clustered_{tag}_high']:.3f}}}"
            )
        stat = t["statistic"] + (f" ({t['decided_by']})" if t.get("decided_by") else "")
        print(
            f"| {t['method']} | {stat} | {t['runs']} | {cells[0]} | {cells[1]} | {t['ks_p']:.3g} | "
            f"{t['ks_p_clustered']:.3g} | {t['made_by']} | {t['fb_twins_median']:g} | {t['tied_runs']} | "
            f"{t['uniform_spec13']} | {t['uniform_clustered']} |"
        )


def _read(path: Path) -> list[dict]:
    """The per-run CSV written by an earlier run, its numbers as numbers."""

    def value(x: str):
        for kind in (int, float):
            try:
                return kind(x)
            except ValueError:
                pass
        return x

    with path.open(newline="") as f:
        return [{k: value(v) for k, v in r.items()} for r in csv.DictReader(f)]


def _write(path: Path, rows: list[dict]) -> None:
    keys = list(dict.fromkeys(k for r in rows for k in r))
    with path.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)


def _machine() -> tuple[str, str]:
    cpu = subprocess.run(["lscpu"], capture_output=True, text=True).stdout
    model = next((x.split(":", 1)[1].strip() for x in cpu.splitlines() if x.startswith("Model name")), "?")
    load = subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()
    return model, load


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--studies", type=int, default=50)
    parser.add_argument("--runs-per-study", type=_runs_per_study, default=(5, 4), metavar="SxT",
                        help="subjects x trials per study (default 5x4)")  # fmt: skip
    parser.add_argument("--seed", type=int, default=2026, help="root seed (SeedSequence)")
    parser.add_argument("--jobs", type=int, default=2, help="studies analysed side by side")
    parser.add_argument("--twins", type=int, default=20, help="hcid analyse --twins (default 20)")
    parser.add_argument("--max-fb-twins", type=int, default=99, help="hcid analyse --max-fb-twins (99)")
    parser.add_argument("--out", type=Path, help="per-run CSV (default: TMPDIR/null_study[_smoke].csv)")
    parser.add_argument("--smoke", action="store_true", help="1 study of 4 runs, --twins 4 --max-fb-twins 8")
    parser.add_argument("--from-csv", type=Path, metavar="CSV",
                        help="no studies: the table again from an earlier run's per-run CSV")  # fmt: skip
    args = parser.parse_args(argv)
    if args.smoke:
        args.studies, args.runs_per_study, args.twins, args.max_fb_twins = 1, (2, 2), 4, 8
    if args.out is None:
        args.out = Path(tempfile.gettempdir()) / f"null_study{'_smoke' if args.smoke else ''}.csv"
    if args.from_csv:
        rows = _read(args.from_csv)
        twins, max_fb = rows[0].get("twins", args.twins), rows[0].get("max_fb_twins", args.max_fb_twins)
        studies = len({r["study"] for r in rows})
        runs = len({(r["study"], r["run_id"]) for r in rows})
        print(f"{args.from_csv}: {studies} studies, {runs} runs (x 2 methods), --twins {twins} "
              f"--max-fb-twins {max_fb}")  # fmt: skip
        table = summarise(rows, args.seed, twins, max_fb)
        print_table(table)
        summary = args.from_csv.with_name(args.from_csv.stem + "_summary.csv")
        _write(summary, table)
        print(f"\ntable: {summary}")
        return
    options = {
        "runs": args.runs_per_study,
        "twins": args.twins,
        "max_fb_twins": args.max_fb_twins,
    }
    cpu, load = _machine()
    subjects, trials = args.runs_per_study
    print(
        f"{args.studies} studies x {subjects} subjects x {trials} trials (feedback only), seed {args.seed}, "
        f"--twins {args.twins} --max-fb-twins {args.max_fb_twins}, --jobs {args.jobs}\nCPU {cpu}, "
        f"{os.cpu_count()} cores; before: {load}",
        flush=True,
    )
    seqs = np.random.SeedSequence(args.seed).spawn(args.studies)
    start = time.perf_counter()
    rows: list[dict] = []
    done = 0

    def finished(index: int, got: list[dict], wall: float) -> None:
        nonlocal done
        done += 1
        rows.extend(got)
        _write(args.out, rows)  # kept as the studies finish
        elapsed = time.perf_counter() - start
        eta = elapsed / done * (args.studies - done)
        print(f"study {index}: {len(got)} rows in {wall:.0f} s; {done}/{args.studies} done, "
              f"{elapsed / 60:.1f} min, about {eta / 60:.0f} min left", flush=True)  # fmt: skip

    if args.jobs == 1 or args.studies == 1:
        for i, seq in enumerate(seqs):
            finished(*_worker(i, seq, options))
    else:
        with ProcessPoolExecutor(min(args.jobs, args.studies), mp_context=get_context("spawn")) as pool:
            futures = [pool.submit(_worker, i, seq, options) for i, seq in enumerate(seqs)]
            for future in as_completed(futures):
                finished(*future.result())
    wall = time.perf_counter() - start
    rows.sort(key=lambda r: (r["study"], r["run_id"], r["method"]))
    table = summarise(rows, args.seed, args.twins, args.max_fb_twins)
    _write(args.out, rows)
    summary = args.out.with_name(args.out.stem + "_summary.csv")
    _write(summary, table)
    runs = len({(r["study"], r["run_id"]) for r in rows})
    print(f"\n{args.studies} studies, {runs} runs (x 2 methods) in {wall / 60:.1f} min wall "
          f"({wall / max(runs, 1):.1f} s per run); after: {_machine()[1]}")  # fmt: skip
    print_table(table)
    print(f"\nper run: {args.out}\ntable: {summary}")
    sys.stdout.flush()


if __name__ == "__main__":
    main()
