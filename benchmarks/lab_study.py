"""`hcid analyse` on synthetic lab studies: wall time per stage, and what it found against the truth.

    .venv/bin/python benchmarks/lab_study.py                  # the two shipped examples (24 runs each)
    .venv/bin/python benchmarks/lab_study.py --study large    # 20 subjects x 4 conditions x 5 trials

The studies are made by configs/lab_example/make.py (hcid's simulator, not people), so every run's
truth is known: ``example`` and ``weak`` are the shipped configs/lab_example and configs/lab_weak;
``large`` (400 runs, not shipped) is generated into a temporary folder with subjects' parameters
drawn from the example's ranges, feedforward in the two ``pursuit`` conditions and none in the two
``compensatory`` ones. Each study is analysed in a fresh run directory (``--jobs``, default 2) with
the numba cache as it is (run `make bench`'s cold-start benchmark for a cold one).

Printed per study: the wall time of each stage (identify, fit runs, twins, fit selected, tables);
per condition and method the W, its rule and the twins' stated FP / FN rates against the errors
made on the runs; the 95% intervals (estimate +- 1.96 se) that hold the true parameter; the
model-free (Fourier-coefficient) estimates of each run against its true paths at the forcing
lines below 10 rad/s.
"""

from __future__ import annotations

import argparse
import functools
import importlib.util
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
from _tables import calibration_table, evidence_table

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("lab_make", ROOT / "configs" / "lab_example" / "make.py")
make = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(make)

#: The true neuromuscular system of every subject (configs/integrator_example.yaml's loop).
NMS = {"w_nms": 10.1, "zeta_nms": 0.35}
#: The large study's ranges of the subjects' parameters (those of the example's subjects).
RANGES = {"Kpe": (1.7, 2.4), "TL": (0.10, 0.20), "tau_pe": (0.22, 0.30), "Kpt": (0.6, 1.0),
          "TI": (0.15, 0.25), "tau_pt": (0.15, 0.30)}  # fmt: skip
PARAMETERS = ("Kpe", "TL", "tau_pe", "w_nms", "zeta_nms", "Kpt", "TI", "tau_pt")


def _margins_ok(p: dict) -> bool:
    """Whether the subject's loop with the example's plant is one a person tracks with: one
    gain crossover, phase margin at least 30 deg (the ranges also hold loops that the
    neuromuscular peak makes unstable near 10 rad/s)."""
    from hcid.analysis.descriptors import loop_margins
    from hcid.hcfit import hc_response

    yc = _example_plant()
    m = loop_margins(lambda w: hc_response({**p, **NMS}, yc, w)[1] * np.asarray(yc(1j * w)).ravel())
    return m.n_crossovers == 1 and m.phase_margin >= 30.0


def _gain_margin(p: dict) -> float:
    """The loop's gain margin with the example's plant and neuromuscular system: 1 / |L| at the
    first frequency where its phase (continuous from 0.1 rad/s) reaches -180 deg (inf where it
    does not below 100 rad/s). The neuromuscular peak near 10 rad/s sets it."""
    from hcid.hcfit import hc_response

    yc = _example_plant()
    w = np.logspace(-1, 2, 3000)
    loop = hc_response({**p, **NMS}, yc, w)[1] * np.asarray(yc(1j * w)).ravel()
    phase = np.unwrap(np.angle(loop))
    below = np.flatnonzero((phase[:-1] > -np.pi) & (phase[1:] <= -np.pi))
    return float(1.0 / abs(loop[below[0]])) if below.size else float("inf")


@functools.cache
def _example_plant():
    """The lab example's plant (1.5/s), as python-control's system (read once)."""
    from hcid.assembly.resolve import load_config
    from hcid.loop.hcmodel import plant

    return plant(load_config(ROOT / "configs" / "lab_example.yaml").loop)


def large_spec(subjects: int = 20, trials: int = 5, seed: int = 7) -> dict:
    """``subjects`` drawn from the example's ranges (drawn again until their loop has a phase
    margin of 30 deg or more: :func:`_margins_ok`), 4 conditions, ``trials`` each."""
    rng = np.random.default_rng(seed)
    truth = {}
    while len(truth) < subjects:
        p = {p: round(float(rng.uniform(lo, hi)), 3) for p, (lo, hi) in RANGES.items()}
        if _margins_ok(p):
            truth[f"P{len(truth) + 1:02d}"] = p
    conditions = ("pursuit", "pursuit2", "compensatory", "compensatory2")
    return {"truth": truth, "remnant": 1.0, "seed": 9000, "conditions": conditions,
            "trials": tuple(range(1, trials + 1))}  # fmt: skip


def _truth(spec: dict, subject: str, condition: str) -> dict:
    p = {**spec["truth"][subject], **NMS}
    if not condition.startswith("pursuit"):
        p.update(Kpt=0.0, TI=0.0, tau_pt=0.0)
    return p


def _config_text(name: str) -> str:
    text = (ROOT / "configs" / "lab_example.yaml").read_text()
    return text.replace("name: lab_example", f"name: {name}")


def analyse(config: Path, data: Path, run: Path, jobs: int) -> tuple[float, str]:
    """``hcid analyse`` in a subprocess: its wall time and its output."""
    import subprocess

    start = time.perf_counter()
    out = subprocess.run(
        [str(ROOT / ".venv" / "bin" / "hcid"), "analyse", str(config), "--data", str(data), "--run", str(run),
         "--jobs", str(jobs), "--quiet"],
        capture_output=True, text=True, check=True,
    )  # fmt: skip
    return time.perf_counter() - start, out.stdout


def findings(spec: dict, run: Path, config: Path) -> dict[str, str]:
    """What the analysis found against the truth, as the docs quote it (benchmarks/docs_figures.py
    checks them): the calibration's and the runs' own evidence's tables, the 95% intervals that
    hold the truth, and the model-free estimates' errors."""
    from hcid.analysis.fourier import fc_estimate
    from hcid.assembly.resolve import load_config
    from hcid.hcfit import hc_response
    from hcid.loop.hcmodel import plant
    from hcid.pipeline.fit_hc import _records

    rows = pq.read_table(run / "analysis.parquet").to_pylist()

    def truth(r: dict) -> bool:
        return r["condition"].startswith("pursuit")

    out = {"calibration": calibration_table(run, truth), "evidence": evidence_table(run, truth)}
    hits = {True: [0, 0], False: [0, 0]}
    for r in rows:
        hits[truth(r)][0] += r["p_value"] <= 0.05
        hits[truth(r)][1] += 1
    out["runs"] = (
        f"runs without feedforward at p <= 0.05: {hits[False][0]} of {hits[False][1]} "
        f"({100 * hits[False][0] / max(hits[False][1], 1):.1f}%); runs with feedforward found: "
        f"{hits[True][0]} of {hits[True][1]}"
    )
    held, total, per = 0, 0, {}
    for r in rows:
        if r["method"] != "direct":
            continue
        true = _truth(spec, r["subject"], r["condition"])
        for p in PARAMETERS:
            x, se = r[p], r[f"{p}_se"]
            if not np.isfinite(x) or true[p] == 0.0 or not np.isfinite(se):
                continue
            ok = abs(x - true[p]) <= 1.96 * se
            held, total = held + ok, total + 1
            per.setdefault(p, [0, 0])
            per[p][0] += ok
            per[p][1] += 1
    each = ", ".join(f"{p} {a}/{b}" for p, (a, b) in per.items())
    out["intervals"] = (f"95% intervals holding the true value (direct method, at the group's W): {held} of "
                        f"{total} ({100 * held / max(total, 1):.0f}%); {each}")  # fmt: skip
    # Model-free estimates per run against the run's true paths.
    cfg = load_config(config)
    yc = plant(cfg.loop)
    n = round(cfg.timing.window * cfg.timing.output_rate)
    records = _records(run)
    factors = {r["run_id"]: r for r in rows if r["method"] == "direct"}
    err = {"e": ([], []), "ft": ([], [])}
    for (_, seed), record in sorted(records.items()):
        f = factors[seed]
        fc = fc_estimate([record], cfg.timing.output_rate, slice(0, n))
        true = _truth(spec, f["subject"], f["condition"])
        for path, omega, h in (("e", fc.omega_e, fc.he), ("ft", fc.omega_t, fc.ht)):
            if path == "ft" and true["Kpt"] == 0.0:
                continue
            low = omega < 10
            hft, he = hc_response(true, yc, omega[low])
            ref = he if path == "e" else hft
            ratio = h[low] / ref
            err[path][0].extend(np.abs(20 * np.log10(np.abs(ratio))))
            err[path][1].extend(np.abs(np.degrees(np.angle(ratio))))
    out["model-free"] = "; ".join(
        f"model-free {'He' if path == 'e' else 'Ht'} per run, lines below 10 rad/s: mean |error| "
        f"{np.mean(db):.2f} dB, {np.mean(deg):.1f} deg ({len(db)} run-lines)"
        for path, (db, deg) in err.items()
        if db
    )
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--study", choices=("example", "weak", "large"), action="append")
    parser.add_argument("--jobs", type=int, default=2)
    args = parser.parse_args()
    studies = args.study or ["example", "weak"]
    info = Path("/proc/cpuinfo").read_text().splitlines()
    cpu = next((line.split(":", 1)[1].strip() for line in info if "model name" in line), "?")
    print(f"CPU {cpu}, {os.cpu_count()} cores; --jobs {args.jobs}")
    for study in studies:
        with tempfile.TemporaryDirectory(prefix=f"hcid-lab-{study}-") as tmp:
            tmp = Path(tmp)
            if study == "large":
                spec = large_spec()
                data = tmp / "data"
                start = time.perf_counter()
                make.make(spec, data)
                made = time.perf_counter() - start
                print(f"\n## large: {len(list(data.glob('*.csv')))} files made in {made:.1f} s")
                config = tmp / "lab_large.yaml"
                config.write_text(_config_text("lab_large"))
            else:
                name = "lab_example" if study == "example" else "lab_weak"
                spec, data, config = (
                    make.STUDIES[name],
                    ROOT / "configs" / name,
                    ROOT / "configs" / f"{name}.yaml",
                )
                print(f"\n## {study}: {config.relative_to(ROOT)}, {len(list(data.glob('*.csv')))} files")
            load = os.getloadavg()[0]
            wall, out = analyse(config, data, tmp / "run", args.jobs)
            line = next(x for x in out.splitlines() if x.startswith("analysed in"))
            after = os.getloadavg()[0]
            print(f"wall {wall:.1f} s (load {load:.2f} before, {after:.2f} after); {line.split(';')[0]}")
            print("\n\n".join(findings(spec, tmp / "run", config).values()))
    sys.stdout.flush()


if __name__ == "__main__":
    main()
