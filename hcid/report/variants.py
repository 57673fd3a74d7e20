"""Compare studies that differ only in how a method is configured (the indirect stage-1 variants).

``python -m hcid.report.variants OUT_DIR CONFIG...`` (``make indirect-variants``)
reads each config's run directory (``runs/<name>``, as the CLI's default),
and writes ``OUT_DIR/report.md``, ``report.html`` and ``variants.parquet``:
per variant, W_FP of the indirect method, P(W_FP >= the paper's) for a study
of 50, W_FP of each block of 50 seeds, the false-positive rate at W_BIC with
its exact band, and the accuracy of e_r (VAF against the noise-free e).
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa

from hcid import tables
from hcid.assembly.resolve import load_config
from hcid.config import Config, paper
from hcid.errors import DataError, HcidError
from hcid.io import folders, results
from hcid.report import figures
from hcid.report.document import Doc, to_html, to_markdown
from hcid.report.sections.handoff import stage_options, summarize
from hcid.report.sections.rates import rate_with_band
from hcid.report.verdicts import sampling_verdict
from hcid.selection import criteria

__all__ = ["Variant", "compute_variant", "main", "write_variants"]

METHOD = "indirect"
BLOCK = paper.N_REALIZATIONS


@dataclass(frozen=True)
class Variant:
    """One variant's figures (FB model, indirect method)."""

    name: str
    options: str
    n: int
    w_fp: float
    p_w_fp_at_paper: float
    block_w_fp: tuple[float, ...]
    fp_rate_bic: float
    vaf_median: float
    vaf_p5: float
    vaf_min: float
    vaf_record_median: float
    nb_ft_at_bound: float
    stage1_top: str
    rates: pa.Table
    w_bic: float


def _fb(config: Config):
    fb = next((m for m in config.models if not m.has_feedforward), None)
    if fb is None:
        raise DataError(f"{config.name}: has no model without feedforward to count false positives on")
    return fb


def _block_w_fp(run_dir: Path, fb: str, hint: str) -> tuple[float, ...]:
    """W_FP of each block of :data:`BLOCK` FB realizations (in seed order): the largest W at which
    any of them selects feedforward under the indirect method, from the breakpoints."""
    bp = results.read(tables.BREAKPOINTS, run_dir, hint=hint).to_pydict()
    extent: dict[int, float] = {}
    for model, seed, method, w_to, nb in zip(
        bp["model"], bp["seed"], bp["method"], bp["w_to"], bp["nb_ft"], strict=True
    ):
        if model == fb and method == METHOD:
            extent.setdefault(seed, 0.0)
            if nb > 0:
                extent[seed] = max(extent[seed], w_to)
    seeds = sorted(extent)
    return tuple(
        max(extent[s] for s in seeds[i : i + BLOCK]) for i in range(0, len(seeds) - BLOCK + 1, BLOCK)
    )


def _stage1_choices(config: Config, run_dir: Path, fb: str, hint: str) -> tuple[float, str]:
    """Stage 1's choices for the FB realizations: the share at the grid's largest nb_ft, and the
    most frequent structure with its count."""
    stage1 = results.read(tables.stage_choice("stage1", ("ft", "fd", "e")), run_dir, hint=hint).to_pydict()
    chosen = [
        tuple(stage1[c][i] for c in ("na", "nb_ft", "nb_fd", "nk_ft", "nk_fd"))
        for i in range(len(stage1["model"]))
        if stage1["model"][i] == fb
    ]
    bound = config.identify.stage("stage1").grid.nb1[1]
    counts: dict[tuple, int] = {}
    for c in chosen:
        counts[c] = counts.get(c, 0) + 1
    top = max(counts.items(), key=lambda x: x[1]) if counts else ((), 0)
    at_bound = float(np.mean([c[1] == bound for c in chosen])) if chosen else np.nan
    return at_bound, f"{list(top[0])} x{top[1]}"


def compute_variant(config: Config, run_dir: Path) -> Variant:
    """The figures of one variant's run directory (after ``identify --method indirect``, ``sweep-w``)."""
    fb = _fb(config).name
    hint = f"run `make indirect-variants` (or identify and sweep-w {config.name})"
    th = {
        (r["method"], r["model"]): r
        for r in results.read(tables.thresholds(), run_dir, hint=hint).to_pylist()
    }
    if (METHOD, fb) not in th or th[(METHOD, fb)].get("p_w_fp_at_paper") is None:
        raise DataError(
            f"{run_dir}: thresholds.parquet has no {METHOD} row for {fb} with sampling columns; {hint}"
        )
    row = th[(METHOD, fb)]
    blocks = _block_w_fp(run_dir, fb, hint)
    handoff = results.read(tables.HANDOFF, run_dir, hint=hint).to_pydict()
    mine = [
        i
        for i, (m, me) in enumerate(zip(handoff["model"], handoff["method"], strict=True))
        if m == fb and me == METHOD
    ]
    vafs = np.array([handoff["vaf_noise_free"][i] for i in mine])
    vafs_record = np.array([handoff["vaf_noise_free_record"][i] for i in mine])
    med, p5, lo = summarize(vafs) if vafs.size else (np.nan, np.nan, np.nan)
    at_bound, top = _stage1_choices(config, run_dir, fb, hint)
    rates = results.read(tables.RATES, run_dir, hint=hint)
    mask = [
        m == fb and me == METHOD
        for m, me in zip(rates["model"].to_pylist(), rates["method"].to_pylist(), strict=True)
    ]
    return Variant(
        name=config.name,
        options="; ".join(stage_options(config)) or "SPEC 3 defaults",
        n=row["n_realizations"],
        w_fp=row["w_fp"],
        p_w_fp_at_paper=row["p_w_fp_at_paper"],
        block_w_fp=blocks,
        fp_rate_bic=row.get(tables.rate_column("w_bic")),
        w_bic=criteria.w_bic(row["nf"]),
        vaf_median=med,
        vaf_p5=p5,
        vaf_min=lo,
        vaf_record_median=float(np.median(vafs_record)) if vafs_record.size else np.nan,
        nb_ft_at_bound=at_bound,
        stage1_top=top,
        rates=rates.filter(pa.array(mask)),
    )


def _table(variants: list[Variant]) -> pa.Table:
    return pa.Table.from_pydict(
        {
            "variant": [v.name for v in variants],
            "options": [v.options for v in variants],
            "n_realizations": [v.n for v in variants],
            "w_fp": [v.w_fp for v in variants],
            "p_w_fp_at_paper": [v.p_w_fp_at_paper for v in variants],
            "block_w_fp": [list(v.block_w_fp) for v in variants],
            "fp_rate_bic": [v.fp_rate_bic for v in variants],
            "vaf_e_r_median": [v.vaf_median for v in variants],
            "vaf_e_r_p5": [v.vaf_p5 for v in variants],
            "vaf_e_r_min": [v.vaf_min for v in variants],
            "vaf_e_r_record_median": [v.vaf_record_median for v in variants],
            "nb_ft_at_bound": [v.nb_ft_at_bound for v in variants],
        }
    )


def render(variants: list[Variant]) -> Doc:
    doc = Doc()
    ref = paper.W_FP[METHOD]
    doc.text(
        "# Indirect method: stage-1 variants\n\n"
        f"The FB study identified by the indirect method under each stage-1 variant (config "
        f"`identify.stage1` options `rows` and `model`). The paper's W_FP indirect is {ref:g}. "
        f"P(W_FP >= {ref:g}) is for a study of the paper's {BLOCK} realizations, from this run's "
        "per-realization largest false-positive W (SPEC 9); the W_FP of each block of "
        f"{BLOCK} seeds shows the spread directly. e_r accuracy: VAF (%) of stage 1's e_r against e "
        "simulated without remnant, over the rows stage 2 fits and validates on and over "
        "the whole record. 'nb_ft at bound': share of realizations whose "
        "stage-1 model has nb_ft at the grid's upper end (the paper reports it always does)."
    )
    doc.table(
        [
            "variant",
            "stage-1 options",
            "n",
            "W_FP indirect",
            f"P(W_FP >= {ref:g})",
            "verdict",
            f"W_FP per {BLOCK} seeds",
            "FP rate at W_BIC [95%]",
            "e_r VAF % (stage-2 rows) median / 5th pct / min",
            "e_r VAF % whole record, median",
            "nb_ft at bound",
            "most frequent stage-1 model",
        ],
        [
            [
                v.name,
                v.options,
                str(v.n),
                f"{v.w_fp:.3g}",
                f"{v.p_w_fp_at_paper:.3g}",
                sampling_verdict(v.p_w_fp_at_paper)[1] or "-",
                ", ".join(f"{b:.3g}" for b in v.block_w_fp),
                rate_with_band(v.fp_rate_bic, v.n),
                f"{v.vaf_median:.2f} / {v.vaf_p5:.2f} / {v.vaf_min:.2f}",
                f"{v.vaf_record_median:.4g}",
                f"{v.nb_ft_at_bound:.0%}",
                v.stage1_top,
            ]
            for v in variants
        ],
    )
    doc.figure(
        "variants_fp_rate.png",
        "False-positive rate of FB (indirect method) over W per stage-1 variant, with exact 95% bands; "
        f"the paper's W_FP indirect ({ref:g}) and W_BIC marked.",
        lambda: _plot(variants),
    )
    return doc


def _plot(variants: list[Variant]):
    curves = {
        v.name: {c: np.asarray(v.rates.column(c).to_numpy()) for c in ("w", "rate", "low", "high")}
        for v in variants
    }
    return figures.plot_rate_curves(
        curves, {"paper W_FP indirect": paper.W_FP[METHOD], "W_BIC": variants[0].w_bic}, "FB, indirect method"
    )


def write_variants(out_dir: Path, configs: list[Config], runs_root: Path = Path("runs")) -> list[Variant]:
    """Compute every variant from ``runs_root/<config name>`` and write the comparison into ``out_dir``."""
    variants = [compute_variant(c, runs_root / c.name) for c in configs]
    doc = render(variants)
    names = [*doc.drawings, "report.md", "report.html", "variants.parquet"]
    folders.check_output_path(out_dir, "report folder")
    folders.claim(out_dir, names, folders.REPORT, adopt=lambda entries: set(entries) <= set(names))
    for name, draw in doc.drawings.items():
        figures.save(draw(), out_dir / name)
    results.write_text(to_markdown(doc), out_dir / "report.md")
    results.write_text(to_html(doc, out_dir, "indirect stage-1 variants"), out_dir / "report.html")
    results.write_table(_table(variants), out_dir / "variants.parquet")
    return variants


def main(argv: list[str]) -> int:
    if len(argv) < 2:
        print("usage: python -m hcid.report.variants OUT_DIR CONFIG...", file=sys.stderr)
        return 2
    try:
        variants = write_variants(Path(argv[0]), [load_config(p) for p in argv[1:]])
    except HcidError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    for v in variants:
        print(
            f"{v.name:<16} W_FP {v.w_fp:.3g}  P(W_FP >= {paper.W_FP[METHOD]:g}) {v.p_w_fp_at_paper:.3g}  "
            f"FP at W_BIC {v.fp_rate_bic:.3f}  e_r VAF median {v.vaf_median:.2f}% "
            f"(whole record {v.vaf_record_median:.4g}%)"
        )
    print(f"report: {Path(argv[0]) / 'report.html'}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
