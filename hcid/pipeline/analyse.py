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
from hcid.calibration import benjamini_hochberg, rates_at
from hcid.config import Config
from hcid.config.fit import FEEDFORWARD_PARAMETERS
from hcid.config.parse import default_data
from hcid.descriptors import fit_remnant
from hcid.errors import ConfigError, DataError, IdentificationError
from hcid.fourier import fc_estimate
from hcid.hcfit.determined import group_model, parameter_status
from hcid.hcmodel import plant
from hcid.pipeline.evidence import (
    MAX_FB_TWINS,
    MIN_POWER,
    Checks,
    Evidence,
    consistency_columns,
    decide,
    group_name,
    group_verdict,
)
from hcid.pipeline.fit import _choices, _records, _stage_choices
from hcid.pipeline.parallel import labelled, parallel_map
from hcid.pipeline.rundir import holds_run_dir
from hcid.pipeline.studies import identify_study
from hcid.pipeline.twins import (
    calibrate_twins,
    choose_w,
    draw_fb_twins,
    forcing_sets,
    group_slug,
    pool_twins,
    separates,
    twin_rate,
)
from hcid.selected import SelectedModel, analyse_selected

__all__ = ["AnalysisRun", "analyse_study"]

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
    #: Wall seconds per stage: identify, fit runs, twins, more FB twins, fit selected, tables.
    stages: dict[str, float] = field(default_factory=dict)
    #: The files left out because they could not be read: (path, reason).
    set_aside: tuple[tuple[str, str], ...] = ()


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


def _tables(config, runs, groups, by, used, chosen, finals, drawn, models, checks, evidence, alpha):
    twins, fb_drawn = drawn
    group_checks = {key: checks.group(seeds, models[key].values) for key, seeds in groups.items()}
    factors = [c for c in runs.column_names if c not in tables.RUNS.names]
    factor_of = {int(r["seed"]): r for r in runs.to_pylist()}
    group_rows, run_rows = [], []
    for key, seeds in groups.items():
        name = group_name(by, key)
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
                    "data_set": config.data.name, "run_id": seed,
                    "file": str(factor_of[seed]["file"]), "file_run": int(factor_of[seed]["file_run"]),
                    **choice,
                    **dict(zip(tables.ORDER_COLUMNS, sel.orders, strict=True)),
                    "feedforward": bool(sel.nb_ft > 0), "vaf_arx_validation": sel.vaf_validation,
                    "vaf_validation": fit.vaf_validation if fit else math.nan,
                }  # fmt: skip
                status = parameter_status(fit) if fit else {}
                row["estimator"] = fit.target if fit else config.fit_hc.target
                row["hc_form"] = ("nms fixed" if fit.fixed else "full") if fit else ""
                for p in tables.HC_PARAMETER_NAMES:
                    row[p] = values.get(p, math.nan)
                    row[f"{p}_se"] = ses.get(p, math.nan)
                    row[f"{p}_status"] = status.get(p, "not fitted")
                row["crossover"] = fitted_loop.crossover if fitted_loop else math.nan
                row["phase_margin"] = fitted_loop.phase_margin if fitted_loop else math.nan
                row["share_remnant"] = fitted_loop.shares["remnant"] if fitted_loop else math.nan
                row.update(evidence[(seed, method_name)])
                row["evidence_uncertain"] = bool(row["power"] < MIN_POWER)
                check = checks.run(seed, fit) if fit else None
                n_contradicted += bool(check is not None and check.contradicted)
                row.update(consistency_columns(check, checks.problem([seed]) if fit else "not fitted"))
                for f in factors:
                    row[f] = str(factor_of[seed][f])
                run_rows.append(row)
            mine = [evidence[(seed, method_name)] for seed in seeds]
            group_rows.append(
                {**choice, "n_runs": len(seeds), "n_feedforward": int(n_ff), **group_verdict(mine, alpha),
                 "forcing_sets": len(pair.sets), "decided_by": mine[0]["decided_by"],
                 **{f"twin_{p}": pair.model[p] for p in tables.HC_PARAMETER_NAMES},
                 **{f"fitted_{p}": models[key].values[p] for p in tables.HC_PARAMETER_NAMES},
                 "twin_kn": pair.remnant[0], "twin_w_n": pair.remnant[1], "twin_zeta_n": pair.remnant[2],
                 "twins": twins, "fb_twins": fb_drawn[(key, method_name)], "twins_folder": pair.folder,
                 "twin_source": models[key].source, "twin_undetermined": ", ".join(models[key].undetermined),
                 "n_contradicted": int(n_contradicted),
                 **consistency_columns(group_checks[key], checks.problem(seeds))}
            )  # fmt: skip
    schema = tables.ANALYSIS.arrow
    for f in factors:
        schema = schema.append(pa.field(f, pa.string()))
    return (
        pa.Table.from_pylist(group_rows, schema=tables.ANALYSIS_GROUPS.arrow),
        pa.Table.from_pylist(run_rows, schema=schema),
    )


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
    max_fb_twins: int | None = None,
    ff_twin: str = "auto",
    alpha: float = 0.05,
    fdr: bool = False,
    set_aside: Sequence[tuple[str, str]] = (),
    skip_unreadable: bool = False,
    jobs: int = 2,
    force: bool = False,
    backend: str = "loky",
    scheduler: str | None = None,
    show_progress: bool = True,
) -> AnalysisRun:
    """Analyse a measured study with W calibrated on twins of each group's fitted model (module notes).

    ``skip_unreadable``: files that cannot be read or fail their checks (too short for the
    windows, another sample rate, other columns) are left out instead of refusing the set; with
    ``set_aside`` (files the caller already left out, ``(path, reason)``,
    :func:`hcid.resolve.readable_files`) they are written to ``set_aside.parquet`` so that the
    answer and the report list them.

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
    if max_fb_twins is None:  # the default: p down to 0.01, and never fewer than the calibration's
        max_fb_twins = max(MAX_FB_TWINS, twins)
    if not twins <= max_fb_twins <= 10000:
        raise ConfigError(
            f"--max-fb-twins: must be an integer in [--twins ({twins}), 10000], got {max_fb_twins}"
        )
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
    with labelled("runs: "):
        identified = identify_study(
            config, run_dir, names, data_path=list(sources), jobs=jobs, force=force, backend=backend,
            scheduler=scheduler, show_progress=show_progress, skip_unreadable=skip_unreadable,
        )  # fmt: skip
    set_aside = [*set_aside, *identified.set_aside]
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
    used, remnants_of = {}, {}  # (group, method) -> TwinSets; group -> its twins' remnant filter
    for key, seeds in groups.items():
        remnants = [fitted[s][1] for s in seeds if fitted[s][1] is not None and not fitted[s][1].at_bound]
        if not remnants:
            raise DataError(
                f"group {group_slug(key)}: no run's remnant could be fitted; cannot build its twins"
            )
        remnant = tuple(float(np.median([getattr(r, a) for r in remnants])) for a in ("kn", "w_n", "zeta_n"))
        remnants_of[key] = remnant
        runs_of_set = forcing_sets(seeds, records, config)  # each set gets twins of its own
        study_model = {**medians[key], **{p: medians[strongest][p] for p in FEEDFORWARD_PARAMETERS}}

        def twins_for(kind, model, fb_from=None, key=key, runs_of_set=runs_of_set, remnant=remnant):
            made = [
                calibrate_twins(config, run_dir, key, records[members[0]], model, remnant, twins, kind,
                                kn_rate, i + 1 if len(runs_of_set) > 1 else 0,
                                fb_from.sets[i] if fb_from is not None else None, **twin_args)
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
            # The study's FB twin is the own twins' (Kpt = 0: the same loop), shared, not made again.
            twins_of["study"] = twins_for("study", study_model, earlier)
        for method_name in names:
            # The first twins where they separate; else the last made (study's, or the same).
            use = first if separates(earlier.calibrations[method_name]) else next(reversed(twins_of))
            used[(key, method_name)] = twins_of[use]

    lap_done("twins")

    # 4. More FB twins wherever a run's p-value is not settled (sequential, Besag and Clifford).
    frontier = results.read(tables.FRONTIER, run_dir)
    by_key = tables.split_by_key(frontier, tables.FRONTIER.key)
    paths = {}  # (seed, method) -> (its frontier, selection path, nb_ft)
    for seed in records:
        for method_name in names:
            t = by_key[(data.name, seed, method_name)]
            orders = np.column_stack([t.column(c).to_numpy() for c in tables.ORDER_COLUMNS])
            path = selection.breakpoints(t.column("d").to_numpy(), t.column("v").to_numpy(), orders)
            paths[(seed, method_name)] = (t, path, t.column("nb_ft").to_numpy())
    checks = Checks(config, records)
    run_sizes = checks.sizes()
    judge = Evidence(config, run_dir, alpha, max_fb_twins)
    fb_drawn, deciding = {}, {}
    for key in groups:
        name, sets = group_name(by, key), used[(key, names[0])].runs
        deciding[key] = {m: judge.statistic(used[(key, m)], m) for m in names}
        for i, members in enumerate(sets):
            twin_of = {m: used[(key, m)].sets[i] for m in names}
            values = [
                ({m: judge.w_star(*paths[(s, m)][1:]) for m in names}, run_sizes.get(s)) for s in members
            ]
            while (drawn := judge.drawn(name, i + 1, twin_of[names[0]])) < max_fb_twins:
                open_methods, fourier_open = judge.unsettled(name, i + 1, twin_of, deciding[key], values)
                if not (open_methods or fourier_open):
                    break
                judge.add(name, i + 1, draw_fb_twins(
                    config, run_dir, key, records[members[0]], medians[key], remnants_of[key], kn_rate,
                    i + 1 if len(sets) > 1 else 0, drawn + 1, min(twins, max_fb_twins - drawn), open_methods,
                    **twin_args,
                ))  # fmt: skip
            for m in names:
                if deciding[key][m] == "W*":
                    n = judge.fb_thresholds(name, i + 1, twin_of[m], m).size
                else:
                    n = judge.drawn(name, i + 1, twin_of[m])
                fb_drawn[(key, m)] = max(fb_drawn.get((key, m), 0), n)
    lap_done("more FB twins")

    # 5. Every run selected at its group's W and its selected structure fitted.
    stored = _choices(run_dir)
    chosen, tasks, evidence = {}, [], {}
    for key, seeds in groups.items():
        for method_name in names:
            w, rule, uncertain = choose_w(used[(key, method_name)].calibrations[method_name])
            chosen[(key, method_name)] = (w, rule, uncertain)
            stage = config.identify.stage(methods.get(method_name).final_stage.name)
            for seed in seeds:
                t, path, nb_ft = paths[(seed, method_name)]
                row = path.at(np.array([w]))[0]
                evidence[(seed, method_name)] = judge.run(
                    group_name(by, key), path, nb_ft, used[(key, method_name)], seed, method_name,
                    run_sizes.get(seed), deciding[key][method_name],
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
            decide([evidence[(seed, method_name)] for seed in seeds], alpha, deciding[key][method_name])
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
        config, runs, groups, by, used, chosen, finals, (twins, fb_drawn), models, checks, evidence, alpha
    )
    fc_rows = []
    for key, seeds in groups.items():
        name = group_name(by, key)
        fc_rows += _fc_rows(config, name, seeds, records, medians[key])
    results.write(
        tables.FC_ESTIMATES, pa.Table.from_pylist(fc_rows, schema=tables.FC_ESTIMATES.arrow), run_dir
    )
    results.write(tables.EVIDENCE_TWINS, judge.twins_table(groups, by, evidence), run_dir)
    aside = [{"file": f, "reason": why} for f, why in set_aside]
    results.write(tables.SET_ASIDE, pa.Table.from_pylist(aside, schema=tables.SET_ASIDE.arrow), run_dir)
    results.write(tables.ANALYSIS_GROUPS, group_table, run_dir)
    results.write(tables.ANALYSIS, run_table, run_dir)
    folders.atomic_write(run_dir / "analysis.csv", lambda tmp: _write_csv(run_table, tmp))
    lap_done("tables")
    return AnalysisRun(group_table, run_table, time.perf_counter() - start, run_dir, stages,
                       tuple((str(f), str(why)) for f, why in set_aside))  # fmt: skip
