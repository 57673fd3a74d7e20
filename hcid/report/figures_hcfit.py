"""Figures of the parametric HC fit and the residual analysis (report section 10).

Each ``plot_*`` draws data computed by :mod:`hcid.report.sections.hcfit`;
nothing here computes results. No pyplot (see :mod:`hcid.report.figures`).
"""

from __future__ import annotations

import numpy as np
from matplotlib import ticker

from hcid.hcfit import PARAMETERS, UNITS
from hcid.report.figures import _figure, finish_bode, method_color

__all__ = ["plot_parameter_strips", "plot_parametric_bode", "plot_residual_correlations"]


def plot_parameter_strips(
    groups: list[tuple[str, str]],
    estimates: dict[tuple[str, str, str], np.ndarray],
    at_bound: dict[tuple[str, str, str], np.ndarray],
    truths: dict[tuple[str, str], float],
    title: str = "",
    axes=None,
):
    """One panel per parameter: every realization's estimate (dots; crosses at a bound) per
    (model, method) group, the group's true value as a black bar.

    ``estimates[(model, method, parameter)]`` are the estimates across realizations,
    ``truths[(model, parameter)]`` the true values (NaN: none).
    """
    fig, axes = _figure(axes, 2, 4, figsize=(15.0, 7.0))
    x = np.arange(len(groups))
    for ax, name in zip(axes.flat, PARAMETERS, strict=True):
        for i, (model, method) in enumerate(groups):
            values = estimates.get((model, method, name))
            if values is not None and values.size:
                # Deterministic spread across the strip (no random jitter).
                offsets = np.linspace(-0.25, 0.25, values.size) if values.size > 1 else np.zeros(1)
                hit = at_bound.get((model, method, name), np.zeros(values.size, bool))
                color = method_color(method)
                ax.scatter(x[i] + offsets[~hit], values[~hit], s=9, color=color, alpha=0.7)
                if hit.any():
                    ax.scatter(x[i] + offsets[hit], values[hit], s=25, color=color, marker="x")
            true = truths.get((model, name), np.nan)
            if np.isfinite(true):
                ax.hlines(true, x[i] - 0.35, x[i] + 0.35, color="k", lw=2)
        ax.set_title(f"{name} ({UNITS[name]})")
        ax.set_xticks(x, [f"{m}\n{me}" for m, me in groups], fontsize=8)
        ax.grid(True, axis="y", alpha=0.3)
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def plot_parametric_bode(omega, band, curves: list[tuple[str, str, dict, dict]], title: str = "", axes=None):
    """ARX paths (thin, the method's colour) and the parametric model's (dashed black) per run.

    ``curves`` holds ``(run label, method, arx, par)`` with ``arx`` and ``par``
    mapping 'hft'/'he' to complex responses on ``omega`` (None: no path).
    """
    names = {"hft": "feedforward Hft (u per ft)", "he": "feedback He (u per e)"}
    fig, axes = _figure(axes, 2, 2, figsize=(11.0, 6.5), sharex=True)
    for col, path in enumerate(("hft", "he")):
        ax_mag, ax_ph = axes[0, col], axes[1, col]
        labelled = set()
        for _run, method, arx, par in curves:
            for kind, h in (("ARX", arx.get(path)), ("parametric", par.get(path))):
                if h is None or not np.any(np.abs(h) > 0):
                    continue
                style = (
                    {"color": method_color(method), "lw": 0.8}
                    if kind == "ARX"
                    else {"color": "k", "ls": "--", "lw": 0.8}
                )
                label = f"{kind} {method}" if kind == "ARX" else kind
                ax_mag.loglog(omega, np.abs(h), label=None if label in labelled else label, **style)
                ax_ph.semilogx(omega, np.degrees(np.unwrap(np.angle(h))), **style)
                labelled.add(label)
        finish_bode(ax_mag, ax_ph, band, names[path])
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def plot_residual_correlations(
    series: list[tuple[str, np.ndarray, np.ndarray, float]], title: str = "", axes=None
):
    """One panel per series: correlation against lag (s), the white-residual band shaded.

    ``series`` holds ``(signal, lag_s, correlation, bound)``.
    """
    fig, axes = _figure(axes, 1, max(1, len(series)), figsize=(4.5 * max(1, len(series)), 3.5))
    for ax, (signal, lag_s, values, bound) in zip(axes.flat, series, strict=False):
        outside = np.abs(values) > bound
        ax.axhspan(-bound, bound, color="0.85")
        ax.vlines(lag_s, 0, values, color="C0", lw=1)
        ax.plot(lag_s[outside], values[outside], "o", color="C3", ms=3)
        ax.axhline(0, color="k", lw=0.5)
        kind = "autocorrelation of eps" if signal == "eps" else f"eps vs {signal}"
        ax.set_title(f"{kind} ({outside.mean() * 100:.0f}% outside)")
        ax.set_xlabel("lag (s)")
        ax.grid(True, alpha=0.3)
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def plot_remnant_spectra(
    curves: list[tuple[str, np.ndarray, np.ndarray, np.ndarray]], title: str = "", axes=None
):
    """Remnant densities (rad^2/Hz) against frequency (rad/s), log-log: Welch estimate and fitted filter.

    ``curves`` holds ``(source, omega, psd, psd_fit)``.
    """
    fig, axes = _figure(axes, 1, 1, figsize=(6.5, 4.0))
    ax = axes.flat[0]
    for i, (source, omega, psd, fit) in enumerate(curves):
        name = "ARX model" if source == "arx" else "parametric model" if source == "fitted" else source
        ax.loglog(omega, psd, color=f"C{i}", lw=0.8, alpha=0.6, label=f"what the {name} leaves (Welch)")
        ax.loglog(omega, fit, color=f"C{i}", lw=2, label="its fitted remnant filter Yn")
    ax.set_xlabel("frequency (rad/s)")
    ax.set_ylabel("remnant density (rad²/Hz)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def _plain_log_x(ax) -> None:
    """A log x axis with plain numbers (0.02, 0.05, 0.1), not 2x10^-2 and the minor ticks' own
    labels crowding each other: 1-2-5 ticks up to ~3 decades (beyond, they print into each
    other), decades beyond that. Call once the data are drawn (it reads the limits)."""
    ax.set_xscale("log")
    decades = np.log10(ax.get_xlim()[1] / ax.get_xlim()[0])
    ax.xaxis.set_major_locator(ticker.LogLocator(subs=(1.0, 2.0, 5.0) if decades <= 3.2 else (1.0,)))
    ax.xaxis.set_major_formatter(ticker.FuncFormatter(lambda x, _: f"{x:g}"))
    ax.xaxis.set_minor_formatter(ticker.NullFormatter())


def plot_fc(paths: dict[str, list[dict]], curves: dict, title: str = "", axes=None):
    """Bode plot of the model-free estimates (points with their spread across runs) and the
    fitted model on a dense grid (lines, phase unwrapped from low frequency): He at the
    disturbance lines, Ht at the target lines. Each point's phase is taken within 180 deg of
    the model's at its frequency.

    ``paths`` maps ``e`` and ``ft`` to rows of ``fc_estimates.parquet``; ``curves`` holds
    ``omega`` and the model's ``e`` and ``ft`` responses (``ft`` None without feedforward).
    """
    fig, axes = _figure(axes, 2, 1, figsize=(7.5, 7.5), sharex=True)
    ax_mag, ax_ph = axes[0][0], axes[1][0]
    labels = {"e": "He (u per e), disturbance lines", "ft": "Ht (u per ft), target lines"}
    for (path, rows), color in zip(paths.items(), ("C0", "C1"), strict=False):
        label = labels.get(path, path)
        model = curves.get(path)
        phase_model = None
        if model is not None:
            phase_model = np.degrees(np.unwrap(np.angle(model)))
            ax_mag.plot(
                curves["omega"],
                20 * np.log10(np.abs(model)),
                "-",
                color=color,
                lw=1.2,
                label=f"{label}: the group's model",
            )
            ax_ph.plot(curves["omega"], phase_model, "-", color=color, lw=1.2)
        if not rows:
            continue
        w = np.array([r["omega"] for r in rows])
        mag = np.array([r["magnitude_db"] for r in rows])
        ph = np.array([r["phase_deg"] for r in rows])
        if phase_model is not None:
            near = np.interp(np.log(w), np.log(curves["omega"]), phase_model)
            ph = ph + 360.0 * np.round((near - ph) / 360.0)
        else:
            ph = np.degrees(np.unwrap(np.radians(ph)))
        sd_db = np.array([r["sd_db"] for r in rows])
        sd_deg = np.array([r["sd_deg"] for r in rows])
        ax_mag.plot(w, mag, "o", color=color, ms=4, label=f"{label}: model-free")
        ax_ph.plot(w, ph, "o", color=color, ms=4)
        if np.isfinite(sd_db).any():  # the estimates' spread across runs as a band
            ax_mag.fill_between(
                w, mag - sd_db, mag + sd_db, color=color, alpha=0.2, lw=0, label=f"{label}: ±1 sd across runs"
            )
            ax_ph.fill_between(w, ph - sd_deg, ph + sd_deg, color=color, alpha=0.2, lw=0)
    ax_mag.set_ylabel("magnitude (dB)")
    ax_ph.set_ylabel("phase (deg)")
    ax_ph.set_xlabel("frequency (rad/s)")
    for ax in (ax_mag, ax_ph):
        _plain_log_x(ax)
        ax.grid(True, which="both", alpha=0.3)
    # Below the axes, so that no label covers a point or a band.
    fig.legend(*ax_mag.get_legend_handles_labels(), fontsize=7, loc="lower center", ncol=2)
    fig.suptitle(title)
    fig.tight_layout(rect=(0, 0.1, 1, 1))
    return fig


def plot_inversion(rows: list[dict], title: str = "", axes=None):
    """Model inversion ``Ht Yc`` at the target lines (rows of ``fc_estimates.parquet`` with path
    ``ft``): magnitude (linear, 1 the plant's exact inverse, 0.5 half of it) of the coefficient
    average (circles) beside the median of the runs' own (diamonds, bars from the 25% to the 75%
    quartile; tables before these columns: the average alone), and phase of the average with
    +-1 sd across runs; open markers where He was held beyond the disturbance lines."""
    fig, axes = _figure(axes, 2, 1, figsize=(7.5, 6.5), sharex=True)
    ax_mag, ax_ph = axes[0][0], axes[1][0]

    def column(name):
        return np.array([r.get(name, np.nan) for r in rows], dtype=float)

    w, mag, ph = column("omega"), column("inversion"), column("inversion_deg")
    sd_deg = column("inversion_sd_deg")
    median, q25, q75 = column("inversion_median"), column("inversion_q25"), column("inversion_q75")
    held = np.array([bool(r["extrapolated"]) for r in rows])
    for mask, face, label in (
        (~held, "C1", "coefficient average (He interpolated between disturbance lines)"),
        (held, "white", "coefficient average (He held beyond the disturbance lines: less sure)"),
    ):
        if not mask.any():
            continue
        style = {"fmt": "o", "color": "C1", "mfc": face, "ms": 6, "capsize": 3}
        ax_mag.plot(w[mask], mag[mask], "o", color="C1", mfc=face, ms=6, label=label)
        ax_ph.errorbar(w[mask], ph[mask], yerr=np.where(np.isfinite(sd_deg), sd_deg, 0.0)[mask], **style)
    if np.isfinite(median).any():
        beside = w * 1.07  # just right of the average at the same line
        ax_mag.errorbar(
            beside,
            median,
            yerr=np.vstack([median - q25, q75 - median]),
            fmt="D",
            color="0.25",
            ms=4.5,
            capsize=2,
            lw=1,
            label="median of the runs' own (bar: 25% to 75% of runs)",
        )
    ax_mag.axhline(1.0, color="0.3", lw=1, ls="--")
    ax_mag.axhline(0.5, color="0.6", lw=1, ls=":")
    # Named outside the axes, on the right: never over a point.
    right = ax_mag.get_yaxis_transform()
    for y, name, grey in ((1.0, "exact\ninverse", "0.3"), (0.5, "half", "0.5")):
        ax_mag.text(1.01, y, name, transform=right, va="center", fontsize=8, color=grey, clip_on=False)
    ax_ph.axhline(0.0, color="0.3", lw=1, ls="--")
    ax_mag.set_ylabel("|Ht Yc| (-)")
    shown = np.concatenate([mag, median])
    top = max(1.9, float(np.nanmax(shown)) * 1.25)  # quartile bars may run off the top
    ax_mag.set_ylim(-0.04 * top, top)  # a point at |Ht Yc| = 0 whole, not half cut by the axis
    handles, labels = ax_mag.get_legend_handles_labels()
    fig.legend(handles, labels, fontsize=8, loc="lower center", ncol=1, frameon=False)  # below the data
    ax_ph.set_ylabel("phase of Ht Yc (deg)")
    ax_ph.set_xlabel("frequency (rad/s)")
    for ax in (ax_mag, ax_ph):
        _plain_log_x(ax)
        ax.grid(True, which="both", alpha=0.3)
    fig.suptitle(title)
    fig.tight_layout(rect=(0, 0.02 + 0.03 * len(labels), 1, 1))
    return fig


#: The most factors a run's name on the evidence figure gives (the run table has them all).
_NAMED_FACTORS = 3


def run_labels(runs: list[dict], factors: list[str]) -> list[dict]:
    """The runs (rows of ``analysis.parquet``), each with its ``label`` on :func:`plot_evidence`:
    its number and the ``factors`` that differ between the runs (e.g. ``run 1: dp, trial +1``; a
    number-like value with its factor's name), at most :data:`_NAMED_FACTORS`."""
    varying = [f for f in factors if len({str(r[f]) for r in runs}) > 1][:_NAMED_FACTORS]

    def value(f: str, v) -> str:
        text = str(v)
        return f"{f} {text}" if text.lstrip("+-").replace(".", "", 1).isdigit() else text

    def name(r: dict) -> str:
        return f"run {r['run_id']}" + (": " + ", ".join(value(f, r[f]) for f in varying) if varying else "")

    return [{**r, "label": name(r)} for r in runs]


#: The evidence figure's rows: the twins' jitter about their row, and the height of one row
#: (inches; a run's name in 7-point type, with room).
_TWIN_JITTER = 0.25
_ROW_INCHES = 0.2


def plot_evidence(twins: list[dict], runs: list[dict], title: str = "", alpha: float = 0.05, axes=None):
    """Each run's feedforward threshold W* on its forcing set's twins (SPEC 11): per forcing set a
    row of its FB twins' W* (what a person without feedforward shows), one of its FF twins' (what
    one with the group's feedforward shows), then one row per run, named on the axis by its
    ``label`` (else its ``run_id``) and filled where its W*'s p-value is at most alpha. A row per
    run: a number beside a marker among others is not read as whose it is (issue 46).

    ``twins``: rows of ``evidence_twins.parquet`` for one group and method; ``runs``: its rows of
    ``analysis.parquet`` (``forcing_set``, ``w_star``, ``p_w_star``, ``run_id``, optionally
    ``label``). On the figure's own axes, tall enough for a row per run; on a caller's ``axes``,
    their size is the caller's."""
    sets = sorted({r["forcing_set"] for r in runs})
    rows = sum(2 + sum(r["forcing_set"] == fs for r in runs) for fs in sets)
    fig, axes = _figure(axes, 1, 1, figsize=(8.0, 1.6 + _ROW_INCHES * (rows + len(sets))))
    ax = axes[0][0]
    rng = np.random.default_rng(0)  # a fixed jitter: the same picture for the same tables
    ticks, labels, y = [], [], 0.0
    for i, fs in enumerate(sets):
        named = f"set {fs}: " if len(sets) > 1 else ""
        for twin, color in (("FB", "0.55"), ("FF", "C0")):
            w = np.array([t["w_star"] for t in twins if t["forcing_set"] == fs and t["twin"] == twin])
            w = w[np.isfinite(w)]  # an FB twin drawn for the Fourier statistic only has no W*
            jitter = rng.uniform(-_TWIN_JITTER, _TWIN_JITTER, w.size)
            label = f"{twin} twins" if i == 0 else None
            ax.plot(w, y + jitter, "o", color=color, ms=3.5, alpha=0.7, label=label)
            ticks.append(y)
            labels.append(f"{named}{w.size} {twin} twins")
            y -= 1.0
        for r in (r for r in runs if r["forcing_set"] == fs):
            hit = r["p_w_star"] <= alpha
            ax.plot(r["w_star"], y, "D", color="C3", mfc="C3" if hit else "white", ms=6)
            ax.axhline(y, color="0.9", lw=0.6, zorder=0)  # the eye from the name to its marker
            ticks.append(y)
            labels.append(str(r.get("label") or r["run_id"]))
            y -= 1.0
        y -= 1.0  # a blank row between forcing sets
    ax.plot([], [], "D", color="C3", ms=6, label=f"run, p(W*) <= {alpha:g}")
    ax.plot([], [], "D", color="C3", mfc="white", ms=6, label=f"run, p(W*) > {alpha:g}")
    ax.set_yticks(ticks)
    ax.set_yticklabels(labels, fontsize=7)
    ax.set_ylim(y + 0.5, 0.7)
    _plain_log_x(ax)
    ax.set_xlabel("W* (largest W keeping feedforward, -)")
    ax.grid(True, axis="x", which="both", alpha=0.3)
    bottom = 0.42 / fig.get_figheight()  # the legend's band, in inches whatever the height
    fig.legend(*ax.get_legend_handles_labels(), fontsize=7, loc="lower center", ncol=4)
    fig.suptitle(title)
    fig.tight_layout(rect=(0, bottom, 1, 1))
    return fig
