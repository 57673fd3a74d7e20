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


#: Rows of a forcing set in the evidence figure (FB twins, FF twins, runs) and the room for its
#: runs' numbers above them, in data units; the runs' markers' jitter about their row.
_SET_ROWS = 4.0
_RUN_JITTER = 0.12
#: The runs' numbers: font size, and their offsets (points) above the runs' row, tried in this
#: order: the lowest clears a diamond (half-height 0.71 x 7 pt) at the top of its jitter.
_LABEL_FONT = 7.0
_LABEL_LANES = (13.0, 22.5, 32.0)
#: Points per data unit the lanes need: the highest lane's numbers clear of the next set's FB twins.
_MIN_POINTS_PER_ROW = 23.0


def plot_evidence(twins: list[dict], runs: list[dict], title: str = "", alpha: float = 0.05, axes=None):
    """Each run's feedforward threshold W* on its forcing set's twins (SPEC 11): the FB twins'
    W* (what a person without feedforward shows), the FF twins' (what one with the group's
    feedforward shows) and the runs' (filled where their W*'s p-value is at most alpha), one row of
    each per forcing set, each twins' row labelled with its count.

    ``twins``: rows of ``evidence_twins.parquet`` for one group and method; ``runs``: its rows of
    ``analysis.parquet`` (``forcing_set``, ``w_star``, ``p_w_star``, ``run_id``). The runs' numbers
    print clear of each other and of the twins (:func:`_label_runs`); on the figure's own axes, made
    tall enough for that, not on a caller's ``axes``, whose size is the caller's."""
    own = axes is None
    sets = sorted({r["forcing_set"] for r in runs})
    fig, axes = _figure(axes, 1, 1, figsize=(8.0, 1.2 + 1.4 * len(sets)))
    ax = axes[0][0]
    rng = np.random.default_rng(0)  # a fixed jitter: the same picture for the same tables
    ticks, labels = [], []
    for i, fs in enumerate(sets):
        base = _SET_ROWS * i
        for offset, twin, color in ((0.0, "FB", "0.55"), (1.0, "FF", "C0")):
            w = np.array([t["w_star"] for t in twins if t["forcing_set"] == fs and t["twin"] == twin])
            w = w[np.isfinite(w)]  # an FB twin drawn for the Fourier statistic only has no W*
            ax.plot(
                w,
                base + offset + rng.uniform(-0.25, 0.25, w.size),
                "o",
                color=color,
                ms=4,
                alpha=0.7,
                label=f"{twin} twins" if i == 0 else None,
            )
            ticks.append(base + offset)
            labels.append(f"set {fs}: {w.size} {twin} twins")
        mine = [r for r in runs if r["forcing_set"] == fs]
        y = base + 2.0 + rng.uniform(-_RUN_JITTER, _RUN_JITTER, len(mine))
        for r, yy in zip(mine, y, strict=True):
            hit = r["p_w_star"] <= alpha
            ax.plot(r["w_star"], yy, "D", color="C3", mfc="C3" if hit else "white", ms=7, label=None)
        ticks.append(base + 2.0)
        labels.append(f"set {fs}: runs")
    ax.plot([], [], "D", color="C3", ms=7, label=f"runs, p(W*) <= {alpha:g}")
    ax.plot([], [], "D", color="C3", mfc="white", ms=7, label=f"runs, p(W*) > {alpha:g}")
    ax.set_yticks(ticks)
    ax.set_yticklabels(labels, fontsize=8)
    ax.set_ylim(-0.7, _SET_ROWS * (len(sets) - 1) + 3.8)  # room for the runs' numbers above their row
    _plain_log_x(ax)
    ax.set_xlabel("W* (largest W keeping feedforward, -)")
    ax.grid(True, axis="x", which="both", alpha=0.3)
    fig.legend(*ax.get_legend_handles_labels(), fontsize=7, loc="lower center", ncol=4)
    fig.suptitle(title)
    fig.tight_layout(rect=(0, 0.12, 1, 1))
    for _ in range(3 if own else 0):  # tall enough for the numbers' lanes
        low, high = ax.get_ylim()
        per_row = ax.get_window_extent().height * 72.0 / fig.dpi / (high - low)
        if per_row >= _MIN_POINTS_PER_ROW:
            break
        fig.set_figheight(fig.get_figheight() * 1.02 * _MIN_POINTS_PER_ROW / per_row)
        fig.tight_layout(rect=(0, 0.12, 1, 1))
    for i, fs in enumerate(sets):  # the runs' numbers, laid out once the axes have their size
        _label_runs(ax, [r for r in runs if r["forcing_set"] == fs], _SET_ROWS * i + 2.0)
    return fig


def _label_runs(ax, runs: list[dict], row: float) -> None:
    """Each run's number beside its W* above the runs' row of a forcing set, in the first lane
    (:data:`_LABEL_LANES`) where it prints clear of the numbers placed before it (runs from the
    smallest W* up); where every lane is taken, in the lane whose last number ends first, moved
    right to start after it (past the last run, beyond the axes' right edge if need be). No number
    prints over another or over a marker."""
    fig = ax.figure
    width = ax.get_window_extent().width * 72.0 / fig.dpi  # the axes' width in points
    low, high = np.log10(ax.get_xlim())
    ends = [-np.inf] * len(_LABEL_LANES)
    gap = 3.0
    drawn = [r for r in runs if np.isfinite(r["w_star"]) and r["w_star"] > 0]
    for r in sorted(drawn, key=lambda r: (r["w_star"], str(r["run_id"]))):
        text = str(r["run_id"])
        at = (np.log10(r["w_star"]) - low) / (high - low) * width  # the marker, in points
        start = at + 4.0
        free = [k for k, end in enumerate(ends) if end + gap <= start]
        lane = free[0] if free else int(np.argmin(ends))
        start = max(start, ends[lane] + gap)
        ends[lane] = start + 0.65 * _LABEL_FONT * len(text)
        offset = (start - at, _LABEL_LANES[lane])
        ax.annotate(
            text,
            (r["w_star"], row),
            xytext=offset,
            textcoords="offset points",
            fontsize=_LABEL_FONT,
            va="center",
        )
