"""Figures of the report, drawn with matplotlib from :mod:`hcid.report.compute` data.

Each ``plot_*`` takes computed data and draws it; nothing here computes results.
Figures are :class:`matplotlib.figure.Figure` objects made without pyplot, so
no global backend or figure registry is touched.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib import colormaps, ticker
from matplotlib.figure import Figure

from hcid.io import folders
from hcid.methods import METHODS
from hcid.report.compute import Curves, Responses

__all__ = [
    "plot_bode",
    "plot_calibration",
    "plot_data_structure",
    "plot_errors",
    "plot_forcing_spectra",
    "plot_nb_ft",
    "plot_rate_curves",
    "plot_rates",
    "plot_signals",
    "plot_vaf",
    "save",
]

STYLES = {0: "-", 1: "--"}
DPI = 110


def method_color(method: str) -> str:
    """A method's colour in every figure: tab10 in registry order (direct blue, indirect orange)."""
    names = list(METHODS)
    index = names.index(method) if method in names else len(names) + sum(map(ord, method)) % 5
    return f"C{index % 10}"


def methods_in(keys) -> list[str]:
    """The methods among ``(model, method)`` keys, registered ones first in registry order."""
    found = {k[1] for k in keys}
    return [m for m in METHODS if m in found] + sorted(found - set(METHODS))


def save(fig, path) -> None:
    """Write ``fig`` as a PNG atomically, as one of its folder's hcid files (:mod:`hcid.io.folders`)."""
    path = Path(path)
    folders.atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=DPI, bbox_inches="tight", format="png"))


def _figure(axes, rows: int, cols: int, *, figsize, sharex: bool = False):
    """``(figure, 2-D array of axes)``: new ones, or the caller's ``axes`` (rows x cols)."""
    if axes is None:
        fig = Figure(figsize=figsize)
        return fig, fig.subplots(rows, cols, squeeze=False, sharex=sharex)
    axes = np.asarray(axes, dtype=object).reshape(rows, cols)
    return axes.flat[0].figure, axes


def finish_bode(ax_mag, ax_ph, band, title: str) -> None:
    """Band edges, grid, labels and legend of one path's magnitude and phase axes."""
    for ax in (ax_mag, ax_ph):
        for w in band:
            ax.axvline(w, color="0.5", ls="--", lw=0.8)
        ax.grid(True, which="both", alpha=0.3)
    ax_mag.set_title(title)
    ax_mag.set_ylabel("magnitude (-)")
    ax_ph.set_ylabel("phase (deg)")
    ax_ph.set_xlabel("frequency (rad/s)")
    if ax_mag.get_yscale() == "log":
        plain_log(ax_mag.yaxis)
    if ax_mag.get_legend_handles_labels()[0]:
        ax_mag.legend(fontsize=8, loc="best")


def plain_log(axis) -> None:
    """A log axis labelled in plain numbers (0.5, 2, 10), not 2x10^0; over less than about 1.5
    decades its 2, 3 and 5 are labelled too, else only the decades."""
    lo, hi = sorted(abs(v) for v in axis.get_view_interval())
    axis.set_major_formatter(ticker.FuncFormatter(lambda v, _: f"{v:g}"))

    def minor(v, _):
        mantissa = round(v / 10 ** np.floor(np.log10(v)), 6)
        return f"{v:g}" if mantissa in (2.0, 3.0, 5.0) else ""

    short = lo > 0 and hi / lo < 10**1.5
    axis.set_minor_formatter(ticker.FuncFormatter(minor) if short else ticker.NullFormatter())


def _key_label(model: str, method: str) -> str:
    return f"{model} {method}"


def _w_lines(ax, marks: dict[str, float]) -> None:
    """Vertical lines at marked W values; a method's marks take its colour."""
    for i, (label, w) in enumerate(marks.items()):
        if w is not None and np.isfinite(w) and w > 0:
            words = label.split()
            color = next((method_color(m) for m in METHODS if m in words), "0.3")
            ax.axvline(w, color=color, ls=[":", "--", "-.", (0, (3, 1, 1, 1))][i % 4], lw=1.2, label=label)


def plot_vaf(curves: Curves, marks: dict[str, float], axes=None):
    """Paper Fig. 5: mean VAF +- sd of the selected models vs W, small-W and full-range panels.

    Draws on ``axes`` (two) when given, else on a new figure; returns the figure. Every
    ``plot_*`` here takes its axes the same way.
    """
    fig, axes = _figure(axes, 1, 2, figsize=(11, 4.2))
    axes = axes.ravel()
    models = sorted({k[0] for k in curves.vaf_mean})
    for ax, (lo, hi) in zip(axes, [(curves.w[0], 0.1), (curves.w[0], curves.w[-1])], strict=True):
        sel = (curves.w >= lo) & (curves.w <= hi)
        for (model, method), mean in sorted(curves.vaf_mean.items()):
            sd = curves.vaf_sd[(model, method)]
            ls = STYLES[models.index(model) % 2]
            ax.plot(curves.w[sel], mean[sel], ls, color=method_color(method), label=_key_label(model, method))
            ax.fill_between(
                curves.w[sel], (mean - sd)[sel], (mean + sd)[sel], color=method_color(method), alpha=0.15
            )
        _w_lines(ax, marks)
        ax.set_xscale("log")
        ax.set_xlabel("W (penalty per parameter, -)")
        ax.set_ylabel("VAF of selected model (%)")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_title("(a) small W: VAF, mean +- sd")
    axes[1].set_title("(b) full range")
    lows = [m[(curves.w < 0.1)].min() for m in curves.vaf_mean.values()]
    axes[0].set_ylim(min(lows) - 2 if lows else 90, 100.5)
    axes[1].legend(fontsize=8, loc="lower left")
    return fig


def plot_nb_ft(curves: Curves, marks: dict[str, float], ax=None):
    """Paper Fig. 6: mean nb_ft of the selected models vs W, with W_FP and W_FN."""
    fig, ax = _figure(ax, 1, 1, figsize=(8, 4.2))
    ax = ax.ravel()[0]
    models = sorted({k[0] for k in curves.nb_ft_mean})
    for (model, method), mean in sorted(curves.nb_ft_mean.items()):
        ls = STYLES[models.index(model) % 2]
        ax.plot(curves.w, mean, ls, color=method_color(method), label=_key_label(model, method))
    _w_lines(ax, marks)
    ax.axhline(2.0, color="0.6", lw=0.8)
    ax.set_xscale("log")
    ax.set_xlabel("W (penalty per parameter, -)")
    ax.set_ylabel("mean nb_ft of selected models (-)")
    ax.set_title("Feedforward found vs W (nb_ft = 0: no feedforward; >= 2 needed for a differentiator)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    return fig


def _bode_axes(ax_mag, ax_ph, omega, h, color, label, alpha):
    for i, row in enumerate(h):
        ax_mag.loglog(omega, np.abs(row), color=color, lw=0.6, alpha=alpha, label=label if i == 0 else None)
        ax_ph.semilogx(omega, np.degrees(np.unwrap(np.angle(row))), color=color, lw=0.6, alpha=alpha)


def plot_bode(
    responses: Responses,
    model: str,
    truths: dict[str, np.ndarray],
    references: dict[str, tuple[str, np.ndarray]] | None = None,
    paths: tuple[str, ...] = ("hft", "he"),
    title: str = "",
    axes=None,
):
    """Paper Figs. 7-9: selected models of every realization (thin lines) against the truth.

    ``truths[path]`` is the true response of ``path`` ('hft' or 'he');
    ``references`` adds other dashed curves, e.g. the FF feedforward with Kpt = 0.2.
    """
    names = {"hft": "feedforward Hft (u per ft)", "he": "feedback He (u per e)"}
    fig, axes = _figure(axes, 2, len(paths), figsize=(max(8.0, 5.5 * len(paths)), 6.5), sharex=True)
    omega = responses.omega
    for col, path in enumerate(paths):
        ax_mag, ax_ph = axes[0, col], axes[1, col]
        for method in methods_in(getattr(responses, path)):
            h = getattr(responses, path).get((model, method))
            if h is None:
                continue
            keep = np.any(np.abs(h) > 0, axis=1)
            if keep.any():
                _bode_axes(
                    ax_mag, ax_ph, omega, h[keep], method_color(method), f"{method} ({int(keep.sum())})", 0.5
                )
        true = truths.get(path)
        if true is not None and np.any(np.abs(true) > 0):
            ax_mag.loglog(omega, np.abs(true), "k", lw=2, label="true")
            ax_ph.semilogx(omega, np.degrees(np.unwrap(np.angle(true))), "k", lw=2)
        for label, ref in (references or {}).get(path, []):
            ax_mag.loglog(omega, np.abs(ref), "k--", lw=1.5, label=label)
            ax_ph.semilogx(omega, np.degrees(np.unwrap(np.angle(ref))), "k--", lw=1.5)
        finish_bode(ax_mag, ax_ph, responses.band, names[path])
    fig.suptitle(title, parse_math=False)  # user strings are not mathtext
    fig.tight_layout()
    return fig


def plot_errors(
    omega: np.ndarray,
    errors: dict[tuple[str, str], dict[str, np.ndarray]],
    band: tuple[float, float],
    title: str,
    axes=None,
):
    """Paper Fig. 10: mean and max magnitude and phase errors per method; dashed: the disturbance band.

    ``errors[(path, method)]`` comes from :func:`hcid.report.compute.compute_errors`.
    """
    fig, axes = _figure(axes, 2, 2, figsize=(11, 6.5), sharex=True)
    names = {"hft": "feedforward", "he": "feedback"}
    for col, path in enumerate(("hft", "he")):
        for method in methods_in(errors):
            err = errors.get((path, method))
            if err is None:
                continue
            c = method_color(method)
            axes[0, col].loglog(omega, err["mag_mean"], color=c, label=f"{method} mean")
            axes[0, col].loglog(omega, err["mag_max"], color=c, ls="--", label=f"{method} max")
            axes[1, col].semilogx(omega, err["phase_mean"], color=c)
            axes[1, col].semilogx(omega, err["phase_max"], color=c, ls="--")
        axes[0, col].set_title(f"{names[path]} path")
        axes[0, col].set_ylabel("| |H| - |Htrue| | (-)")
        axes[1, col].set_ylabel("|phase error| (deg)")
        axes[1, col].set_xlabel("frequency (rad/s)")
        axes[1, col].set_ylim(0, 180)
        for ax in axes[:, col]:
            for w in band:
                ax.axvline(w, color="0.5", ls="--", lw=0.8)
            ax.grid(True, which="both", alpha=0.3)
        if axes[0, col].get_legend_handles_labels()[0]:
            axes[0, col].legend(fontsize=8)
    fig.suptitle(title, parse_math=False)  # user strings are not mathtext
    fig.tight_layout()
    return fig


def plot_forcing_spectra(spectra: dict[str, tuple[np.ndarray, np.ndarray]], nyquist: float, axes=None):
    """Amplitude spectra of the forcing functions (deg vs rad/s, log-log); lines below 1e-6 of the
    peak are left out."""
    fig, axes = _figure(axes, 1, 1, figsize=(9, 3.8))
    ax = axes[0, 0]
    for i, (name, (w, amp)) in enumerate(spectra.items()):
        keep = amp > 1e-6 * max(amp.max(), 1e-300)
        ax.vlines(w[keep], 1e-6, np.degrees(amp[keep]), color=f"C{i}", lw=0.8)
        ax.plot(w[keep], np.degrees(amp[keep]), "o", ms=3, color=f"C{i}", label=name)
    ax.axvline(nyquist, color="k", ls=":", lw=0.8, label="analysis Nyquist")
    ax.set_xscale("log")
    ax.set_yscale("log")
    peaks = [np.degrees(a.max()) for _, a in spectra.values() if a.size]
    if peaks:
        ax.set_ylim(max(peaks) * 1e-4, max(peaks) * 2)
    ax.set_xlabel("frequency (rad/s)")
    ax.set_ylabel("amplitude (deg)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def plot_signals(t: np.ndarray, channels: dict[str, np.ndarray], title: str, axes=None):
    """One record: target, system output, error and control, in deg."""
    fig, axes = _figure(axes, 2, 1, figsize=(11, 5.5), sharex=True)
    axes = axes.ravel()
    for name in ("ft", "theta", "e"):
        if name in channels:
            axes[0].plot(t, np.degrees(channels[name]), lw=0.9, label=name)
    if "fd" in channels:
        axes[0].plot(t, 3 * np.degrees(channels["fd"]), lw=0.7, label="fd x 3")
    axes[0].set_ylabel("angle (deg)")
    axes[0].legend(fontsize=8, ncol=4, loc="upper right")
    axes[1].plot(t, np.degrees(channels["u"]), lw=0.7, label="u")
    if "n" in channels:
        axes[1].plot(t, np.degrees(channels["n"]), lw=0.7, label="remnant n")
    axes[1].set_ylabel("control (deg)")
    axes[1].set_xlabel("time (s)")
    axes[1].legend(fontsize=8, loc="upper right")
    for ax in axes:
        ax.grid(True, alpha=0.3)
    fig.suptitle(title, parse_math=False)  # user strings are not mathtext
    fig.tight_layout()
    return fig


def plot_data_structure(data, marks: dict[str, float], name: str, axes=None):
    """Measured runs: selected nb_ft, d and VAF vs W, per method (lines per run)."""
    methods = methods_in(data.values)
    fig, axes = _figure(axes, 3, len(methods), figsize=(5.5 * len(methods), 8), sharex=True)
    runs = sorted({k[0] for k in data.values})
    for col, method in enumerate(methods):
        for i, run in enumerate(runs):
            v = data.values.get((run, method))
            if v is None:
                continue
            style = dict(lw=1.2, color=colormaps["viridis"](i / max(len(runs) - 1, 1)), label=f"run {run}")
            axes[0, col].step(v["w"], v["nb_ft"], where="post", **style)
            axes[1, col].step(v["w"], v["d"], where="post", **style)
            axes[2, col].plot(v["w"], v["vaf_estimation"], **style)
        axes[0, col].set_title(f"{name}: {method} method", parse_math=False)
        axes[0, col].set_ylabel("selected nb_ft (-)")
        axes[1, col].set_ylabel("selected d (-)")
        axes[2, col].set_ylabel("VAF (%)")
        axes[2, col].set_xlabel("W (penalty per parameter, -)")
        for ax in axes[:, col]:
            ax.set_xscale("log")
            ax.grid(True, which="both", alpha=0.3)
            _w_lines(ax, {k: w for k, w in marks.items() if method in k or "BIC" in k})
        axes[0, col].legend(fontsize=8)
    fig.tight_layout()
    return fig


def plot_calibration(table, name: str, axes=None, used: dict[str, float] | None = None):
    """False-positive (FB twin) and false-negative (FF twin) rates vs W with 95% bands,
    the safe interval shaded and the recommended W marked, one panel per method; ``used``
    marks, per method, a W chosen otherwise (the least total error where no W is safe)."""
    methods = methods_in((None, m) for m in table.column("method").to_pylist())
    fig, axes = _figure(axes, 1, len(methods), figsize=(5.8 * len(methods), 5.2))
    rows = table.to_pylist()
    fig.suptitle(name)
    for ax, method in zip(axes[0], methods, strict=True):
        r = [x for x in rows if x["method"] == method]
        w = np.array([x["w"] for x in r])
        for prefix, color, label in (
            ("fp", "tab:red", "false-positive rate (FB twin)"),
            ("fn", "tab:purple", "false-negative rate (FF twin)"),
        ):
            rate = np.array([x[f"{prefix}_rate"] for x in r])
            ax.step(w, rate, where="post", color=color, label=label)
            ax.fill_between(
                w,
                [x[f"{prefix}_low"] for x in r],
                [x[f"{prefix}_high"] for x in r],
                step="post",
                color=color,
                alpha=0.15,
            )
        lo, hi, rec = r[0]["safe_low"], r[0]["safe_high"], r[0]["recommended"]
        if lo < hi:
            span = (max(lo, w[0]), min(hi, w[-1]))
            ax.axvspan(*span, color="tab:green", alpha=0.12, label=f"safe interval [{lo:.3g}, {hi:.3g})")
            for edge in span:  # its edges drawn: a narrow interval is not hidden under the W line
                ax.axvline(edge, color="tab:green", lw=0.9, ls="--")
        if np.isfinite(rec):
            ax.axvline(rec, color="tab:green", lw=1.2, label=f"recommended W = {rec:.3g}")
        elif used is not None and method in used:
            ax.axvline(
                used[method],
                color="0.2",
                lw=2,
                ls="--",
                label=f"W used = {used[method]:.3g} (least total error; no safe W)",
            )
        ax.axhline(r[0]["target_rate"], color="0.4", lw=0.8, ls=":")
        ax.set_xscale("log")
        ax.set_ylim(-0.02, 1.02)
        ax.set_xlabel("W (penalty per parameter, -)")
        ax.set_ylabel("rate over realizations (-)")
        ax.set_title(f"{method} method ({r[0]['n_fb']} + {r[0]['n_ff']} realizations)", parse_math=False)
        ax.grid(True, which="both", alpha=0.3)
        _legend_below(ax)
    fig.tight_layout()
    return fig


def _legend_below(ax) -> None:
    """The axes' legend under its x label, never over the data."""
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=2, frameon=False)


def plot_rates(table, marks: dict[str, float], name: str, axes=None):
    """Error rates over W with exact 95% bands (``rates.parquet``), one panel per method: the
    false-positive rate of each model without feedforward, the false-negative rate of each with it."""
    methods = methods_in((None, m) for m in table.column("method").to_pylist())
    fig, axes = _figure(axes, 1, len(methods), figsize=(5.8 * len(methods), 5.6))
    rows = table.to_pylist()
    fig.suptitle(name)
    colors = {"false_positive": "tab:red", "false_negative": "tab:purple"}
    words = {"false_positive": "false-positive rate", "false_negative": "false-negative rate"}
    for ax, method in zip(axes[0], methods, strict=True):
        models = list(dict.fromkeys(x["model"] for x in rows if x["method"] == method))
        for i, model in enumerate(models):
            r = [x for x in rows if x["method"] == method and x["model"] == model]
            w = np.array([x["w"] for x in r])
            error = r[0]["error"]
            color = colors.get(error, "0.3")
            ax.step(
                w,
                [x["rate"] for x in r],
                STYLES[i % 2],
                where="post",
                color=color,
                label=f"{model}: {words.get(error, error)} (n = {r[0]['n']})",
            )
            ax.fill_between(
                w, [x["low"] for x in r], [x["high"] for x in r], step="post", color=color, alpha=0.15
            )
        # Marks of this method, and marks shared by every method (no method named in the label).
        mine = {k: v for k, v in marks.items() if method in k.split() or not set(k.split()) & set(METHODS)}
        _w_lines(ax, mine)
        ax.set_xscale("log")
        ax.set_ylim(-0.02, 1.02)
        ax.set_xlabel("W (penalty per parameter, -)")
        ax.set_ylabel("rate over realizations (-)")
        ax.set_title(f"{method} method")
        ax.grid(True, which="both", alpha=0.3)
        _legend_below(ax)
    fig.tight_layout()
    return fig


def plot_rate_curves(curves: dict[str, dict[str, np.ndarray]], marks: dict[str, float], title: str, ax=None):
    """Several rate curves (``w``, ``rate``, ``low``, ``high`` each) with their bands on one log-W axis."""
    fig, ax = _figure(ax, 1, 1, figsize=(8, 4.3))
    ax = ax.ravel()[0]
    for i, (label, c) in enumerate(curves.items()):
        color = f"C{i % 10}"
        ax.step(c["w"], c["rate"], where="post", color=color, label=label)
        ax.fill_between(c["w"], c["low"], c["high"], step="post", color=color, alpha=0.12)
    _w_lines(ax, marks)
    ax.set_xscale("log")
    ax.set_ylim(-0.02, 1.02)
    ax.set_xlabel("W (penalty per parameter, -)")
    ax.set_ylabel("false-positive rate (-)")
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig
