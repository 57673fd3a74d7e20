"""The run report: Markdown and self-contained HTML with PNG figures, from a run's tables.

:func:`build_report` reads what the run directory holds, computes (in
:mod:`hcid.report.compute`), draws (in :mod:`hcid.report.figures`) and writes
``report.md``, ``report.html`` (figures embedded) and the PNGs beside them.
Stages that have not run are named as missing; what is there is reported.
"""

from __future__ import annotations

import importlib.metadata
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute  # noqa: F401  (pa.compute)
import yaml

from hcid import paper as PAPER
from hcid import results, selection
from hcid.config import Config, parse_config
from hcid.errors import DataError
from hcid.hcmodel import true_response
from hcid.report.document import Doc, to_html, to_markdown

__all__ = ["Report", "build_report"]


@dataclass(frozen=True)
class Report:
    """Where the report went and what it holds."""

    markdown: Path
    html: Path
    figures: tuple[Path, ...]
    missing: tuple[str, ...]
    verdicts: list


_REQUIRED = {
    results.SIMULATION_SUMMARY: ("model", "seed", "rms_e_deg", "noise_ratio_disturbance_only", "kn"),
    results.FRONTIER: (
        *results.KEY_COLUMNS,
        "na",
        "nb_ft",
        "nb_e",
        "nk_ft",
        "nk_e",
        "d",
        "v",
        "vaf_estimation",
        "vaf_validation",
        "a",
        "b_ft",
        "b_e",
    ),
    results.IDENTIFY_LOG: (
        *results.KEY_COLUMNS,
        "n_candidates",
        "n_unstable",
        "stage1_candidates",
        "stage1_unstable",
        "seconds_stage1",
        "seconds",
    ),
    results.STAGE1: ("model", "seed", "na", "nb_ft", "nb_fd", "nk_ft", "nk_fd"),
    results.SELECTION: (
        *results.KEY_COLUMNS,
        "w",
        "na",
        "nb_ft",
        "nb_e",
        "nk_ft",
        "nk_e",
        "d",
        "vaf_estimation",
    ),
    results.THRESHOLDS: ("method", "model", "has_feedforward", "nf", "w_aic", "w_bic", "w_fp", "w_fn"),
    results.RUN_LOG: ("stage", "seconds", "jobs", "finished"),
    results.CALIBRATION: (
        "method",
        "w",
        "fp_rate",
        "fp_low",
        "fp_high",
        "fn_rate",
        "fn_low",
        "fn_high",
        "n_fb",
        "n_ff",
        "target_rate",
        "safe_low",
        "safe_high",
        "recommended",
    ),
}


def _read_optional(run_dir: Path, name: str) -> pa.Table | None:
    """A table of the run, checked for the columns the report reads, or None if absent."""
    path = run_dir / name
    return results.read_table(path, _REQUIRED.get(name, ())) if path.is_file() else None


def _load_config(run_dir: Path) -> Config:
    path = run_dir / "config.yaml"
    if not path.is_file():
        raise DataError(f"{path}: missing; is {run_dir} a run directory (made by `hcid simulate`)?")
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise DataError(f"{path}: not valid YAML") from exc
    return parse_config(data, run_dir.name)


def _versions() -> str:
    names = ["hcid", "numpy", "scipy", "control", "numba", "pyarrow", "joblib", "matplotlib"]
    out = []
    for n in names:
        try:
            out.append(f"{n} {importlib.metadata.version(n)}")
        except importlib.metadata.PackageNotFoundError:
            out.append(f"{n} -")
    return ", ".join(out)


def _fmt_range(r) -> str:
    return f"{r[0]}..{r[1]}"


def _section_facts(b: _Build):
    """1. Run facts: config, grids, candidates, unstable counts, wall times, versions."""

    # 1. run facts
    b.doc.text("## 1. Run facts")
    g_d, g_1 = b.config.identify.direct.grid, b.config.identify.stage1.grid
    facts = [
        ["config", b.config.name],
        ["models", ", ".join(m.name for m in b.config.models)],
        ["seeds", f"{len(b.config.seeds)} ({b.config.seeds[0]}..{b.config.seeds[-1]})"],
        [
            "direct / stage-2 grid",
            f"na {_fmt_range(g_d.na)}, nb_ft {_fmt_range(g_d.nb1)}, nb_e {_fmt_range(g_d.nb2)}, "
            f"nk_ft {_fmt_range(g_d.nk1)}, nk_e {_fmt_range(g_d.nk2)}",
        ],
        [
            "stage-1 grid",
            f"na {_fmt_range(g_1.na)}, nb_ft {_fmt_range(g_1.nb1)}, nb_fd {_fmt_range(g_1.nb2)}, "
            f"nk_ft {_fmt_range(g_1.nk1)}, nk_fd {_fmt_range(g_1.nk2)}",
        ],
        [
            "W grid",
            f"{len(b.config.w_grid)} points, {b.config.w_grid[0]:.3g}..{b.config.w_grid[-1]:.3g} (log)",
        ],
    ]
    if b.log is not None:
        lg = b.log.to_pydict()
        n_cand = sum(lg["n_candidates"]) + sum(lg["stage1_candidates"])
        n_unst = sum(lg["n_unstable"]) + sum(lg["stage1_unstable"])
        facts.append(
            ["candidates fitted", f"{n_cand:,} ({n_unst:,} unstable, {n_unst / max(n_cand, 1):.1%})"]
        )
        for method in ("direct", "indirect"):
            rows = [i for i, m in enumerate(lg["method"]) if m == method]
            if rows:
                s1 = sum(lg["seconds_stage1"][i] for i in rows)
                tot = sum(lg["seconds"][i] for i in rows)
                unst = sum(lg["n_unstable"][i] for i in rows)
                text = f"{tot:.0f} s summed over tasks"
                if method == "indirect":
                    unst1 = sum(lg["stage1_unstable"][i] for i in rows)
                    text += (
                        f" (stage 1 {s1:.0f} s, stage 2 {tot - s1:.0f} s); "
                        f"unstable: stage 1 {unst1:,}, stage 2 {unst:,}"
                    )
                else:
                    text += f"; unstable {unst:,}"
                facts.append([f"{method} identification", text])
    if b.runlog is not None:
        for row in b.runlog.to_pylist():
            facts.append(
                [
                    f"wall time: {row['stage']}",
                    f"{row['seconds']:.1f} s on {row['jobs']} worker(s), {row['finished']}",
                ]
            )
    facts.append(["packages", _versions()])
    b.doc.table(["item", "value"], facts)


def _section_simulation(b: _Build):
    """2. Simulation: RMS(e) and remnant ratio beside the paper's Table 2; a record."""
    from hcid.report import figures

    # 2. simulation
    b.doc.text("## 2. Simulation")
    if b.summary is not None:
        s = b.summary.to_pydict()
        paper = {k: f"{v:.2f}" for k, v in PAPER.RMS_E_DEG.items()}
        rows = []
        for m in b.config.models:
            idx = [i for i, n in enumerate(s["model"]) if n == m.name]
            rms = np.array([s["rms_e_deg"][i] for i in idx])
            ratio = np.array([s["noise_ratio_disturbance_only"][i] for i in idx])
            rows.append(
                [
                    m.name,
                    f"{m.Kpt:g}",
                    f"{m.Kpe:g}",
                    f"{m.TL:g}",
                    f"{m.tau_pe:g}",
                    f"{rms.mean():.3f} +- {rms.std(ddof=1) if rms.size > 1 else 0:.3f}",
                    paper.get(m.name, "-"),
                    f"{ratio.mean():.4f}",
                    f"{s['kn'][idx[0]]:.5g}",
                ]
            )
        b.doc.table(
            [
                "model",
                "Kpt",
                "Kpe",
                "TL s",
                "tau_pe s",
                "RMS(e) deg (mean +- sd)",
                "paper Table 2",
                "var(n)/var(u) dist.-only",
                "Kn",
            ],
            rows,
        )
        sims = _read_optional(b.run_dir, results.SIMULATIONS)
        if sims is not None:
            recs = results.records(sims, b.run_dir / results.SIMULATIONS)
            key = next(
                ((m.name, b.config.seeds[0]) for m in b.config.models if m.has_feedforward), next(iter(recs))
            )
            rec = recs[key]
            b.figs["signals.png"] = figures.plot_signals(
                rec["t"], rec, f"Record of model {key[0]}, seed {key[1]}"
            )
            b.doc.figure("signals.png", f"One simulated record (model {key[0]}, seed {key[1]}), 25 Hz.")
    else:
        b.doc.text("_Missing: `simulation_summary.parquet` (run `hcid simulate`)._")


def _section_curves(b: _Build):
    """3-4. VAF and nb_ft of the selected models over W (paper Figs. 5, 6)."""
    from hcid.report import compute, figures

    # 3-4. curves over W
    b.doc.text("## 3. Model fit vs W (paper Fig. 5)")
    if b.selection is not None:
        curves = compute.compute_curves(b.selection)
        b.verdict_inputs["curves"] = curves
        b.figs["vaf_vs_w.png"] = figures.plot_vaf(curves, {"W_AIC": b.w_aic, "W_BIC": b.w_bic})
        b.doc.figure(
            "vaf_vs_w.png",
            "Mean VAF (estimation rows) +- one sd of the selected models over "
            "the realizations; dotted W_AIC, dashed W_BIC.",
        )
        b.doc.text("## 4. Feedforward found vs W (paper Fig. 6)")
        marks = {}
        for r in b.th_rows:
            if r["w_fp"] is not None:
                marks[f"W_FP {r['method']}"] = r["w_fp"]
            if r["w_fn"] is not None:
                marks[f"W_FN {r['method']}"] = r["w_fn"]
        b.figs["nb_ft_vs_w.png"] = figures.plot_nb_ft(curves, marks)
        b.doc.figure(
            "nb_ft_vs_w.png",
            "Mean nb_ft of the selected models. FB: any nb_ft > 0 is a false "
            "positive; FF: a mean below 2 is a false negative.",
        )
        if b.th_rows:
            b.doc.table(
                ["method", "model", "W_AIC", "W_BIC", "W_FP", "W_FN", "paper"],
                [
                    [
                        r["method"],
                        r["model"],
                        f"{r['w_aic']:.3g}",
                        f"{r['w_bic']:.3g}",
                        "-" if r["w_fp"] is None else f"{r['w_fp']:.3g}",
                        "-" if r["w_fn"] is None else f"{r['w_fn']:.3g}",
                        f"W_FN {PAPER.W_FN:g}"
                        if r["has_feedforward"]
                        else f"W_FP {PAPER.W_FP[r['method']]:.2g}",
                    ]
                    for r in b.th_rows
                ],
            )
    else:
        b.doc.text("_Missing: `selection.parquet` (run `hcid sweep-w`)._")


def _section_responses(b: _Build):
    """5-7. Selected models' frequency responses and errors (paper Figs. 7-10)."""
    from hcid.report import compute, figures

    # 5-7. frequency responses
    b.doc.text("## 5. Selected models at W_BIC (paper Figs. 7, 8)")
    if b.frontier is not None:
        bic = compute.compute_responses(b.frontier, b.config, b.w_bic)
        w047 = compute.compute_responses(b.frontier, b.config, 0.47)
        b.verdict_inputs.update(bic=bic, w047=w047)
        omega = bic.omega
        ref02 = compute.reference_feedforward(b.config, omega)
        for m in b.config.models:
            hft_true, he_true = true_response(m, b.config.loop, omega)
            refs = {}
            if not m.has_feedforward and ref02 is not None:
                refs = {"hft": [("FF feedforward, Kpt = 0.2", ref02)]}
            name = f"bode_{m.name}_bic.png"
            b.figs[name] = figures.plot_bode(
                bic,
                m.name,
                {"hft": hft_true, "he": he_true},
                refs,
                title=f"{m.name}: selected models at W_BIC = {b.w_bic:.3g}",
            )
            b.doc.figure(
                name,
                f"{m.name}: every realization's selected model at W_BIC (thin lines; "
                "the count of models with that path in the legend), the true paths (black), "
                "the disturbance band 0.23..17.33 rad/s (dashed).",
            )
        ff = next((m for m in b.config.models if m.has_feedforward), None)
        if ff is not None:
            b.doc.text("## 6. FF feedback path at W = 0.47 (paper Fig. 9)")
            _, he_true = true_response(ff, b.config.loop, w047.omega)
            b.figs["bode_FF_w047.png"] = figures.plot_bode(
                w047, ff.name, {"he": he_true}, paths=("he",), title=f"{ff.name}: feedback path at W = 0.47"
            )
            b.doc.figure("bode_FF_w047.png", "Feedback path of the models selected at W = 0.47.")
            b.doc.text("## 7. Errors at W_BIC, direct vs indirect (paper Fig. 10)")
            hft_true, he_true = true_response(ff, b.config.loop, omega)
            errors = {}
            for path, true in (("hft", hft_true), ("he", he_true)):
                for method in ("direct", "indirect"):
                    h = getattr(bic, path).get((ff.name, method))
                    if h is not None:
                        errors[(path, method)] = compute.compute_errors(h, true)
            b.figs["errors_bic.png"] = figures.plot_errors(
                omega, errors, f"{ff.name}: errors at W_BIC, mean (solid) and max (dashed) over realizations"
            )
            b.doc.figure("errors_bic.png", "Magnitude and phase errors (paper eq. 11-12) of the FF model.")
        if b.stage1 is not None:
            s1 = b.stage1.to_pydict()
            combos = {}
            for i in range(b.stage1.num_rows):
                k = (s1["na"][i], s1["nb_ft"][i], s1["nb_fd"][i], s1["nk_ft"][i], s1["nk_fd"][i])
                combos[k] = combos.get(k, 0) + 1
            b.doc.text(
                "Stage-1 choices of the indirect method (na, nb_ft, nb_fd, nk_ft, nk_fd): "
                + ", ".join(f"{k} x{v}" for k, v in sorted(combos.items(), key=lambda x: -x[1])[:6])
                + "."
            )
    else:
        b.doc.text("_Missing: `frontier.parquet` (run `hcid identify`)._")


def _section_verdicts(b: _Build) -> list:
    """8. Verdicts on SPEC section 6."""
    from hcid.report import compute

    # 8. verdicts
    b.doc.text("## 8. Verdicts: the paper's claims (SPEC section 6) against this run")
    if b.summary is None:
        b.doc.text("_No simulation in this run: the paper's claims are not evaluated._")
    verdicts = compute.compute_verdicts(
        b.config,
        b.summary,
        b.verdict_inputs["curves"],
        b.thresholds,
        b.verdict_inputs["bic"],
        b.verdict_inputs["w047"],
    )
    b.doc.table(
        ["claim", "paper", "this run", "holds", "rule"],
        [
            [
                v.claim,
                v.paper,
                v.this_run,
                {True: "holds", False: "does not hold", None: "not evaluated"}[v.holds],
                v.rule,
            ]
            for v in verdicts
        ],
    )

    return verdicts


def _section_calibration_and_data(b: _Build):
    """9-10. W calibration and measured data (paper section 6)."""
    from hcid.report import compute, figures

    # 9-10. calibration and measured data (paper section 6's two recommendations)
    calibration = _read_optional(b.run_dir, results.CALIBRATION)
    recommended = {}
    if calibration is not None:
        b.doc.text("## 9. W calibration on the HC hypothesis")
        b.figs["calibration.png"] = figures.plot_calibration(calibration, b.config.name)
        b.doc.figure(
            "calibration.png",
            "False-positive rate of the FB twin and false-negative rate of the FF "
            "twin over W, with exact 95% (Clopper-Pearson) bands over realizations; green: the safe "
            "interval where both rates are at most the target rate, and the recommended W, its "
            "geometric midpoint.",
        )
        rows = []
        for method in ("direct", "indirect"):
            r = [x for x in calibration.to_pylist() if x["method"] == method]
            if r:
                r = r[0]
                recommended[method] = r["recommended"]
                rows.append(
                    [
                        method,
                        f"{r['target_rate']:g}",
                        f"{r['safe_low']:.4g}",
                        f"{r['safe_high']:.4g}",
                        f"{r['recommended']:.4g}" if np.isfinite(r["recommended"]) else "no safe W",
                    ]
                )
        b.doc.table(["method", "target rate", "safe from W", "safe below W", "recommended W"], rows)
    data_cfg = b.config.data
    if (
        data_cfg is not None
        and b.frontier is not None
        and data_cfg.name in set(b.frontier.column("model").to_pylist())
    ):
        b.doc.text(f"## 10. Measured data: {data_cfg.name}")
        b.doc.text(
            "No true dynamics are known for measured data: the report shows the selected structure and "
            "fit as functions of W, and the models at chosen W values"
            + (
                ", the calibrated W marked as the answer."
                if recommended
                else "; run `hcid calibrate-w` to mark a calibrated W."
            )
        )
        if b.selection is not None:
            structure = compute.compute_data_structure(b.selection, data_cfg.name)
            if structure is not None:
                marks = {"W_BIC": b.w_bic, **{f"calibrated {m}": w for m, w in recommended.items()}}
                b.figs["data_structure.png"] = figures.plot_data_structure(structure, marks, data_cfg.name)
                b.doc.figure("data_structure.png", "Selected nb_ft, d and VAF of every run vs W.")
        w_values = sorted(set(data_cfg.w_report) | {w for w in recommended.values() if np.isfinite(w)})
        b.doc.table(
            ["run", "method", "W", "na", "nb_ft", "nb_e", "nk_ft", "nk_e", "VAF est. %", "VAF val. %"],
            compute.data_summary_rows(b.frontier, data_cfg.name, w_values),
        )
        b.doc.text(
            f"nk_ft includes the {b.config.identify.target_shift:g} s target shift: the ft delay is "
            f"nk_ft - {b.config.identify.shift_samples(b.config.timing.output_rate)} samples "
            "(negative: anticipation)."
        )
        for w in w_values:
            resp = compute.compute_responses(
                b.frontier.filter(pa.compute.equal(b.frontier.column("model"), data_cfg.name)), b.config, w
            )
            name = f"bode_data_w{w:.4g}.png".replace("+", "")
            answer_for = [m for m, r in recommended.items() if np.isclose(w, r)]
            is_answer = bool(answer_for)
            title = f"{data_cfg.name}: selected models at W = {w:.3g}" + (
                f" (calibrated for the {' and '.join(answer_for)} method)" if is_answer else ""
            )
            b.figs[name] = figures.plot_bode(resp, data_cfg.name, {}, title=title)
            b.doc.figure(
                name,
                f"Every run's selected model at W = {w:.3g}"
                + (", the calibrated W: the answer." if is_answer else "."),
            )


@dataclass
class _Build:
    """What the report sections read (the run's tables) and share (figures, W marks)."""

    run_dir: Path
    config: Config
    summary: pa.Table | None
    frontier: pa.Table | None
    log: pa.Table | None
    stage1: pa.Table | None
    selection: pa.Table | None
    thresholds: pa.Table | None
    runlog: pa.Table | None
    doc: Doc = field(default_factory=Doc)
    figs: dict[str, object] = field(default_factory=dict)
    verdict_inputs: dict = field(default_factory=lambda: {"curves": None, "bic": None, "w047": None})

    @property
    def th_rows(self) -> list[dict]:
        return self.thresholds.to_pylist() if self.thresholds is not None else []

    @property
    def w_aic(self) -> float:
        return selection.w_aic(self.config.identify.direct.estimation.length)

    @property
    def w_bic(self) -> float:
        return selection.w_bic(self.config.identify.direct.estimation.length)


def build_report(run_dir: str | Path, out_dir: str | Path | None = None) -> Report:
    """Write the report of ``run_dir`` into ``out_dir`` (default: ``run_dir/report``)."""
    from hcid.report import figures

    run_dir = Path(run_dir)
    out_dir = Path(out_dir) if out_dir is not None else run_dir / "report"
    b = _Build(
        run_dir=run_dir,
        config=_load_config(run_dir),
        summary=_read_optional(run_dir, results.SIMULATION_SUMMARY),
        frontier=_read_optional(run_dir, results.FRONTIER),
        log=_read_optional(run_dir, results.IDENTIFY_LOG),
        stage1=_read_optional(run_dir, results.STAGE1),
        selection=_read_optional(run_dir, results.SELECTION),
        thresholds=_read_optional(run_dir, results.THRESHOLDS),
        runlog=_read_optional(run_dir, results.RUN_LOG),
    )
    missing = [
        name
        for name, t in (("simulation", b.summary), ("identification", b.frontier), ("W sweep", b.selection))
        if t is None
    ]
    b.doc.text(f"# hcid report: {b.config.name}\n\nRun directory: `{run_dir}`.")
    if missing:
        b.doc.text(
            "**Missing stages:** "
            + ", ".join(missing)
            + ". Run `hcid run CONFIG` to complete them; what is there is reported below."
        )
    _section_facts(b)
    _section_simulation(b)
    _section_curves(b)
    _section_responses(b)
    verdicts = _section_verdicts(b)
    _section_calibration_and_data(b)
    doc, figs, config = b.doc, b.figs, b.config

    written = []
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise DataError(f"{out_dir}: cannot write the report ({exc.strerror or exc})") from exc
    for name, fig in figs.items():
        figures.save(fig, out_dir / name)
        written.append(out_dir / name)
    md_path, html_path = out_dir / "report.md", out_dir / "report.html"
    results.write_text(to_markdown(doc), md_path)
    results.write_text(to_html(doc, out_dir, config.name), html_path)
    return Report(md_path, html_path, tuple(written), tuple(missing), verdicts)
