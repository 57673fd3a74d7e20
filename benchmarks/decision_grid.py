"""Would a smaller grid decide as the analysis grid does? W* on order-capped frontiers (issue 34).

    .venv/bin/python benchmarks/decision_grid.py RUN_DIR [--caps 3,7,7 4,4,4 5,5,5]

RUN_DIR is a finished ``hcid analyse`` run directory. Each frontier (the best candidate of every
order triple) is restricted to the triples with ``na <= a``, ``nb_ft <= b`` and ``nb_e <= c``
(a cap ``a,b,c``): exactly the frontier a grid with those upper orders would give, up to the
rounding of a smaller least-squares factor. Per group and method, printed: the share of FB and FF
twins and of runs whose W* (SPEC 11) is unchanged, the runs at p <= 0.05 against the group's FB
twins (every one drawn, pooled over the group's folders: groups of one forcing set only), and the
largest change of a run's p-value. For the indirect method only stage 2 is capped (its stage 1,
the smallest V over its own grid, as run). Then the wall time of one direct identification on the
group's twin records under each cap, and of the indirect method's stage 1, in this process.

A capped grid is a different statistic: SPEC 10 and 11 identify twins and runs exactly alike on
the analysis grid, so a smaller grid is a config's choice (``identify:``) for runs and twins
together, never a shortcut for the twins alone. This script measures what that choice would
change; docs/benchmarks.md "2026-11-27, last" has its figures.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import os
import time
from pathlib import Path

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import numpy as np  # noqa: E402
import pyarrow.parquet as pq  # noqa: E402
import yaml  # noqa: E402

from hcid import tables  # noqa: E402
from hcid.arx import fit_grid  # noqa: E402
from hcid.assembly.resolve import parse_config  # noqa: E402
from hcid.io import results  # noqa: E402
from hcid.methods import shift_forward  # noqa: E402
from hcid.pipeline.twins import group_slug  # noqa: E402
from hcid.selection.calibration import evidence_p_value, feedforward_threshold  # noqa: E402
from hcid.selection.over_w import breakpoints  # noqa: E402

ORDERS = ("na", "nb_ft", "nb_e", "nk_ft", "nk_e")
FULL = (99, 99, 99)


def w_stars(path: Path, method: str, caps, w_range) -> dict[tuple[str, int], list[float]]:
    """Each realization's W* in a frontier file, under every cap (FULL first)."""
    table = pq.read_table(path, filters=[("method", "=", method)])
    col = {c: table.column(c).to_numpy() for c in ("model", "seed", "d", "v", *ORDERS)}
    out = {}
    for key in sorted(set(zip(col["model"], col["seed"], strict=True))):
        own = (col["model"] == key[0]) & (col["seed"] == key[1])
        values = []
        for a, b, c in caps:
            rows = np.flatnonzero(own & (col["na"] <= a) & (col["nb_ft"] <= b) & (col["nb_e"] <= c))
            orders = np.stack([col[o][rows] for o in ORDERS], axis=1)
            path_w = breakpoints(col["d"][rows].astype(np.float64), col["v"][rows], orders)
            values.append(feedforward_threshold(path_w, col["nb_ft"][rows], *w_range))
        out[(str(key[0]), int(key[1]))] = values
    return out


def group_runs(run_dir: Path) -> dict[str, dict]:
    """Per group of analysis.csv: its factor key, its runs' (model, seed) and its forcing sets."""
    runs = pq.read_table(run_dir / "runs.parquet").to_pydict()
    seed_of = {f: (m, s) for f, m, s in zip(runs["file"], runs["model"], runs["seed"], strict=True)}
    factors = [c for c in runs if c not in ("model", "seed", "file", "file_run")]
    groups: dict[str, dict] = {}
    with open(run_dir / "analysis.csv", newline="") as handle:
        for row in csv.DictReader(handle):
            g = groups.setdefault(row["group"], {"runs": set(), "sets": set()})
            # The grouping factors, in the group's own order, and this run's values of them.
            by = [f for f in factors if row["group"].startswith(f"{f}=") or f", {f}=" in row["group"]]
            by.sort(key=lambda f: row["group"].find(f"{f}="))
            g["key"] = tuple(row[f] for f in by)
            g["runs"].add(seed_of[row["file"]])
            g["sets"].add(row["forcing_set"])
    return groups


def agreement(run_dir: Path, caps, w_range) -> None:
    for group, g in group_runs(run_dir).items():
        if len(g["sets"]) > 1:
            print(f"{group}: {len(g['sets'])} forcing sets, skipped (this script pools a group's twins)")
            continue
        slug = group_slug(g["key"])
        folders = [f for f in sorted((run_dir / "twins").glob(slug + "*")) if not f.name.endswith("-study")]
        for method in ("direct", "indirect"):
            runs = {
                k: v
                for k, v in w_stars(run_dir / "frontier.parquet", method, caps, w_range).items()
                if k in g["runs"]
            }
            twins = {"FB": [], "FF": []}
            for folder in folders:
                for (model, _), v in w_stars(folder / "frontier.parquet", method, caps, w_range).items():
                    twins[model].append(v)
            fb, ff = np.array(twins["FB"]), np.array(twins["FF"])
            rv = np.array(list(runs.values()))
            if not (fb.size and ff.size and rv.size):
                print(f"{group}, {method}: no FB twins, FF twins or runs in {run_dir}, skipped")
                continue
            print(f"{group}, {method}: {len(rv)} runs, {len(fb)} FB and {len(ff)} FF twins")
            p_full = np.array([evidence_p_value(w, fb[:, 0]) for w in rv[:, 0]])
            for j, cap in enumerate(caps[1:], start=1):
                p = np.array([evidence_p_value(w, fb[:, j]) for w in rv[:, j]])
                print(
                    f"  cap {cap}: W* unchanged for FB {np.mean(fb[:, j] == fb[:, 0]):.2f}, "
                    f"FF {np.mean(ff[:, j] == ff[:, 0]):.2f}, runs {np.mean(rv[:, j] == rv[:, 0]):.2f}; "
                    f"runs at p <= 0.05: {np.sum(p_full <= 0.05)} -> {np.sum(p <= 0.05)}; "
                    f"largest |change of p| {np.max(np.abs(p - p_full)):.3f}"
                )


def timing(run_dir: Path, caps, config, repeat: int = 10) -> None:
    folder = next(f for f in sorted((run_dir / "twins").glob("*-fb*")))
    sims = results.records(results.read(tables.SIMULATIONS, folder), folder / tables.SIMULATIONS.file)
    records = [r for _, r in sorted(sims.items())][:repeat]
    shift = config.identify.shift_samples(config.timing.output_rate)
    direct, stage1 = config.identify.stage("direct"), config.identify.stage("stage1")

    def per_fit(stage, grid, inputs) -> float:
        fit_grid(*inputs(records[0]), grid, stage.estimation.rows(), stage.validation.rows())  # compiled
        start = time.perf_counter()
        for r in records:
            fit_grid(*inputs(r), grid, stage.estimation.rows(), stage.validation.rows())
        return (time.perf_counter() - start) / len(records) * 1e3

    def direct_inputs(r):
        return shift_forward(r["ft"], shift), r["e"], r["u"]

    def stage1_inputs(r):
        return shift_forward(r["ft"], shift), r["fd"], r["e"]

    print(f"one identification on {len(records)} FB twin records of {folder.name}, ms each:")
    for a, b, c in caps:
        g = direct.grid  # the configured lower orders kept, the upper ones capped
        grid = dataclasses.replace(
            g,
            na=(g.na[0], min(a, g.na[1])),
            nb1=(g.nb1[0], min(b, g.nb1[1])),
            nb2=(g.nb2[0], min(c, g.nb2[1])),
        )
        print(f"  direct, cap {(a, b, c)}: {per_fit(direct, grid, direct_inputs):.1f}")
    print(f"  indirect stage 1 (its own grid): {per_fit(stage1, stage1.grid, stage1_inputs):.1f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("run_dir", type=Path)
    parser.add_argument("--caps", nargs="+", default=["3,7,7", "4,4,4", "5,5,5"])
    args = parser.parse_args()
    caps = [FULL] + [tuple(int(x) for x in c.split(",")) for c in args.caps]
    raw = yaml.safe_load((args.run_dir / "config.yaml").read_text())
    config = parse_config(raw, raw["name"])
    w_grid = config.selection.w_grid
    agreement(args.run_dir, caps, (float(min(w_grid)), float(max(w_grid))))
    timing(args.run_dir, caps, config)


if __name__ == "__main__":
    main()
