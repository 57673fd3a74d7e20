"""The ``fit-hc`` stage: parametric HC fit and residual analysis of every selected model.

For every record (simulated realization or measured run) and method in
``frontier.parquet``, the model selected at each requested W is analysed by
:func:`hcid.hcfit.selected.analyse_selected` on the worker pool
(an :class:`~hcid.pipeline.execution.Execution`), one task per record and method.
Writes ``hc_parameters.parquet``, ``residuals.parquet``, ``hc_loop.parquet`` and
``remnant_spectrum.parquet`` (:data:`OUTPUTS`).

Resumable: each finished task is kept in ``RUN/.parts/fit_hc/<settings>/``
until the tables are written; rows already in the tables (or parts) are reused
when they were made with the same fit settings (the ``settings`` digest) and
the same selected model (orders and V equal to the current frontier's
selection at their W). Rows at other W values that are still valid are kept.
Wall times go to ``run_log.parquet`` only, so the tables are identical for any
``jobs``, backend or interruption.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
import shutil
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute  # noqa: F401  (pa.compute)

from hcid import hcfit, methods, tables
from hcid.analysis.descriptors import RemnantFit, fit_remnant
from hcid.config import Config
from hcid.errors import ConfigError, DataError, HcidError, IdentificationError
from hcid.hcfit import FEEDBACK_PARAMETERS, TARGETS, UNITS, parse_fit_settings
from hcid.hcfit.determined import parameter_status
from hcid.hcfit.selected import (
    RESIDUAL_CONFIDENCE,
    RESIDUAL_MAX_LAG,
    SelectedModel,
    analyse_selected,
    true_loop,
    true_parameters,
)
from hcid.io import results
from hcid.loop.hcmodel import plant
from hcid.pipeline.execution import Execution
from hcid.pipeline.rundir import check_run_dir, holds_run_dir, record_config
from hcid.selection import criteria
from hcid.selection.frontier import Frontier

__all__ = ["OUTPUTS", "HCFitRun", "RunFits", "fit_hc_study", "fit_run", "requested_w"]

PARTS = Path(".parts") / "fit_hc"
_KEY = ("model", "seed", "method", "w")
#: The stage's tables, each under its name in the parts folder.
OUTPUTS = {
    "parameters": tables.HC_PARAMETERS,
    "residuals": tables.RESIDUALS,
    "loop": tables.HC_LOOP,
    "spectrum": tables.REMNANT_SPECTRUM,
}


@dataclass(frozen=True)
class HCFitRun:
    """The tables of ``hcid fit-hc`` and what was done.

    ``w_of[method]`` lists the ``(W, source)`` pairs fitted; ``computed`` and
    ``reused`` count (record, method) tasks.
    """

    parameters: pa.Table
    residuals: pa.Table
    loop: pa.Table
    w_of: dict[str, list[tuple[float, str]]]
    computed: int
    reused: int
    seconds: float
    run_dir: Path


def requested_w(
    config: Config, run_dir: Path, method_names: Sequence[str], w_values: Sequence[float] | None
) -> dict[str, list[tuple[float, str]]]:
    """Per method, the W values to analyse and where each came from.

    ``w_values`` if given (source ``--w``); otherwise the method's calibrated W
    from ``calibration.parquet`` when it has one (``calibrated``), else
    ``W_BIC = ln(Nf)/Nf`` with the method's Nf (``W_BIC``).
    """
    if w_values:
        bad = [w for w in w_values if not (math.isfinite(w) and w > 0)]
        if bad:
            raise HcidError(f"w (--w): must be positive numbers, got {bad}")
        return {m: [(float(w), "--w") for w in sorted(set(w_values))] for m in method_names}
    calibration = results.read_optional(tables.CALIBRATION, run_dir, ("method", "recommended"))
    recommended = {}
    if calibration is not None:
        for method, w in zip(
            calibration.column("method").to_pylist(),
            calibration.column("recommended").to_pylist(),
            strict=True,
        ):
            if w is not None and math.isfinite(w) and w > 0:
                recommended[method] = float(w)
    out = {}
    for m in method_names:
        if m in recommended:
            out[m] = [(recommended[m], "calibrated")]
        else:
            out[m] = [(criteria.w_bic(methods.get(m).nf(config.identify)), "W_BIC")]
    return out


def _settings_digest(config: Config) -> str:
    text = repr((config.fit_hc, RESIDUAL_MAX_LAG, RESIDUAL_CONFIDENCE, config.timing.sim_rate))
    return hashlib.sha256(text.encode()).hexdigest()[:12]


# --------------------------------------------------------------------------- inputs


def _records(run_dir: Path) -> dict[tuple[str, int], dict[str, np.ndarray]]:
    out = {}
    sims = results.read_optional(tables.SIMULATIONS, run_dir)
    if sims is not None:
        out.update(results.records(sims, run_dir / tables.SIMULATIONS.file))
    measured = results.read_optional(tables.MEASURED, run_dir)
    if measured is not None:
        for key, t in results.split_by_key(measured, tables.MEASURED.key).items():
            out[key] = {c: t.column(c).to_numpy().astype(np.float64) for c in tables.SIGNALS}
    return out


def stored_choices(run_dir: Path) -> dict[str, dict[tuple[str, int], methods.StageChoice]]:
    """Per choosing stage, its stored choice per (model, seed), read from ``run_dir``."""
    out: dict[str, dict] = {}
    for method in methods.METHODS.values():
        for stage in method.choice_stages:
            table = results.read_optional(tables.stage_choice(stage.name, stage.inputs), run_dir)
            if table is not None:
                out[stage.name] = results.stage_choices_of(table, stage)
    return out


def _selected(frontier: Frontier, ws: list[float], config, method: str) -> list[SelectedModel]:
    rows = frontier.select(ws)
    stage = config.identify.stage(methods.get(method).final_stage.name)
    return [
        SelectedModel.from_frontier(
            frontier,
            int(row),
            w,
            rate=config.timing.output_rate,
            target_shift=config.identify.target_shift,
            stage=stage,
        )
        for w, row in zip(ws, rows, strict=True)
    ]


# --------------------------------------------------------------------------- one task


def _base(key, w_source: str, sel: SelectedModel) -> dict:
    model, seed, method = key
    return {
        "model": model,
        "seed": seed,
        "method": method,
        "w": sel.w,
        "w_source": w_source,
        "na": sel.na,
        "nb_ft": sel.nb_ft,
        "nb_e": sel.nb_e,
        "nk_ft": sel.nk_ft,
        "nk_e": sel.nk_e,
        "v": sel.v,
        "vaf_arx_validation": sel.vaf_validation,
    }


def _parameter_rows(base: dict, fit, settings, truths: dict) -> list[dict]:
    if fit is None:
        fitted = [(n, math.nan, math.nan, (math.nan, math.nan), False) for n in FEEDBACK_PARAMETERS]
        cost = vaf = math.nan
        starts, status, covariance = 0, "no feedback path (nb_e = 0)", ""
        determined = {n: "not fitted" for n in FEEDBACK_PARAMETERS}
    else:
        fitted = [
            (n, v, se, fit.interval(n), hit)
            for n, v, se, hit in zip(fit.names, fit.estimates, fit.se, fit.at_bound, strict=True)
        ]
        determined = parameter_status(fit)
        cost, vaf, starts, status, covariance = (
            fit.cost,
            fit.vaf_validation,
            fit.starts,
            "fitted",
            fit.covariance,
        )
    rows = []
    for name, estimate, se, (low, high), hit in fitted:
        bound = settings.bound(name)
        rows.append(
            {
                **base,
                "status": status,
                "parameter": name,
                "unit": UNITS[name],
                "estimate": estimate,
                "se": se,
                "ci_low": low,
                "ci_high": high,
                "covariance": covariance,
                "true_value": truths.get(name, math.nan),
                "lower": bound.lower,
                "upper": bound.upper,
                "at_bound": hit,
                "parameter_status": determined[name],
                "cost": cost,
                "vaf_validation": vaf,
                "starts": starts,
            }
        )
    return rows


def _loop_rows(base: dict, loop, true_margins: tuple[float, float]) -> tuple[list[dict], list[dict]]:
    rows, spectrum = [], []
    for d in loop:
        r = d.remnant
        rows.append(
            {
                **base,
                "source": d.source,
                "crossover": d.crossover,
                "phase_margin": d.phase_margin,
                "n_crossovers": d.n_crossovers,
                "true_crossover": true_margins[0],
                "true_phase_margin": true_margins[1],
                "share_ft": d.shares["ft"],
                "share_e": d.shares["e"],
                "share_remnant": d.shares["remnant"],
                "remnant_kn": math.nan if r is None else r.kn,
                "remnant_w_n": math.nan if r is None else r.w_n,
                "remnant_zeta_n": math.nan if r is None else r.zeta_n,
                "kn_rate": math.nan if r is None else r.kn_rate,
                "remnant_at_bound": False if r is None else r.at_bound,
            }
        )
        if r is not None:
            key = {k: base[k] for k in _KEY}
            spectrum += [
                {**key, "source": d.source, "omega": float(o), "psd": float(p), "psd_fit": float(q)}
                for o, p, q in zip(r.omega, r.psd, r.psd_fit, strict=True)
            ]
    return rows, spectrum


def _fit_task(config, key, record, todo, choices, truth, digest):
    """One record and method's analyses: ``todo`` its (selected model, source) pairs, ``truth``
    the simulated model's (parameters, loop margins) or ({}, NaNs) for measured data."""
    selected, sources = [s for s, _ in todo], [src for _, src in todo]
    truths, true_margins = truth
    method = methods.get(key[2])
    settings = config.fit_hc
    out = {name: [] for name in OUTPUTS}
    for sel, source in zip(selected, sources, strict=True):
        analysis = analyse_selected(sel, record, config, method, choices)
        base = _base(key, source, sel)
        out["parameters"] += _parameter_rows(
            {**base, "target": analysis.fit.target if analysis.fit else settings.target, "settings": digest},
            analysis.fit,
            settings,
            truths,
        )
        res = analysis.residuals
        shares = {c.signal: c.share_outside for c in res.correlations}
        for row in res.rows():
            out["residuals"].append(
                {
                    **base,
                    **row,
                    "share_outside": shares[row["signal"]],
                    "n": res.n,
                    "confidence": res.confidence,
                }
            )
        loop_rows, spectrum_rows = _loop_rows(base, analysis.loop, true_margins)
        out["loop"] += loop_rows
        out["spectrum"] += spectrum_rows
    return key, {name: pa.Table.from_pylist(out[name], schema=OUTPUTS[name].arrow) for name in OUTPUTS}


# --------------------------------------------------------------------------- reuse


def _groups(found: dict[str, pa.Table | None], digest: str) -> dict:
    """Rows made with these settings, by (model, seed, method, w): ``{table name: rows}``."""
    if any(found.get(name) is None for name in OUTPUTS):
        return {}
    mask = pa.compute.equal(found["parameters"].column("settings"), digest)
    split = {"parameters": results.split_by_key(found["parameters"].filter(mask), _KEY)}
    for name in list(OUTPUTS)[1:]:
        split[name] = results.split_by_key(found[name], _KEY)
    out = {}
    for k, p in split["parameters"].items():
        if k in split["residuals"]:
            out[k] = {
                "parameters": p,
                **{name: split[name].get(k, OUTPUTS[name].arrow.empty_table()) for name in list(OUTPUTS)[1:]},
            }
    return out


def _stored(run_dir: Path) -> dict[str, pa.Table | None]:
    """The stage's tables as written, None for one missing or of an older layout (recomputed)."""
    out = {}
    for name, schema in OUTPUTS.items():
        try:
            out[name] = results.read_optional(schema, run_dir)
        except DataError:
            out[name] = None
    return out


def _read_parts(run_dir: Path, digest: str) -> dict:
    folder = run_dir / PARTS / digest
    found = {}
    if not folder.is_dir():
        return found
    for path in sorted(folder.glob(f"*.parameters{results.PART_SUFFIX}")):
        try:
            tables_of = {
                name: results.read_part_table(path.with_name(path.name.replace(".parameters.", f".{name}.")))
                for name in OUTPUTS
            }
            found.update(_groups(tables_of, digest))
        except (pa.ArrowException, OSError):
            continue  # cut off mid-write: recomputed
    return found


def _valid(group: dict[str, pa.Table], sel: SelectedModel, source: str | None) -> bool:
    """Whether stored rows were made from this selected model (and, if given, W source)."""
    first = group["parameters"].slice(0, 1).to_pylist()[0]
    same = tuple(first[c] for c in tables.ORDER_COLUMNS) == sel.orders and first["v"] == sel.v
    return same and (source is None or first["w_source"] == source)


# --------------------------------------------------------------------------- the stage


def _plan(config, run_dir: Path, by_key: dict, w_of: dict, names: list[str], existing: dict, digest: str):
    """``(tasks, kept, reused)``: the fits to run, the valid rows kept, the record-methods reused."""
    tasks, kept, reused = [], {}, 0
    records = _records(run_dir)
    choices = stored_choices(run_dir)
    for key, frontier in by_key.items():
        model, seed, method_name = key
        # Methods not asked for keep their valid rows (below) and get no new ones.
        pairs = w_of.get(method_name, [])
        todo = []
        for sel, (_, source) in zip(
            _selected(frontier, [w for w, _ in pairs], config, method_name) if pairs else [],
            pairs,
            strict=True,
        ):
            group = existing.get((*key, sel.w))
            if group is not None and _valid(group, sel, source):
                kept[(*key, sel.w)] = group
            else:
                todo.append((sel, source))
        # Rows at other W of this record and method stay while their selection still holds.
        requested = {w for w, _ in pairs}
        others = sorted(k[3] for k in existing if k[:3] == key and k[3] not in requested)
        for sel in _selected(frontier, others, config, method_name) if others else []:
            if _valid(existing[(*key, sel.w)], sel, None):
                kept[(*key, sel.w)] = existing[(*key, sel.w)]
        if not todo:
            reused += method_name in names
            continue
        record = records.get((model, seed))
        if record is None:
            raise DataError(f"{run_dir}: no record of {model}, seed {seed} (simulations or measured data)")
        earlier = stage_choices(run_dir, choices, method_name, model, seed)
        truths, true_margins = {}, (math.nan, math.nan)
        if model in {m.name for m in config.models}:
            truths, true_margins = true_parameters(config, model), true_loop(config, model)
        tasks.append((config, key, record, list(todo), earlier, (truths, true_margins), digest))

    return tasks, kept, reused


def stage_choices(run_dir: Path, choices: dict, method_name: str, model: str, seed: int) -> tuple:
    """The earlier stages' stored choices a method's final stage needs on one record."""
    out = []
    for stage in methods.get(method_name).choice_stages:
        found = choices.get(stage.name, {}).get((model, seed))
        if found is None:
            raise DataError(
                f"{run_dir / (stage.name + '.parquet')}: no {stage.name} choice of {model}, seed {seed}; "
                "rerun `hcid identify`"
            )
        out.append(found)
    return tuple(out)


def _fit_settings(config: Config, target: str | None):
    """The config's fit settings (built in code: the config's disturbance band, SPEC 5), with
    ``target`` (``--target``) over its estimator."""
    settings = config.fit_hc if config.fit_hc is not None else parse_fit_settings(None)
    if settings.band is None:
        settings = dataclasses.replace(settings, band=config.disturbance.band)
    if target is not None:
        if target not in TARGETS:
            raise ConfigError(f"target (--target): must be one of {', '.join(TARGETS)}, got {target!r}")
        settings = dataclasses.replace(settings, target=target)
    return settings


def _write_fit_parts(parts_dir: Path, key: tuple, made: dict) -> None:
    """A finished task's tables as parts, for a resume; parameters last: a part counts once it is there."""
    stem = "__".join(str(k) for k in key)
    for name, table in made.items():
        if name != "parameters":
            results.write_part_table(table, parts_dir / f"{stem}.{name}{results.PART_SUFFIX}")
    results.write_part_table(made["parameters"], parts_dir / f"{stem}.parameters{results.PART_SUFFIX}")


def _write_fits(config: Config, run_dir: Path, by_key: dict, kept: dict) -> dict[str, pa.Table]:
    """The tables of :data:`OUTPUTS` in frontier order, written atomically; the parts removed."""
    order = {k: i for i, k in enumerate(by_key)}
    keys = sorted(kept, key=lambda k: (order.get(k[:3], len(order)), k[3]))
    written = {
        name: results.concat([schema.arrow.empty_table()] + [kept[k][name] for k in keys])
        for name, schema in OUTPUTS.items()
    }
    record_config(config, run_dir)
    for name, schema in OUTPUTS.items():
        results.write(schema, written[name], run_dir)
    shutil.rmtree(run_dir / PARTS, ignore_errors=True)
    return written


@holds_run_dir(create=False)
def fit_hc_study(
    config: Config,
    run_dir: Path,
    method_names: Sequence[str] | None = None,
    w_values: Sequence[float] | None = None,
    *,
    target: str | None = None,
    execution: Execution = Execution(),
    force: bool = False,
) -> HCFitRun:
    """Fit the parametric HC model to, and analyse the residuals of, every selected model.

    For every record and method of ``frontier.parquet`` (``method_names``
    default: every registered method present), the models selected at
    :func:`requested_w` are analysed by :func:`hcid.hcfit.selected.analyse_selected`.
    Writes the tables of :data:`OUTPUTS` atomically;
    reuses valid rows unless ``force``. ``target`` overrides the config's
    ``fit_hc.target``.

    Raises
    ------
    DataError
        If the run has no frontier, or a record or stage choice the frontier
        needs is missing.
    ConfigError
        For a data-only config: the parametric model needs the experiment's plant.
    """
    if config.loop is None:
        raise ConfigError(
            "loop: missing; `hcid fit-hc` needs the plant of the experiment (the fit's feedforward "
            "model inverts it), which a data-only config does not give: add models, loop, signals "
            "and seeds as in configs/integrator_example.yaml"
        )
    config.require_one_plant("`hcid fit-hc`")
    check_run_dir(config, run_dir, "select")
    start = time.perf_counter()
    config = dataclasses.replace(config, fit_hc=_fit_settings(config, target))
    frontier = results.read(tables.FRONTIER, run_dir, hint="run `hcid identify` first")
    results.check_against_config(frontier, config, run_dir / tables.FRONTIER.file)
    by_key = results.frontiers(frontier)
    present = list(dict.fromkeys(k[2] for k in by_key))
    names = [m for m in (method_names or methods.METHODS) if m in present]
    for m in names:
        methods.get(m)
    w_of = requested_w(config, run_dir, names, w_values)
    digest = _settings_digest(config)

    existing = {}
    if not force:
        existing = _groups(_stored(run_dir), digest)
        existing.update(_read_parts(run_dir, digest))
    else:
        shutil.rmtree(run_dir / PARTS, ignore_errors=True)

    tasks, kept, reused = _plan(config, run_dir, by_key, w_of, names, existing, digest)
    parts_dir = run_dir / PARTS / digest
    for key, made in execution.map(_fit_task, tasks, "fit-hc"):
        _write_fit_parts(parts_dir, key, made)
        kept.update(_groups(made, digest))
    written = _write_fits(config, run_dir, by_key, kept)
    seconds = time.perf_counter() - start
    if tasks:
        results.append_run_log(run_dir, f"fit-hc ({len(tasks)} tasks)", seconds, execution.jobs)
    return HCFitRun(
        written["parameters"],
        written["residuals"],
        written["loop"],
        w_of,
        len(tasks),
        reused,
        seconds,
        run_dir,
    )


def fit_windows(config: Config) -> tuple[slice, slice]:
    """The rows every measured run's parametric fits use (``hcid analyse``): the direct method's
    final stage's estimation and validation windows."""
    stage = config.identify.stage(methods.get("direct").final_stage.name)
    return stage.estimation.rows(), stage.validation.rows()


def tracking_record(record: dict, config: Config) -> hcfit.TrackingRecord:
    """A measured run's record for the parametric fits, over :func:`fit_windows`."""
    return hcfit.TrackingRecord(
        record["ft"],
        record["e"],
        record["u"],
        config.timing.output_rate,
        *fit_windows(config),
        fd=record["fd"],
    )


@dataclass(frozen=True)
class RunFits:
    """A measured run's parametric fits with and without its feedforward path (``hcid analyse``)
    and the remnant filter its feedforward fit leaves (None where that could not be fitted)."""

    run: int
    with_ff: hcfit.HCFit
    without_ff: hcfit.HCFit
    remnant: RemnantFit | None

    def of(self, feedforward: bool) -> hcfit.HCFit:
        """The fit with or without the feedforward path."""
        return self.with_ff if feedforward else self.without_ff


def fit_run(config: Config, run: int, record: dict, kn_rate: float) -> RunFits:
    """A measured run's FF and FB fits and the remnant its FF fit leaves."""
    yc = plant(config.loop)
    tracking = tracking_record(record, config)
    settings = config.fit_hc
    with_ff, without_ff = (
        hcfit.fit_parametric(settings, yc, ff, record=tracking, disturbance_at=config.loop.disturbance_at)
        for ff in (True, False)
    )
    rows = slice(tracking.estimation.start, tracking.validation.stop)
    n = record["u"] - hcfit.simulate_hc(with_ff.values, yc, tracking, settings.oversample)
    try:
        remnant = fit_remnant(n[rows], config.timing.output_rate, kn_rate)
    except IdentificationError:
        remnant = None
    return RunFits(run, with_ff, without_ff, remnant)
