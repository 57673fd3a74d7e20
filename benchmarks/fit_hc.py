"""Benchmark of one ``hcid fit-hc`` task (``make bench``): wall time per record and method.

Default fit settings, one core, two simulated studies: the paper config, whose
target is not a sum of sines over whole periods of the window (no forcing
lines), and the integrator example, whose target and disturbance are
multisines over whole periods (forcing lines on disjoint bins). For 3 seeds of
each model (FB, FF) and each method, the record is identified on the config's
grids (not timed) and the model selected at W_BIC. Then, for each estimator
(:data:`hcid.hcfit.TARGETS`), side by side on the same selected models: the
parametric fit alone (:func:`hcid.hcfit.selected.fit_selected`) and the
whole task, fit plus loop descriptors plus residual analysis
(:func:`hcid.hcfit.selected.analyse_selected`, what one fit-hc task does per
W). An estimator is timed only on the records it applies to (``lines``: those
with forcing lines); the records it skips are counted, with hcid's reason.
Prints the median wall times per estimator, and per model and method for the
config's own estimator.

``--smoke``: one record (the first model, seed 1) and the first method, the
CI config (the paper study on small grids) in place of the paper config;
every path of this script in a few seconds, no figure worth keeping.

Run: ``.venv/bin/python benchmarks/fit_hc.py [--smoke]``.
"""

import os

# One core for BLAS too, before numpy is imported.
for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_name] = "1"

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402
from collections import Counter  # noqa: E402

import numpy as np  # noqa: E402
from _paper_record import PAPER_CONFIG, ROOT  # noqa: E402

import hcid  # noqa: E402
from hcid import methods  # noqa: E402
from hcid.assembly.resolve import load_config  # noqa: E402
from hcid.errors import DataError  # noqa: E402
from hcid.hcfit import TARGETS, TrackingRecord, resolve_target  # noqa: E402
from hcid.hcfit.lines import line_data  # noqa: E402
from hcid.hcfit.selected import analyse_selected, fit_selected  # noqa: E402
from hcid.loop.hcmodel import plant  # noqa: E402
from hcid.loop.simulate import remnant_gain, simulate_realization  # noqa: E402
from hcid.selection.criteria import w_bic  # noqa: E402

INTEGRATOR_CONFIG = ROOT / "configs" / "integrator_example.yaml"
CONFIGS = (PAPER_CONFIG, INTEGRATOR_CONFIG)
SEEDS = (1, 2, 3)
SMOKE_CONFIGS = (ROOT / "configs" / "ci.yaml", INTEGRATOR_CONFIG)
SMOKE_SEEDS = (1,)
#: The estimators that need more of a record than ft, fd, e and u, each with the hcid function
#: that reads it (and raises DataError with the reason where the record lacks it): ``lines``
#: needs the record's forcing lines.
NEEDS = {"lines": line_data}


@dataclasses.dataclass(frozen=True)
class Case:
    """One selected model and what its fit-hc task needs."""

    model: str
    method_name: str
    method: methods.Method
    selected: hcid.SelectedModel
    record: dict[str, np.ndarray]
    choices: tuple
    tracking: TrackingRecord


def _cases(config, seeds, first) -> list[Case]:
    """Every model, seed and method (or the first model and method), identified and selected at W_BIC."""
    kn = remnant_gain(config)
    rate = config.timing.output_rate
    cases = []
    for model in config.models[:1] if first else config.models:
        for seed in seeds:
            r = simulate_realization(config, model, seed, kn)
            record = {"ft": r.ft, "fd": r.fd, "e": r.e, "u": r.u}
            t = np.arange(r.u.size) / rate
            for name, method in list(methods.METHODS.items())[:1] if first else methods.METHODS.items():
                result = hcid.identify(hcid.Record(seed, rate, t, **record), name, config.identify)
                selected = result.select(w_bic(method.nf(config.identify)))
                tracking = TrackingRecord(
                    r.ft, r.e, r.u, rate, selected.estimation.rows(), selected.validation.rows(), fd=r.fd
                )
                cases.append(Case(model.name, name, method, selected, record, result.choices, tracking))
    return cases


def _reason_to_skip(target: str, case: Case) -> str | None:
    """Why ``target`` does not apply to the case's record (hcid's message), or None."""
    if target not in NEEDS:
        return None
    try:
        NEEDS[target](case.tracking)
    except DataError as exc:
        return str(exc)
    return None


def _bench_config(path, seeds, first) -> None:
    config = load_config(path)
    yc = plant(config.loop)
    cases = _cases(config, seeds, first)
    label = f"{config.name} ({path.relative_to(ROOT)})"
    print(f"{label}: fit-hc task per record and method, one core, W = W_BIC, selected models: {len(cases)}")
    print(f"{'estimator':<12}{'models':>8}{'fit median s':>13}{'fit max s':>10}{'task median s':>14}   note")
    per_case = {}
    for target in TARGETS:
        settings = dataclasses.replace(config.fit_hc, target=target)
        cfg = dataclasses.replace(config, fit_hc=settings)
        skipped = Counter()
        fits, tasks = [], []
        resolved = Counter()
        for case in cases:
            reason = _reason_to_skip(target, case)
            if reason is not None:
                skipped[reason] += 1
                continue
            resolved[resolve_target(target, case.tracking)] += 1
            start = time.perf_counter()
            fit_selected(case.selected, case.record, yc, settings, config.loop.disturbance_at)
            fits.append(time.perf_counter() - start)
            start = time.perf_counter()
            analyse_selected(case.selected, case.record, cfg, case.method, case.choices)
            tasks.append(time.perf_counter() - start)
            if target == config.fit_hc.target:
                per_case.setdefault((case.model, case.method_name), []).append(
                    (tasks[-1], case.selected.orders)
                )
        note = (
            ""
            if set(resolved) == {target}
            else "ran as " + ", ".join(f"{t} on {n}" for t, n in resolved.items())
        )
        if fits:
            print(
                f"{target:<12}{len(fits):>8}{statistics.median(fits):>13.3f}{max(fits):>10.3f}"
                f"{statistics.median(tasks):>14.3f}   {note}".rstrip()
            )
        for reason, count in skipped.items():
            print(f"{target:<12}skipped on {count} of {len(cases)} models, their records: {reason}")
    print(f"\nthe config's estimator ({config.fit_hc.target}), whole task per model and method:")
    print(f"{'model':<6}{'method':<10}{'median s':>10}{'max s':>8}   selected (na, nb_ft, nb_e, nk_ft, nk_e)")
    for (model, name), found in per_case.items():
        seconds = [s for s, _ in found]
        print(
            f"{model:<6}{name:<10}{statistics.median(seconds):>10.2f}{max(seconds):>8.2f}   "
            + ", ".join(str(o) for _, o in found)
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--smoke", action="store_true", help="one record, one method, small grids: seconds")
    args = parser.parse_args()
    configs, seeds = (SMOKE_CONFIGS, SMOKE_SEEDS) if args.smoke else (CONFIGS, SEEDS)
    if args.smoke:
        print("smoke run: every path of the benchmark, figures not worth keeping")
    for i, path in enumerate(configs):
        if i:
            print()
        _bench_config(path, seeds, first=args.smoke)


if __name__ == "__main__":
    main()
