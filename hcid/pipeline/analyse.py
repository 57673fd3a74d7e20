"""``hcid analyse``: a measured study end to end, W calibrated on twins of each group's fitted model.

1. Identify every run of the data set by every method (:func:`identify_study`).
2. Fit the parametric HC model (the config's estimator, ``time`` by default) to every run
   with and without its feedforward path, and SPEC 1's remnant filter to what the
   feedforward fit leaves.
3. Per group of runs (``--by``, default the factor ``condition``; one group without it):
   the twins are the group's fitted model (medians over its runs; the FF twin) and the
   same with ``Kpt = 0`` (the FB twin), with the group's fitted neuromuscular system
   and remnant, driven by the group's first run's recorded ft and fd at the data's
   rate and window (SPEC 10). ``calibrate-w`` on them (``RUN/twins/<group>/``) gives
   the safe interval and the recommended W per method.
4. Every run is selected at its group's W; the selected structure's parametric model
   is fitted (:func:`hcid.selected.analyse_selected`).

Where no W separates a group's own twins and another group's fitted feedforward is stronger
(``--ff-twin auto``, the default: a group where nobody uses feedforward has twins that nearly
coincide), the group is calibrated again with that group's feedforward path on its own
feedback: "would feedforward of the size this study shows be found here?"; ``ff_twin`` says
which twins gave W. Where no W separates the twins used, the W of the grid with the least
total error rate (FP + FN) is used and every decision there is marked ``uncertain``.

Writes ``analysis.parquet`` and ``analysis.csv`` (one row per run and method, with the run's
factors: statistics-ready), ``analysis_groups.parquet`` and ``fc_estimates.parquet`` (each
group's model-free estimates of both paths, SPEC 10, beside its fitted model).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pyarrow as pa

from hcid import datasets, folders, hcfit, methods, results, selection, tables
from hcid.calibration import (
    benjamini_hochberg,
    binomial_summary,
    evidence_p_value,
    evidence_power,
    feedforward_threshold,
    rates_at,
)
from hcid.config import Config
from hcid.config.fit import FEEDFORWARD_PARAMETERS
from hcid.config.parse import default_data
from hcid.descriptors import fit_remnant
from hcid.errors import ConfigError, DataError, IdentificationError
from hcid.fourier import fc_estimate
from hcid.hcfit.consistency import consistency, group_consistency
from hcid.hcfit.determined import group_model, is_undetermined, parameter_status, reason
from hcid.hcfit.lines import feedforward_size, line_data
from hcid.hcmodel import plant
from hcid.pipeline.fit import _choices, _records, _stage_choices
from hcid.pipeline.parallel import parallel_map
from hcid.pipeline.rundir import holds_run_dir
from hcid.pipeline.studies import identify_study
from hcid.pipeline.twins import (
    calibrate_twins,
    choose_w,
    forcing_sets,
    group_slug,
    pool_twins,
    separates,
    twin_rate,
    twin_sizes,
)
from hcid.selected import SelectedModel, analyse_selected

__all__ = ["AnalysisRun", "ParameterSummary", "analyse_study", "summarise_parameters"]

#: Realizations of each twin (FB and FF) per group.
TWINS = 20
#: Where the FF twin's feedforward path comes from: ``own`` (the group's fitted model, SPEC 10),
#: ``study`` (the group with the largest fitted Kpt: a power question for a group whose own
#: fitted feedforward is too weak to tell its twins apart) or ``auto`` (own; study for a group
#: whose own twins no W separates, for each method without a safe interval on its own twins).
FF_TWINS = ("auto", "own", "study")


@dataclass(frozen=True)
class AnalysisRun:
    """What ``hcid analyse`` found: ``groups`` (one row per group and method) and ``runs``
    (one row per run and method), as written to the run directory."""

    groups: pa.Table
    runs: pa.Table
    seconds: float
    run_dir: Path
    #: Wall seconds per stage: identify, fit runs, twins, fit selected, tables.
    stages: dict[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class ParameterSummary:
    """One parameter over a group's runs (rows of ``analysis.parquet``), from the runs that
    determine it (SPEC 11): ``median``, ``sd`` (over those runs) and ``median_se`` (NaN where
    none or one), ``kept`` of ``fitted`` runs, and ``left_out``: ``{reason: runs}``."""

    name: str
    unit: str
    fitted: int
    kept: int
    median: float
    sd: float
    median_se: float
    left_out: dict


def summarise_parameters(rows: Sequence[dict]) -> list[ParameterSummary]:
    """The group's parameters as the answer lines and the report give them (one home for both)."""
    out = []
    for p in tables.HC_PARAMETER_NAMES:
        fitted = [r for r in rows if r[f"{p}_status"] != "not fitted"]
        if not fitted:
            continue
        kept = [r for r in fitted if not is_undetermined(r[f"{p}_status"])]
        x = np.array([r[p] for r in kept], dtype=float)
        se = np.array([r[f"{p}_se"] for r in kept], dtype=float)
        left: dict[str, int] = {}
        for r in fitted:
            if is_undetermined(r[f"{p}_status"]):
                left[reason(r[f"{p}_status"])] = left.get(reason(r[f"{p}_status"]), 0) + 1
        out.append(
            ParameterSummary(
                name=p, unit=hcfit.UNITS[p], fitted=len(fitted), kept=int(x.size),
                median=float(np.median(x)) if x.size else math.nan,
                sd=float(np.std(x, ddof=1)) if x.size > 1 else math.nan,
                median_se=float(np.median(se[np.isfinite(se)])) if np.isfinite(se).any() else math.nan,
                left_out=left,
            )
        )  # fmt: skip
    return out


# --------------------------------------------------------------------------- per-run fits


def _fit_windows(config: Config) -> tuple[slice, slice]:
    """The rows every run's parametric fits use: the direct method's final stage's windows."""
    stage = config.identify.stage(methods.get("direct").final_stage.name)
    return stage.estimation.rows(), stage.validation.rows()


def _tracking(record: dict, config: Config) -> hcfit.TrackingRecord:
    return hcfit.TrackingRecord(
        record["ft"], record["e"], record["u"], config.timing.output_rate, *_fit_windows(config),
        fd=record["fd"],
    )  # fmt: skip


def _fit_run(config: Config, seed: int, record: dict, kn_rate: float):
    """The run's FF and FB fits and the remnant its FF fit leaves."""
    yc = plant(config.loop)
    tracking = _tracking(record, config)
    settings = config.fit_hc
    fits = {
        ff: hcfit.fit_hc(settings, yc, ff, record=tracking, disturbance_at=config.loop.disturbance_at)
        for ff in (True, False)
    }
    rows = slice(tracking.estimation.start, tracking.validation.stop)
    n = record["u"] - hcfit.simulate_hc(fits[True].values, yc, tracking, settings.oversample)
    try:
        remnant = fit_remnant(n[rows], config.timing.output_rate, kn_rate)
    except IdentificationError:
        remnant = None
    return seed, fits, remnant


# --------------------------------------------------------------------------- the study


def _groups(runs: pa.Table, by: Sequence[str]) -> dict[tuple[str, ...], list[int]]:
    """The runs (ids) of each group: the values of the ``by`` factors (checked by the caller)."""
    out: dict[tuple[str, ...], list[int]] = {}
    for row in runs.to_pylist():
        out.setdefault(tuple(str(row[f]) for f in by), []).append(int(row["seed"]))
    return out


def _final_task(config, seed, record, method_name, sel, choices, fit):
    analysis = analyse_selected(sel, record, config, methods.get(method_name), choices, fit=fit)
    return seed, method_name, analysis


def _same_fit(config: Config, sel: SelectedModel, fits: dict):
    """The run's own fit (step 2) of the selected structure when it is the one
    :func:`hcid.selected.fit_selected` would make (same windows: the direct method's final
    stage's), else None (fitted again)."""
    if (sel.estimation.rows(), sel.validation.rows()) != _fit_windows(config):
        return None
    return fits[bool(sel.has_feedforward)]


def _tables(config, runs, groups, by, used, chosen, finals, twins, models, checks, evidence, alpha):
    group_checks = {key: checks.group(seeds, models[key].values) for key, seeds in groups.items()}
    factors = [c for c in runs.column_names if c not in tables.RUNS.names]
    factor_of = {int(r["seed"]): r for r in runs.to_pylist()}
    group_rows, run_rows = [], []
    for key, seeds in groups.items():
        name = ", ".join(f"{f}={v}" for f, v in zip(by, key, strict=True)) or "all runs"
        for method_name in methods.METHODS:
            pair = used[(key, method_name)]
            cal = pair.calibrations[method_name]
            w, rule, uncertain = chosen[(key, method_name)]
            choice = {
                "group": name,
                "method": method_name,
                "w": w,
                "w_rule": rule,
                "uncertain": uncertain,
                "ff_twin": pair.kind,
                "safe_low": float(cal.safe_low),
                "safe_high": float(cal.safe_high),
                # Exactly at W, from the twins' selection paths (W need not be on the grid).
                **rates_at(*pair.paths[method_name], w),
            }
            n_ff = n_contradicted = 0
            for seed in seeds:
                a = finals[(seed, method_name)]
                sel, fit = a.model, a.fit
                n_ff += sel.nb_ft > 0
                values = dict(zip(fit.names, fit.estimates, strict=True)) if fit else {}
                ses = dict(zip(fit.names, fit.se, strict=True)) if fit else {}
                fitted_loop = next((d for d in a.loop if d.source == "fitted"), None)
                row = {
                    "model": config.data.name, "seed": seed,
                    "file": str(factor_of[seed]["file"]), "file_run": int(factor_of[seed]["file_run"]),
                    **choice,
                    **dict(zip(tables.ORDER_COLUMNS, sel.orders, strict=True)),
                    "feedforward": bool(sel.nb_ft > 0), "vaf_arx_validation": sel.vaf_validation,
                    "vaf_validation": fit.vaf_validation if fit else math.nan,
                }  # fmt: skip
                status = parameter_status(fit) if fit else {}
                row["target"] = fit.target if fit else config.fit_hc.target
                row["hc_form"] = ("nms fixed" if fit.fixed else "full") if fit else ""
                for p in tables.HC_PARAMETER_NAMES:
                    row[p] = values.get(p, math.nan)
                    row[f"{p}_se"] = ses.get(p, math.nan)
                    row[f"{p}_status"] = status.get(p, "not fitted")
                row["crossover"] = fitted_loop.crossover if fitted_loop else math.nan
                row["phase_margin"] = fitted_loop.phase_margin if fitted_loop else math.nan
                row["share_remnant"] = fitted_loop.shares["remnant"] if fitted_loop else math.nan
                row.update({k: v for k, v in evidence[(seed, method_name)].items() if k != "twins"})
                row["evidence_uncertain"] = bool(row["power"] < MIN_POWER)
                check = checks.run(seed, fit) if fit else None
                n_contradicted += bool(check is not None and check.contradicted)
                row.update(_consistency_columns(check, checks.problem([seed]) if fit else "not fitted"))
                for f in factors:
                    row[f] = str(factor_of[seed][f])
                run_rows.append(row)
            mine = [evidence[(seed, method_name)] for seed in seeds]
            group_rows.append(
                {**choice, "n_runs": len(seeds), "n_feedforward": int(n_ff), **_group_verdict(mine, alpha),
                 "forcing_sets": len(pair.sets), "decided_by": mine[0]["decided_by"],
                 **{f"twin_{p}": pair.model[p] for p in tables.HC_PARAMETER_NAMES},
                 **{f"fitted_{p}": models[key].values[p] for p in tables.HC_PARAMETER_NAMES},
                 "twin_kn": pair.remnant[0], "twin_w_n": pair.remnant[1], "twin_zeta_n": pair.remnant[2],
                 "twins": twins, "twins_folder": pair.folder,
                 "twin_source": models[key].source, "twin_undetermined": ", ".join(models[key].undetermined),
                 "n_contradicted": int(n_contradicted),
                 **_consistency_columns(group_checks[key], checks.problem(seeds))}
            )  # fmt: skip
    schema = tables.ANALYSIS.arrow
    for f in factors:
        schema = schema.append(pa.field(f, pa.string()))
    return (
        pa.Table.from_pylist(group_rows, schema=tables.ANALYSIS_GROUPS.arrow),
        pa.Table.from_pylist(run_rows, schema=schema),
    )


class _Checks:
    """Every run at its forcing lines, read once, for the consistency of any model with it (SPEC
    11); ``problem(seeds)`` says why some run (or the group) has no test."""

    def __init__(self, config: Config, records: dict):
        self.yc = plant(config.loop)
        self.rate = config.timing.output_rate
        self.records = records
        self.lines, self.problems = {}, {}
        for seed, record in records.items():
            try:
                self.lines[seed] = line_data(_tracking(record, config))
            except DataError as exc:
                self.problems[seed] = f"no test: {exc}"

    def problem(self, seeds) -> str:
        return next((self.problems[s] for s in seeds if s in self.problems), "")

    def run(self, seed: int, fit):
        """The run's own fit against its data; the lines estimator's free parameters, fitted to
        these lines, are taken off the degrees of freedom."""
        if seed not in self.lines:
            return None
        fitted = len(fit.names) - len(fit.fixed) if fit.target == "lines" else 0
        return consistency(fit.values, self.yc, self.lines[seed], self.records[seed], self.rate, fitted)

    def group(self, seeds: list[int], values: dict):
        if not all(s in self.lines for s in seeds):
            return None
        try:
            return group_consistency(
                values, self.yc, [self.lines[s] for s in seeds], [self.records[s] for s in seeds], self.rate
            )
        except DataError as exc:
            self.problems[seeds[0]] = f"no test: {exc}"
            return None


#: Below this power the twins cannot tell a run's feedforward from none (SPEC 11).
MIN_POWER = 0.8


def _run_evidence(path, nb_ft, pair, seed, method_name, config, alpha, run_size, sizes) -> dict:
    """The run's two statistics against its own forcing set's twins (SPEC 11, issue 34): its W*
    and its model-free feedforward size (``run_size``; ``sizes`` the set's twins' by FB and FF,
    None without forcing lines), each with its p-value and its twins' power."""
    grid = config.selection.w_grid
    lo, hi = float(min(grid)), float(max(grid))
    own = pair.of_run(seed)
    (fb_paths, fb_nb), (ff_paths, ff_nb) = own.paths[method_name]
    fb = np.array([feedforward_threshold(p, n, lo, hi) for p, n in zip(fb_paths, fb_nb, strict=True)])
    ff = np.array([feedforward_threshold(p, n, lo, hi) for p, n in zip(ff_paths, ff_nb, strict=True)])
    w_star = feedforward_threshold(path, nb_ft, lo, hi)
    nan = math.nan
    fourier = (nan, nan, nan)
    if sizes is not None and run_size is not None:
        fourier = (
            run_size,
            evidence_p_value(run_size, sizes["FB"]),
            evidence_power(sizes["FF"], sizes["FB"], alpha),
        )
    return {
        "twins": {"FB": fb, "FF": ff},
        "forcing_set": pair.sets.index(own) + 1,
        "w_star": w_star,
        "p_w_star": evidence_p_value(w_star, fb),
        "power_w_star": evidence_power(ff, fb, alpha),
        "fourier_size": fourier[0],
        "p_fourier": fourier[1],
        "power_fourier": fourier[2],
    }


#: The two statistics of a run's evidence, by name in the tables.
STATISTICS = {"W*": ("p_w_star", "power_w_star"), "Fourier coefficients": ("p_fourier", "power_fourier")}


def _decide(rows: list[dict], alpha: float) -> None:
    """Which statistic decides for a group and method: the one whose twins give the higher median
    power (from the twins alone, before the runs' values are read); each row gets its
    ``decided_by``, ``p_value``, ``power`` and ``evidence``."""
    powers = {
        name: float(np.median([r[pw] for r in rows])) for name, (_, pw) in STATISTICS.items()
        if all(math.isfinite(r[pw]) for r in rows)
    }  # fmt: skip
    chosen = max(powers, key=lambda name: (powers[name], name == "W*"))
    p_col, power_col = STATISTICS[chosen]
    for r in rows:
        r.update(decided_by=chosen, p_value=r[p_col], power=r[power_col],
                 evidence="feedforward" if r[p_col] <= alpha else "none shown")  # fmt: skip


def _evidence_twins(groups: dict, by, evidence: dict) -> pa.Table:
    """The twins' W* each group's runs were judged against, once per group, method and forcing set."""
    rows, done = [], set()
    for key, seeds in groups.items():
        name = ", ".join(f"{f}={v}" for f, v in zip(by, key, strict=True)) or "all runs"
        for (seed, method_name), e in sorted(evidence.items()):
            if seed not in seeds or (name, method_name, e["forcing_set"]) in done:
                continue
            done.add((name, method_name, e["forcing_set"]))
            for twin, values in e["twins"].items():
                rows += [{"group": name, "method": method_name, "forcing_set": e["forcing_set"], "twin": twin,
                          "seed": i + 1, "w_star": float(w)} for i, w in enumerate(values)]  # fmt: skip
    return pa.Table.from_pylist(rows, schema=tables.EVIDENCE_TWINS.arrow)


def _group_verdict(rows: list[dict], alpha: float) -> dict:
    """A group's (or subject's) summary over its runs: k of n with p <= alpha against the binomial,
    the median power, and the verdict word."""
    k, n, p = binomial_summary(np.array([r["p_value"] for r in rows]), alpha)
    power = float(np.median([r["power"] for r in rows]))
    if p <= alpha:
        verdict = "FEEDFORWARD"
    elif power < MIN_POWER:
        verdict = "UNCERTAIN"
    else:
        verdict = "NO FEEDFORWARD SHOWN"
    return {"verdict": verdict, "n_evidence": k, "binomial_p": p, "median_power": power, "alpha": alpha}


def _consistency_columns(check, problem: str) -> dict:
    if check is None:
        nan = math.nan
        return {"fc_chi2": nan, "fc_dof": 0, "fc_p": nan, "fc_verdict": problem, "fc_spread": "",
                "he_error_db": nan, "he_error_deg": nan, "ht_error_db": nan, "ht_error_deg": nan}  # fmt: skip
    return {
        "fc_chi2": check.chi2, "fc_dof": check.dof, "fc_p": check.p, "fc_verdict": check.verdict,
        "fc_spread": check.spread,
        "he_error_db": check.he_db, "he_error_deg": check.he_deg, "ht_error_db": check.ht_db,
        "ht_error_deg": check.ht_deg,
    }  # fmt: skip


def _fc_rows(config: Config, name: str, seeds: list[int], records: dict, median: dict) -> list[dict]:
    """The group's Fourier-coefficient estimates and its fitted model at the same lines."""
    n = round(config.timing.window * config.timing.output_rate)
    rows = slice(0, n)
    base = {"group": name, "n_runs": len(seeds)}
    try:
        fc = fc_estimate([records[s] for s in seeds], config.timing.output_rate, rows)
    except DataError as exc:
        nan = math.nan
        return [{**base, "path": "", "omega": nan, "magnitude_db": nan, "phase_deg": nan, "sd_db": nan,
                 "sd_deg": nan, "extrapolated": False, "model_db": nan, "model_deg": nan,
                 "inversion": nan, "inversion_deg": nan, "inversion_sd": nan, "inversion_sd_deg": nan,
                 "problem": str(exc)}]  # fmt: skip
    yc = plant(config.loop)
    out = []
    inversion = fc.inversion(np.asarray(yc(1j * fc.omega_t), dtype=complex))
    for path, omega, h, extrapolated in (
        ("e", fc.omega_e, fc.he, np.zeros(fc.omega_e.size, dtype=bool)),
        ("ft", fc.omega_t, fc.ht, fc.extrapolated),
    ):
        sd_db, sd_deg = fc.spread(path)
        hft, he = hcfit.hc_response(median, yc, omega)
        model = he if path == "e" else hft
        inv = inversion if path == "ft" else tuple(np.full(omega.size, math.nan) for _ in range(4))
        for i in range(omega.size):
            out.append(
                {**base, "path": path, "omega": float(omega[i]),
                 "magnitude_db": float(20 * np.log10(abs(h[i]))),
                 "phase_deg": float(np.degrees(np.angle(h[i]))), "sd_db": float(sd_db[i]),
                 "sd_deg": float(sd_deg[i]), "extrapolated": bool(extrapolated[i]),
                 "model_db": float(20 * np.log10(abs(model[i]))),
                 "model_deg": float(np.degrees(np.angle(model[i] / h[i])) + np.degrees(np.angle(h[i]))),
                 "inversion": float(inv[0][i]), "inversion_deg": float(inv[1][i]),
                 "inversion_sd": float(inv[2][i]), "inversion_sd_deg": float(inv[3][i]),
                 "problem": ""}
            )  # fmt: skip
    return out


def _write_csv(table: pa.Table, path: str) -> None:
    import pyarrow.csv as pacsv

    pacsv.write_csv(table, path)


@holds_run_dir(create=True)
def analyse_study(
    config: Config,
    run_dir: Path,
    sources: Sequence[str | Path],
    *,
    by: Sequence[str] | None = None,
    twins: int = TWINS,
    ff_twin: str = "auto",
    alpha: float = 0.05,
    fdr: bool = False,
    jobs: int = 2,
    force: bool = False,
    backend: str = "loky",
    scheduler: str | None = None,
    show_progress: bool = True,
) -> AnalysisRun:
    """Analyse a measured study with W calibrated on twins of each group's fitted model (module notes).

    Raises
    ------
    ConfigError
        Without a plant (``loop``), or for a ``by`` factor the data set does not have.
    DataError
        For a bad data set (one line, nothing written).
    """
    if config.loop is None:
        raise ConfigError(
            "loop: missing; `hcid analyse` needs the plant of the experiment (loop.plant and "
            "loop.disturbance_at) for the parametric fit and the twins"
        )
    if not 2 <= twins <= 1000:
        raise ConfigError(f"--twins: must be an integer in [2, 1000], got {twins}")
    if not (isinstance(alpha, float | int) and 0.0 < alpha < 1.0):
        raise ConfigError(f"--alpha: must be a level in (0, 1), got {alpha!r}")
    if ff_twin not in FF_TWINS:
        raise ConfigError(f"--ff-twin: must be one of {', '.join(FF_TWINS)}, got {ff_twin!r}")
    if config.fit_hc.target == "frequency":
        raise ConfigError(
            "fit_hc.target: frequency fits an ARX model's responses, and hcid analyse fits every run "
            "before any model is selected; use time (the default) or closed_loop"
        )
    data = config.data if config.data is not None else default_data()
    files = datasets.data_files(sources, data.pattern)  # a bad set is refused before any work
    factors = [n for n, _ in files[0].factors] + [d for d in (data.dimensions or ()) if d != "sample"]
    taken = sorted(set(factors) & (set(tables.ANALYSIS.names) | set(tables.ANALYSIS_GROUPS.names)))
    if taken:
        raise ConfigError(
            f"factor {taken[0]!r}: the analysis tables have a column of that name; rename the factor "
            "(data.pattern, the manifest's header or data.dimensions)"
        )
    if by is None:
        by = ["condition"] if "condition" in factors else []
    missing = [f for f in by if f not in factors]
    if missing:
        raise ConfigError(
            f"--by {','.join(by)}: the data set has no factor {missing[0]!r} (its factors: "
            f"{', '.join(factors) or 'none'}; name them with data.pattern or a manifest)"
        )
    start = time.perf_counter()
    stages, lap = {}, [start]

    def lap_done(name: str) -> None:
        now = time.perf_counter()
        stages[name], lap[0] = now - lap[0], now

    if force:  # recompute everything, the twins included
        for folder in sorted((run_dir / "twins").glob("*/")) if (run_dir / "twins").is_dir() else []:
            if (folder / folders.MANIFEST).is_file():
                folders.remove_owned(folder)
    names = tuple(methods.METHODS)
    identify_study(config, run_dir, names, data_path=list(sources), jobs=jobs, force=force,
                   backend=backend, scheduler=scheduler, show_progress=show_progress)  # fmt: skip
    lap_done("identify")
    runs = results.read(tables.RUNS, run_dir)
    records = {seed: r for (model, seed), r in _records(run_dir).items() if model == data.name}
    groups = _groups(runs, by)
    kn_rate = twin_rate(config.timing.output_rate)

    # 2. Every run fitted with and without feedforward.
    fitted = {
        seed: (fits, remnant)
        for seed, fits, remnant in parallel_map(
            _fit_run, [(config, s, records[s], kn_rate) for s in sorted(records)], jobs=jobs,
            label="fit runs", show_progress=show_progress, backend=backend, scheduler=scheduler,
        )
    }  # fmt: skip

    lap_done("fit runs")

    # 3. Per group: its model from what its runs determine, the twins and their calibration.
    num_c, den_c = np.array(config.loop.plant.num), np.array(config.loop.plant.den)
    models = {}
    for key, seeds in groups.items():
        try:
            models[key] = group_model([fitted[s][0][True] for s in seeds], [f"run {s}" for s in seeds],
                                      num_c, den_c)  # fmt: skip
        except DataError as exc:
            raise DataError(
                f"group {group_slug(key)}: {exc}; look at its runs' fits or group them otherwise (--by)"
            ) from None
    medians = {key: m.values for key, m in models.items()}
    # The study's strongest feedforward (--ff-twin study and auto): the group with the largest
    # fitted Kpt ("would feedforward of the size seen in this study be found here?").
    strongest = max(medians, key=lambda k: medians[k]["Kpt"])
    twin_args = dict(jobs=jobs, backend=backend, scheduler=scheduler, show_progress=show_progress)
    used = {}  # (group, method) -> TwinSets
    for key, seeds in groups.items():
        remnants = [fitted[s][1] for s in seeds if fitted[s][1] is not None and not fitted[s][1].at_bound]
        if not remnants:
            raise DataError(
                f"group {group_slug(key)}: no run's remnant could be fitted; cannot build its twins"
            )
        remnant = tuple(float(np.median([getattr(r, a) for r in remnants])) for a in ("kn", "w_n", "zeta_n"))
        runs_of_set = forcing_sets(seeds, records, config)  # each set gets twins of its own
        study_model = {**medians[key], **{p: medians[strongest][p] for p in FEEDFORWARD_PARAMETERS}}

        def twins_for(kind, model, key=key, runs_of_set=runs_of_set, remnant=remnant):
            made = [
                calibrate_twins(config, run_dir, key, records[members[0]], model, remnant, twins, kind,
                                kn_rate, i + 1 if len(runs_of_set) > 1 else 0, **twin_args)
                for i, members in enumerate(runs_of_set)
            ]  # fmt: skip
            return pool_twins(kind, made, runs_of_set, config)

        first = "study" if ff_twin == "study" and key != strongest else "own"
        twins_of = {first: twins_for(first, medians[key] if first == "own" else study_model)}
        earlier = twins_of[first]
        if (
            ff_twin == "auto"
            and key != strongest
            and not all(separates(c) for c in earlier.calibrations.values())
        ):
            twins_of["study"] = twins_for("study", study_model)
        for method_name in names:
            # The first twins where they separate; else the last made (study's, or the same).
            use = first if separates(earlier.calibrations[method_name]) else next(reversed(twins_of))
            used[(key, method_name)] = twins_of[use]

    lap_done("twins")

    # 4. Every run selected at its group's W and its selected structure fitted.
    frontier = results.read(tables.FRONTIER, run_dir)
    by_key = tables.split_by_key(frontier, tables.FRONTIER.key)
    stored = _choices(run_dir)
    chosen, tasks, evidence = {}, [], {}
    checks = _Checks(config, records)
    run_sizes = {seed: feedforward_size(data) for seed, data in checks.lines.items()}
    size_cache: dict[str, dict | None] = {}

    def _sizes_of(twin):
        if twin.folder not in size_cache:
            size_cache[twin.folder] = twin_sizes(twin, run_dir, config)
        return size_cache[twin.folder]

    for key, seeds in groups.items():
        for method_name in names:
            w, rule, uncertain = choose_w(used[(key, method_name)].calibrations[method_name])
            chosen[(key, method_name)] = (w, rule, uncertain)
            stage = config.identify.stage(methods.get(method_name).final_stage.name)
            for seed in seeds:
                t = by_key[(data.name, seed, method_name)]
                orders = np.column_stack([t.column(c).to_numpy() for c in tables.ORDER_COLUMNS])
                path = selection.breakpoints(t.column("d").to_numpy(), t.column("v").to_numpy(), orders)
                row = path.at(np.array([w]))[0]
                pair = used[(key, method_name)]
                evidence[(seed, method_name)] = _run_evidence(
                    path, t.column("nb_ft").to_numpy(), pair, seed, method_name, config, alpha,
                    run_sizes.get(seed), _sizes_of(pair.of_run(seed)),
                )  # fmt: skip
                sel = SelectedModel.from_frontier(
                    t,
                    int(row),
                    w,
                    rate=config.timing.output_rate,
                    target_shift=config.identify.target_shift,
                    stage=stage,
                )
                choices = _stage_choices(run_dir, stored, method_name, data.name, seed)
                own = _same_fit(config, sel, fitted[seed][0])  # shared, not fitted twice
                tasks.append((config, seed, records[seed], method_name, sel, choices, own))
            _decide([evidence[(seed, method_name)] for seed in seeds], alpha)
    finals = {
        (seed, method_name): analysis
        for seed, method_name, analysis in parallel_map(
            _final_task, tasks, jobs=jobs, label="fit selected",
            show_progress=show_progress, backend=backend, scheduler=scheduler,
        )
    }  # fmt: skip
    lap_done("fit selected")
    if fdr:  # Benjamini-Hochberg over the study's runs, per method
        for method_name in names:
            keys = [k for k in evidence if k[1] == method_name]
            found = benjamini_hochberg(np.array([evidence[k]["p_value"] for k in keys]), alpha)
            for k, hit in zip(keys, found, strict=True):
                evidence[k] = {**evidence[k], "evidence": "feedforward" if hit else "none shown"}
    group_table, run_table = _tables(
        config, runs, groups, by, used, chosen, finals, twins, models, checks, evidence, alpha
    )
    fc_rows = []
    for key, seeds in groups.items():
        name = ", ".join(f"{f}={v}" for f, v in zip(by, key, strict=True)) or "all runs"
        fc_rows += _fc_rows(config, name, seeds, records, medians[key])
    results.write(
        tables.FC_ESTIMATES, pa.Table.from_pylist(fc_rows, schema=tables.FC_ESTIMATES.arrow), run_dir
    )
    results.write(tables.EVIDENCE_TWINS, _evidence_twins(groups, by, evidence), run_dir)
    results.write(tables.ANALYSIS_GROUPS, group_table, run_dir)
    results.write(tables.ANALYSIS, run_table, run_dir)
    folders.atomic_write(run_dir / "analysis.csv", lambda tmp: _write_csv(run_table, tmp))
    lap_done("tables")
    return AnalysisRun(group_table, run_table, time.perf_counter() - start, run_dir, stages)
