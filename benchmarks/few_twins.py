"""What fewer FB twins would have decided, run by run, on analyses already made (issue 47).

For every run and method of each ``hcid analyse`` run directory given: its deciding statistic
(``analysis.parquet``) against its forcing set's FB twins in the order drawn
(``evidence_twins.parquet``). The p-value over all of them is recomputed by hcid's rule
(``run_p_value``: the count, Besag and Clifford's stop, the tail beyond every twin) and checked
against the stored one; then over the first ``N`` of them (``--twins``), by hcid's rule and by
SPEC 13's tail wherever fewer than 10 twins reach the run (``tail_p_value``: the generalized
Pareto tail where it fits, else the count). Printed per run directory and rule: the runs at
``p <= alpha`` and the decisions equal to all the twins' (at 0.05 and 0.01), then every run whose
decision at 0.05 changes. Twins drawn for a run's set stop where every run of the set is settled,
so a set's first N twins are those N twins drawn (not a new draw).

usage: python benchmarks/few_twins.py RUN_DIR [RUN_DIR ...] [--twins 19,39,59]
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from hcid.pipeline.line_statistics import LINE_STATISTICS  # noqa: E402
from hcid.selection.calibration import run_p_value  # noqa: E402
from hcid.selection.tail import tail_p_value  # noqa: E402

#: Each statistic's column in analysis.parquet and evidence_twins.parquet.
COLUMNS = {"W*": "w_star", **{name: column for name, (column, _) in LINE_STATISTICS.items()}}


def spec_tail_p(value: float, fb: np.ndarray) -> float:
    """SPEC 13's p: the generalized Pareto tail wherever fewer than 10 of the twins reach the
    run (on the log scale where every value is positive, as hcid's rule), else the count."""
    log = value > 0 and bool(np.all(fb > 0))
    return tail_p_value(math.log(value) if log else value, np.log(fb) if log else fb).p


def runs_of(run_dir: Path, ns: tuple[int, ...]) -> list[dict]:
    """Per run and method of one analysis: the stored p, hcid's p over all its FB twins, and over
    the first ``n`` of them by hcid's rule (``p{n}``) and by SPEC 13's tail (``p{n}_tail``)."""
    analysis = pq.read_table(run_dir / "analysis.parquet").to_pylist()
    twins = pq.read_table(run_dir / "evidence_twins.parquet").to_pylist()
    fb_of: dict[tuple, list] = {}
    for t in sorted(twins, key=lambda t: t["seed"]):
        if t["twin"] == "FB":
            fb_of.setdefault((t["group"], t["method"], t["forcing_set"]), []).append(t)
    out = []
    for r in analysis:
        column = COLUMNS.get(r["decided_by"])
        value = r.get(column) if column else None
        if value is None or not math.isfinite(value):
            continue
        fb = np.array([t[column] for t in fb_of[(r["group"], r["method"], r["forcing_set"])]], float)
        fb = fb[np.isfinite(fb)]  # twins drawn for another statistic have none of this one
        row = {"study": run_dir.name, "run": r["run_id"], "group": r["group"], "method": r["method"],
               "statistic": r["decided_by"], "twins": fb.size, "p_stored": r["p_value"],
               "p_all": run_p_value(value, fb)[0]}  # fmt: skip
        for n in ns:
            first = fb[:n]
            row[f"p{n}"] = run_p_value(value, first)[0]
            row[f"p{n}_tail"] = spec_tail_p(value, first)
        out.append(row)
    return out


def summary(rows: list[dict], ns: tuple[int, ...]) -> list[str]:
    """Per study and rule: runs at p <= alpha and decisions equal to all the twins', at 0.05 and 0.01."""
    lines = []
    rules = [f"p{n}{kind}" for n in ns for kind in ("", "_tail")]
    for study in dict.fromkeys(r["study"] for r in rows):
        mine = [r for r in rows if r["study"] == study]
        for alpha in (0.05, 0.01):
            found = sum(r["p_all"] <= alpha for r in mine)
            cells = []
            for rule in rules:
                hits = sum(r[rule] <= alpha for r in mine)
                same = sum((r[rule] <= alpha) == (r["p_all"] <= alpha) for r in mine)
                cells.append(f"{rule} {hits} ({same} same)")
            lines.append(f"{study} alpha {alpha}: {len(mine)} runs, all twins {found}; " + "; ".join(cells))
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run_dirs", nargs="+", type=Path)
    parser.add_argument("--twins", default="19,39,59", help="the numbers of FB twins to try")
    args = parser.parse_args()
    ns = tuple(int(n) for n in args.twins.split(","))
    rows = [row for d in args.run_dirs for row in runs_of(d, ns)]
    stored = sum(abs(r["p_all"] - r["p_stored"]) <= 1e-12 for r in rows)
    print(f"{len(rows)} runs and methods; hcid's p over all their FB twins equals the stored p in {stored}")
    print("\n".join(summary(rows, ns)))
    print("decisions at 0.05 that change:")
    for r in rows:
        rules = [k for k in r if k.startswith("p") and k[1].isdigit()]
        if any((r[k] <= 0.05) != (r["p_all"] <= 0.05) for k in rules):
            cells = (f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}" for k, v in r.items())
            print("  " + ", ".join(cells))


if __name__ == "__main__":
    main()
