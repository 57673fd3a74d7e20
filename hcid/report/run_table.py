"""The study report's table of runs (``hcid analyse``): one row per run and method, its evidence,
fit and parameters with their standard errors, split in two that fit a page; and the number
formats the study section shares with it."""

from __future__ import annotations

import math

from hcid import tables
from hcid.hcfit.consistency import CONTRADICTED, format_p
from hcid.hcfit.determined import is_flagged, is_on_bound, is_undetermined

__all__ = ["SHOWN", "factor_columns", "num", "percent", "run_table", "split_runs", "with_se"]


def num(x, digits: int = 3) -> str:
    """A number to ``digits`` significant figures, ``-`` for None or NaN."""
    return "-" if x is None or not math.isfinite(x) else f"{x:.{digits}g}"


def percent(share: float) -> str:
    """A share (0 to 1) in whole percent, ``-`` for NaN."""
    return "-" if not math.isfinite(share) else f"{100 * share:.0f}"


#: The parameters in the run table's reading order (the feedforward path first).
SHOWN = ("Kpt", "TI", "tau_pt", "Kpe", "TL", "tau_pe", "w_nms", "zeta_nms")
#: The run table's short names of the deciding statistics.
_SHORT = {"Fourier coefficients": "Fourier", "likelihood ratio": "LR"}


def with_se(r: dict, p: str) -> str:
    """The estimate with its se; † where the data do not determine it (no se then: its reason
    in analysis.csv's <p>_status), ‡ where determined but to read with care (outside its
    plausible range, or not told from 0), "(held)" where held at a literature value (a degree
    sign read as a unit)."""
    if not math.isfinite(r[p]):
        return "-"
    status = r[p + "_status"]
    if status.startswith("fixed"):
        return num(r[p]) + " (held)"
    if is_undetermined(status):  # its se says nothing (3e+05 in a correlated pair, 4e-09 in a failed fit)
        # On a bound within 1e-6 of 0 (a lead time held at 0) it reads as 0, not as 1.69e-08.
        at_zero = is_on_bound(status) and abs(r[p]) < 1e-6
        return ("0" if at_zero else num(r[p])) + "†"
    se = f" ± {num(r[p + '_se'], 2)}" if math.isfinite(r[p + "_se"]) else ""
    return num(r[p]) + se + ("‡" if is_flagged(status) else "")


def factor_columns(columns) -> list[str]:
    """The runs' own factor columns (subject, condition, trial, ...): those not hcid's."""
    return [c for c in columns if c not in tables.ANALYSIS.names]


#: The most factors the run table gives a column each; more share one column.
_FACTOR_COLUMNS = 3


def run_table(runs) -> tuple[list[str], list[list[str]]]:
    """The per-run table: its header (the runs' factors, units) and one row per run and method."""
    factors = factor_columns(runs.column_names)
    units = {p: tables.PARAMETER_UNITS[p] for p in SHOWN}
    # Many factors (a logger's names: subject, stamp, plant, ...) in one wrapped column: a column
    # each would make the table wider than the page.
    merged = len(factors) > _FACTOR_COLUMNS
    header = [
        "run",
        *(["factors"] if merged else factors),
        "method",
        "p (evidence)",
        "nb_ft at W",
        "feedforward at W",
        *[f"{p} {units[p]}" if units[p] != "-" else p for p in SHOWN],
        "wc rad/s",
        "PM deg",
        "VAF %",
        "remnant % of var(u): fit / data",
        "data check (p)",
    ]
    rows = []
    for r in runs.to_pylist():
        check = "-"
        if r["fc_dof"] != 0:
            check = format_p(r["fc_p"]) + (" contradicted" if r["fc_p"] < CONTRADICTED else "")
        rows.append(
            [
                str(r["run_id"]),
                *(["; ".join(f"{f} {r[f]}" for f in factors)] if merged else [str(r[f]) for f in factors]),
                r["method"],
                f"{num(r['p_value'], 2)} ({_SHORT.get(r['decided_by'], r['decided_by'])})",
                str(r["nb_ft"]),
                ("yes" if r["feedforward_at_w"] else "no")
                + (" (uncertain)" if r["uncertain"] else "")
                + (" *" if bool(r["feedforward_at_w"]) != (r["evidence"] == "feedforward") else ""),
                *[with_se(r, p) for p in SHOWN],
                num(r["crossover"]),
                num(r["phase_margin"]),
                "-" if not math.isfinite(r["vaf_validation"]) else f"{r['vaf_validation']:.1f}",
                f"{percent(r['share_remnant'])} / {percent(r['remnant_share_data'])}",
                check,
            ]
        )
    return header, rows


def split_runs(header: list[str], rows: list[list[str]]) -> tuple[tuple, tuple]:
    """The run table as two that fit a page: the run (its id, factors and method) with its
    evidence and fit, and the run with its parameters."""
    ident = header.index("method") + 1
    names = tuple(SHOWN)
    is_parameter = [h.split(" ")[0] in names for h in header]
    first = [i for i in range(len(header)) if i < ident or not is_parameter[i]]
    second = [i for i in range(len(header)) if i < ident or is_parameter[i]]

    def pick(columns: list[int]) -> tuple[list[str], list[list[str]]]:
        return [header[i] for i in columns], [[row[i] for i in columns] for row in rows]

    return pick(first), pick(second)
