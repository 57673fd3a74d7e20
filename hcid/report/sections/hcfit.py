"""10. Parametric HC model of the selected models, and their residuals (``hcid fit-hc``, SPEC 8)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pyarrow as pa
import pyarrow.compute  # noqa: F401  (pa.compute)

from hcid import methods
from hcid.hcfit import PARAMETERS, UNITS, hc_response
from hcid.io.results import split_by_key
from hcid.loop.hcmodel import plant
from hcid.pipeline.summary import summarise_fits
from hcid.report import compute as calc
from hcid.report import figures_hcfit
from hcid.report.document import Doc
from hcid.selection.calibration import clopper_pearson

TITLE = "10. Parametric HC model (SPEC 8) and residuals"


@dataclass(frozen=True)
class HCFitSection:
    target: str
    w_text: str
    bias_rows: list[list[str]]
    strips: list[tuple[str, tuple]] = field(default_factory=list)
    measured_rows: list[list[str]] = field(default_factory=list)
    spread_rows: list[list[str]] = field(default_factory=list)
    bode: list[tuple[str, np.ndarray, tuple, list]] = field(default_factory=list)
    residual: tuple[str, list] | None = None
    residual_rows: list[list[str]] = field(default_factory=list)
    not_fitted: int = 0
    at_bound: int = 0
    covariance: str = ""
    loop_rows: list[list[str]] = field(default_factory=list)
    spectrum: tuple[str, list] | None = None


def _num(x: float, digits: int = 4) -> str:
    return "-" if x is None or not math.isfinite(x) else f"{x:.{digits}g}"


def _vaf(x: float) -> str:
    """A VAF in percent, in fixed notation (a poor model's -29380.0, never -2.938e+04)."""
    return "-" if x is None or not math.isfinite(x) else f"{x:.1f}"


def _with_se(value: float, se: float, at_bound: bool) -> str:
    """``0.75 +- 0.02``; ``*`` on a bound (no standard error there)."""
    if at_bound:
        return _num(value) + "*"
    return _num(value) + (f" ± {_num(se, 2)}" if se is not None and math.isfinite(se) else "")


def _rank(run):
    models = [m.name for m in run.config.models]
    names = list(methods.METHODS)
    return lambda k: (
        models.index(k[0]) if k[0] in models else len(models),
        names.index(k[1]) if k[1] in names else len(names),
        *k[2:],
    )


def bias_rows(params: pa.Table, order) -> list[list[str]]:
    """Per simulated model, method, W and parameter: n, true, mean, bias, sd, RMSE (% of true),
    the standard errors against the spread, the 95% intervals' coverage (with its exact 95% band)
    and the estimates at a bound."""
    rows = []
    found = {k: f for k, f in summarise_fits(params).items() if f.scored}
    for key in sorted(found, key=lambda k: (*order(k[:2]), k[2], PARAMETERS.index(k[3]))):
        model, method, w, name = key
        f = found[key]
        pct = f.true != 0
        if f.n_se:
            lo, hi = clopper_pearson(np.array([f.covered]), f.n_se)
            coverage = f"{f.covered}/{f.n_se} ({100 * lo[0]:.0f}-{100 * hi[0]:.0f}%)"
        else:
            coverage = "-"
        rows.append(
            [
                model,
                method,
                f"{w:.4g}",
                name,
                UNITS[name],
                str(f.fitted),
                _num(f.true),
                _num(f.mean),
                f"{f.percent(f.bias):+.1f}" if pct else _num(f.bias, 3),
                f"{f.percent(f.sd):.1f}" if pct else _num(f.sd, 3),
                f"{f.percent(f.rmse):.1f}" if pct else _num(f.rmse, 3),
                _num(f.rms_se, 3),
                _num(f.se_ratio, 3),
                coverage,
                str(f.at_bound),
            ]
        )
    return rows


def _strips(params: pa.Table, order, models: set[str]) -> list[tuple[str, tuple]]:
    simulated = params.filter(
        pa.compute.and_(
            pa.compute.is_in(params.column("model"), pa.array(sorted(models), pa.string())),
            pa.compute.equal(params.column("status"), "fitted"),
        )
    )
    out = []
    for (w_source,), t in split_by_key(simulated, ("w_source",)).items():
        estimates, hits, truths = {}, {}, {}
        for (model, method, _w, name), g in split_by_key(t, ("model", "method", "w", "parameter")).items():
            estimates[(model, method, name)] = g.column("estimate").to_numpy()
            hits[(model, method, name)] = g.column("at_bound").to_numpy(zero_copy_only=False).astype(bool)
            truths[(model, name)] = g.column("true_value")[0].as_py()
        groups = sorted({k[:2] for k in estimates}, key=order)
        out.append((w_source, (groups, estimates, hits, truths)))
    return out


def _measured(run, params: pa.Table, name: str):
    rows, spread, bode = [], [], []
    t = params.filter(pa.compute.equal(params.column("model"), name))
    if t.num_rows == 0:
        return rows, spread, bode
    by_fit = split_by_key(t, ("seed", "method", "w"))
    for (seed, method, w), g in by_fit.items():
        names = g.column("parameter").to_pylist()
        values = dict(zip(names, g.column("estimate").to_pylist(), strict=True))
        ses = dict(zip(names, g.column("se").to_pylist(), strict=True))
        hit = dict(zip(names, g.column("at_bound").to_pylist(), strict=True))
        first = g.slice(0, 1).to_pylist()[0]
        rows.append(
            [str(seed), method, f"{w:.4g}", f"{first['nb_ft']}"]
            + [_with_se(values[p], ses[p], hit[p]) if p in values else "-" for p in PARAMETERS]
            + [_vaf(first["vaf_validation"]), _vaf(first["vaf_arx_validation"])]
        )
    for (method, w, p), g in split_by_key(t, ("method", "w", "parameter")).items():
        x = g.column("estimate").to_numpy()
        x = x[np.isfinite(x)]
        if x.size:
            sd = float(np.std(x, ddof=1)) if x.size > 1 else math.nan
            spread.append(
                [method, f"{w:.4g}", p, UNITS[p], str(x.size), _num(float(np.mean(x))), _num(sd, 3)]
            )
    spread.sort(key=lambda r: (r[0], r[1], PARAMETERS.index(r[2])))
    # Bode: every run's ARX model against its parametric model, per method and W.
    frontier = run.frontier.filter(pa.compute.equal(run.frontier.column("model"), name))
    omega = calc.frequency_grid()
    yc = plant(run.config.loop)
    for (method, w), g in split_by_key(t, ("method", "w")).items():
        resp = calc.compute_responses(
            frontier.filter(pa.compute.equal(frontier.column("method"), method)),
            run.config,
            {method: w},
            omega,
        )
        curves = []
        seeds = list(dict.fromkeys(g.column("seed").to_pylist()))
        for i, seed in enumerate(seeds):
            fit = g.filter(pa.compute.equal(g.column("seed"), seed))
            values = dict(
                zip(fit.column("parameter").to_pylist(), fit.column("estimate").to_pylist(), strict=True)
            )
            if not all(math.isfinite(v) for v in values.values()):
                continue
            hft_par, he_par = hc_response(values, yc, omega)
            arx = {"hft": resp.hft[(name, method)][i], "he": resp.he[(name, method)][i]}
            curves.append((str(seed), method, arx, {"hft": hft_par, "he": he_par}))
        bode.append((f"{name}, {method}, W = {w:.4g}", omega, resp.band, curves))
    return rows, spread, bode


def _shown_record(run, res: pa.Table) -> tuple | None:
    """The record whose residuals and remnant are drawn: the first measured run if any, else the
    first feedforward model's first seed; the first method and W."""
    keys = list(split_by_key(res.select(["model", "seed", "method", "w"]), ("model", "seed", "method", "w")))
    data = run.config.data.name if run.config.data is not None else None
    ff = [m.name for m in run.config.models if m.has_feedforward]
    key = next((k for k in keys if k[0] == data), None) or next((k for k in keys if k[0] in ff), None)
    return key or (keys[0] if keys else None)


def _residual(run, res: pa.Table, key):
    """The residual correlations of the record ``key`` (model, seed, method, w)."""
    if key is None:
        return None
    mask = None
    for col, value in zip(("model", "seed", "method", "w"), key, strict=True):
        m = pa.compute.equal(res.column(col), value)
        mask = m if mask is None else pa.compute.and_(mask, m)
    t = res.filter(mask)
    series = []
    for (signal,), g in split_by_key(t, ("signal",)).items():
        series.append(
            (
                signal,
                g.column("lag_s").to_numpy(),
                g.column("correlation").to_numpy(),
                g.column("bound")[0].as_py(),
            )
        )
    first = t.slice(0, 1).to_pylist()[0]
    title = (
        f"{key[0]} seed/run {key[1]}, {key[2]}, W = {key[3]:.4g}: selected (na, nb_ft, nb_e, nk_ft, nk_e) = "
        f"({first['na']}, {first['nb_ft']}, {first['nb_e']}, {first['nk_ft']}, {first['nk_e']})"
    )
    return title, series


def _residual_rows(res: pa.Table, order) -> list[list[str]]:
    """Per model, method, W and series: mean and max over records of the share of lags outside the band."""
    cols = ["model", "seed", "method", "w", "signal"]
    shares: dict[tuple, list[float]] = {}
    # share_outside repeats on every lag of a series: one value per record and series.
    for key, t in split_by_key(res.select([*cols, "share_outside"]), cols).items():
        shares.setdefault((key[0], key[2], key[3], key[4]), []).append(t.column("share_outside")[0].as_py())
    rows = []
    for key in sorted(shares, key=lambda k: (*order(k[:2]), k[2], k[3])):
        x = np.array(shares[key])
        rows.append(
            [*key[:2], f"{key[2]:.4g}", key[3], str(x.size), f"{100 * x.mean():.1f}", f"{100 * x.max():.1f}"]
        )
    return rows


def loop_rows(loop: pa.Table, order) -> list[list[str]]:
    """Per model, method, W and source: records, crossover and phase margin (mean +- sd, and the
    true loop's), the variance shares of u and the fitted remnant filter (means)."""
    rows = []
    groups = split_by_key(loop, ("model", "method", "w", "source"))
    for key in sorted(groups, key=lambda k: (*order(k[:2]), k[2], k[3])):
        t = groups[key]

        def stat(column, digits=3, t=t):
            x = t.column(column).to_numpy()
            x = x[np.isfinite(x)]
            if not x.size:
                return "-"
            sd = f" ± {_num(float(np.std(x, ddof=1)), 2)}" if x.size > 1 else ""
            return _num(float(np.mean(x)), digits) + sd

        true_wc, true_pm = t.column("true_crossover")[0].as_py(), t.column("true_phase_margin")[0].as_py()
        rows.append(
            [
                key[0],
                key[1],
                f"{key[2]:.4g}",
                key[3],
                str(t.num_rows),
                stat("crossover"),
                _num(true_wc),
                stat("phase_margin"),
                _num(true_pm, 3),
                stat("share_ft", 2),
                stat("share_e", 2),
                stat("share_remnant", 2),
                stat("remnant_kn", 3),
                stat("remnant_w_n", 3),
                stat("remnant_zeta_n", 2),
            ]
        )
    return rows


def _spectrum(run, key) -> tuple[str, list] | None:
    """The remnant spectra (ARX and fitted) of the record the residual figure shows."""
    t = run.remnant_spectrum
    if t is None or t.num_rows == 0 or key is None:
        return None
    mask = None
    for col, value in zip(("model", "seed", "method", "w"), key, strict=True):
        m = pa.compute.equal(t.column(col), value)
        mask = m if mask is None else pa.compute.and_(mask, m)
    t = t.filter(mask)
    curves = [
        (source, g.column("omega").to_numpy(), g.column("psd").to_numpy(), g.column("psd_fit").to_numpy())
        for (source,), g in split_by_key(t, ("source",)).items()
    ]
    title = f"{key[0]} seed/run {key[1]}, {key[2]}, W = {key[3]:.4g}"
    return (title, curves) if curves else None


def compute(run, done) -> HCFitSection | None:
    params, res = run.hc_parameters, run.residuals
    if params is None or params.num_rows == 0:
        return None
    order = _rank(run)
    models = {m.name for m in run.config.models}
    simulated = params.filter(pa.compute.is_in(params.column("model"), pa.array(sorted(models), pa.string())))
    w_pairs = sorted(
        set(
            zip(
                params.column("method").to_pylist(),
                params.column("w").to_pylist(),
                params.column("w_source").to_pylist(),
                strict=True,
            )
        )
    )
    measured_rows, spread, bode = ([], [], [])
    if run.config.data is not None and run.frontier is not None:
        measured_rows, spread, bode = _measured(run, params, run.config.data.name)
    status = params.column("status").to_pylist()
    shown = _shown_record(run, res) if res is not None and res.num_rows else None
    covariances = sorted({c for c in params.column("covariance").to_pylist() if c})
    return HCFitSection(
        target=params.column("target")[0].as_py(),
        w_text=", ".join(f"{m} W = {w:.4g} ({s})" for m, w, s in w_pairs),
        bias_rows=bias_rows(simulated, order),
        strips=_strips(params, order, models),
        measured_rows=measured_rows,
        spread_rows=spread,
        bode=bode,
        residual=_residual(run, res, shown),
        residual_rows=_residual_rows(res, order) if res is not None and res.num_rows else [],
        not_fitted=sum(1 for s in status if s != "fitted"),
        at_bound=int(np.count_nonzero(params.column("at_bound").to_numpy(zero_copy_only=False))),
        covariance=", ".join(covariances),
        loop_rows=loop_rows(run.hc_loop, order) if run.hc_loop is not None else [],
        spectrum=_spectrum(run, shown),
    )


def render(data: HCFitSection | None, doc: Doc) -> None:
    if data is None:
        return
    doc.text(f"## {TITLE}")
    doc.text(
        f"The parametric HC model (SPEC 1, 8: Kpe, TL, tau_pe, w_nms, zeta_nms; Kpt, TI, tau_pt when the "
        f"selected model has a feedforward path) fitted to each selected model by the **{data.target}** "
        f"target at {data.w_text}. Standard errors: {data.covariance or '-'} (docs/parametric-fit.md); "
        f"95% intervals are estimate ± 1.96 se. Estimates on a bound are counted (and marked * below; "
        f"no standard error there): {data.at_bound} parameter estimates at a bound; {data.not_fitted} "
        f"parameter rows not fitted."
    )
    _render_parameters(data, doc)
    _render_loop(data, doc)
    _render_residuals(data, doc)


def _render_parameters(data: HCFitSection, doc: Doc) -> None:
    """The estimates' accuracy (simulations) or the runs' parameters (measured data)."""
    if data.bias_rows:
        doc.text(
            "Simulations: bias, spread and RMSE of the estimates across realizations (in % of the true "
            "value; in the parameter's unit where the true value is 0), the standard errors' RMS "
            "beside it (se/sd near 1 when they are right) and how many 95% intervals hold the true "
            "value, with the exact 95% band of that share."
        )
        doc.table(
            [
                "model",
                "method",
                "W",
                "parameter",
                "unit",
                "n",
                "true",
                "mean",
                "bias %",
                "sd %",
                "RMSE %",
                "se",
                "se/sd",
                "95% CI covers",
                "at bound",
            ],
            data.bias_rows,
        )
    for w_source, (groups, estimates, hits, truths) in data.strips:
        doc.figure(
            f"hc_parameters_{w_source.replace(' ', '_').replace('-', '')}.png",
            f"Estimates across realizations at {w_source} (dots; x = at a bound), true values black.",
            lambda g=groups, e=estimates, h=hits, t=truths, s=w_source: figures_hcfit.plot_parameter_strips(
                g, e, h, t, title=f"parametric HC fit at {s}"
            ),
        )
    if data.measured_rows:
        doc.text(
            "Measured data: parameters per run with their standard errors (* = at a bound), VAF (%) of "
            "the parametric and ARX models on the validation rows."
        )
        doc.table(["run", "method", "W", "nb_ft", *PARAMETERS, "VAF par.", "VAF ARX"], data.measured_rows)
        doc.table(["method", "W", "parameter", "unit", "runs", "mean", "sd"], data.spread_rows)


def _render_loop(data: HCFitSection, doc: Doc) -> None:
    """The loop each model implies, its remnant spectrum and its responses."""
    if data.loop_rows:
        doc.text(
            "The loop each model implies (SPEC 8): crossover frequency and phase margin of He·Yc "
            "(mean ± sd over records; the true loop's beside them for simulations), the shares of "
            "var(u) through the target path, the error path and what they leave (the remnant ratio), "
            "and SPEC 1's remnant filter fitted to the remnant's spectrum (Kn for unit white noise at "
            "the simulation rate). Source arx: the selected ARX model; fitted: the parametric model."
        )
        doc.table(
            [
                "model",
                "method",
                "W",
                "source",
                "n",
                "wc (rad/s)",
                "true wc",
                "PM (deg)",
                "true PM",
                "ft share",
                "e share",
                "remnant share",
                "Kn",
                "w_n",
                "zeta_n",
            ],
            data.loop_rows,
        )
    if data.spectrum is not None:
        title, curves = data.spectrum
        doc.figure(
            "hc_remnant.png",
            f"Remnant spectrum of {title}: what the ARX and the fitted models leave of u (Welch), "
            "and the remnant filter fitted to each.",
            lambda c=curves, t=title: figures_hcfit.plot_remnant_spectra(c, title=t),
        )
    for i, (title, omega, band, curves) in enumerate(data.bode):
        doc.figure(
            f"hc_bode_{i}.png",
            f"{title}: each run's selected ARX model and its fitted parametric model.",
            lambda o=omega, b=band, c=curves, t=title: figures_hcfit.plot_parametric_bode(o, b, c, title=t),
        )


def _render_residuals(data: HCFitSection, doc: Doc) -> None:
    """The selected models' residual correlations."""
    if data.residual_rows:
        doc.text(
            "Residuals of the selected models (simulation residual on the validation rows): share of lags "
            "outside the 99% band of a white residual, mean and max over records (ft_s: the shifted target "
            "the model sees; e: e_r for the indirect method; about 1% expected if white and independent)."
        )
        doc.table(
            ["model", "method", "W", "series", "records", "mean % outside", "max % outside"],
            data.residual_rows,
        )
    if data.residual is not None:
        title, series = data.residual
        doc.figure(
            "hc_residuals.png",
            f"Residual correlations of {title}; grey: 99% band of a white residual.",
            lambda s=series, t=title: figures_hcfit.plot_residual_correlations(s, title=t),
        )
