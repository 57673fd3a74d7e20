"""Independent reference computation for the CPHS 2017 whole-experiment data.

Written with numpy + scipy only, without importing (or reading) the ``hcid``
package, so that it can be used to check hcid's figures on
``/work/shared/data/cphs2017-sessions/`` (SPEC section 12, "A whole experiment").

Usage::

    .venv/bin/python benchmarks/cphs_sessions_reference.py [--data DIR] [--out FILE.json]

Every choice made
-----------------
Files
  * Trials: ``{subject}/*_su17v3_{plant}_r-{tgt}_d-{dis}_s49_p{P}a{A}_{sign}.csv``;
    ``_rst1``/``_rst2`` reset segments, ``desktop.ini`` and ``.npz`` are ignored.
    Each subject has 60 trials (30 per plant), every (plant, assay, phase set,
    sign) once.
  * Columns (after the '#' lines): 0 time, 1 realtime, 2 ``ref`` = target r,
    3 ``inp`` = u, 4 ``dis`` = d, 5 plant output x (``so`` rows also hold x' in
    column 6, unused).  Error e = r - x.
  * Window: rows 300..2699 (t = 5.000 .. 44.983 s; 2400 samples = two 20 s
    periods at 60 Hz).  (The study used the last 2400 rows, 302..2701; a
    2-sample shift changes no ratio.)
  * Fourier coefficients: ``rfft`` of the raw (not detrended) window divided
    by N = 2400; line k (k * 2 pi / 20 rad/s) is DFT bin 2k.
    fo: k = 2 3 5 7 11 13 17 19 23 29 31; so: k = 2 3 5 7 11 13 17.
    E = even-indexed lines (k = 2 5 11 17 23 31 / so 2 5 11 17),
    O = odd-indexed (3 7 13 19 29 / so 3 7 13).
  * The line sets of each trial are taken from its file name and checked
    against the data (an input is "present" at a line when its power there
    is > 1e-6 of the largest line power of the other input, SPEC 12); the script
    stops if a file disagrees with its name.
Plants (disturbance at the plant input, x = M (u + d)), continuous-time M at
  the line frequencies w = 2 pi k / 20: fo M = 1/(jw), so M = 1/(jw (jw + 1)).
  A check of X / (M (U + D)) from the data is printed (how well the recorded
  plant matches the continuous M at the lines).
Per-trial responses
  * H_UR = U / R at the trial's target lines, H_UD = U / D at its disturbance
    lines.  A ratio undoes any sign flip (sos-, the file's -1) by itself.
Averaging over the trials of a condition (primary: as the study did)
  * "mean of ratios": the complex mean of the per-trial ratios.
  * variant "H1": sum_trials U conj(R) / sum_trials |R|^2 (the ratio of
    averaged cross- to auto-spectra; equivalent to averaging coefficients with
    signs and phase sets undone).  Within a condition every trial has the same
    |R| (|D|) at a line (sign flips and phase sets change phases only), so H1
    equals the mean of ratios (to ~1e-5 in |F M|, float rounding of the
    recorded forcing); the script prints the largest difference instead of a
    second table (both are in the JSON).
Single-input estimates
  * H_UR from the 10 a3 trials (target only, all lines), H_UD from the 10 a1
    trials (disturbance only, all lines).
Two-input ("pairs") estimates
  * primary "all": H_UR at E lines from a0 + a4 + a6 (6 trials: E-target),
    at O lines from a2 + a5 (4 trials); H_UD at O lines from a0 + a4 + a6, at
    E lines from a2 + a5.  This is the study's pairing (its "Evenid" = every
    two-input trial whose target is sos+E or sos-E; "Oddid" = sos+O / sos-O),
    complex mean of per-trial ratios.
  * variants by assay set: "a0a2" (a0 + a2, 2 + 2 trials), "a0a2a6"
    (a0 + a6 against a2: the unflipped ones), "a0a2a4a5" (without the repeat
    a6).  Only "all" feeds the superposition test and the prediction.
Feedback, feedforward, model inversion
  * B = -H_UD / (M (1 + H_UD)),  F = H_UR (1 + B M) - B,  factor |F M| per line,
    computed per subject from (H_UR, H_UD) of the same estimate family
    (single: a3 + a1; pairs: two-input trials).
  * Summaries per plant: per subject the median of |F M| over lines k >= 5
    ("from 0.25 Hz up") and over k = 2, 3 ("up to 0.15 Hz"); then the median
    of those over the 3 subjects (with min-max over subjects).
  * Also "study-style": per line the median over subjects of |F| (times |M|),
    then the median over lines k >= 5 with min-max over those lines.  This is
    how the study computed its 0.54 (0.43-0.70) fo / 0.59 (0.41-0.69) so
    (its notebook: median over subjects of |FR| from single-input trials,
    divided by |1/M|, median/min/max over lines index 2:).
Superposition
  * Per subject, line and response (H_UR, H_UD, each at every line):
    single-input estimate vs two-input estimate ("all" variant).
    d_log = ln|H_single| - ln|H_two|;  d_phase = angle(H_single / H_two) in
    degrees (so wrapped to +-180).
  * scipy.stats.wilcoxon (two-sided, default method: exact for these n) on
    d_log and on d_phase: per line (n = 3 subjects; the smallest possible
    two-sided p is then 0.25) and pooled over lines (n = 3 x lines).
    Median magnitude ratio |H_single|/|H_two| with its min-max, and the median
    |d_phase|.
  * Study-style variant: per line the median over subjects of |H| (and the
    circular mean of the phase over subjects); paired Wilcoxon across lines
    (n = lines), as in the study's notebook.  The study differenced the
    magnitudes linearly; both the linear ('p(|.|)') and the log
    ('p(log|.|)') differences are printed (their ranks can differ).
Results on these files (for the record; the script recomputes them)
  |F M| k >= 5, median over subjects: fo single 0.540, pairs(all) 0.621,
  pairs(a0+a2) 0.543, pairs(a0+a2+a6) 0.559; so single 0.381, pairs(all)
  0.597, pairs(a0+a2) 0.760, pairs(a0+a2+a6) 0.719.  k <= 3: fo 1.00 / 1.03,
  so 1.33 / 1.15 (single / pairs all).
Prediction across conditions
  * A model is (F, B) at every line of the plant.  Prediction of a trial from
    its measured r and e: U_hat = F R + B E at every line of the plant (the
    trial's target and disturbance lines together), zero at all other bins;
    u_hat(t) = irfft of that spectrum over the 2400-sample window.
  * Error (window) = RMS(u - u_hat) / RMS(u) over the window, u raw (its mean,
    which u_hat lacks, counts as error; it is small, printed in the checks).
    Error (lines) = sqrt( sum_lines |U - U_hat|^2 / sum_lines |U|^2 ); the
    JSON also holds it squared (``err_lines_sq``, the brief's literal
    formula).
  * Models fitted on single-input trials, predicting the 10 two-input trials
    (a0 a2 a4 a5 a6):
      FF+FB: B from a1 (B = -H_UD/(M(1+H_UD))), F from a3 and that B.
      FB-only: F = 0, B the same B from the a1 (disturbance-only) trials.
        (The study's choice: its "BonlyD", identical to its "BD".)
      FB-only-alt: F = 0, B = H_UR / (1 - H_UR M) from the a3 trials (the pure
        feedback loop that would reproduce the target-only response; the
        study's "BonlyR"), reported as a variant.
  * Models fitted on the two-input trials ("all" estimates) predicting the 20
    single-input trials (a1, a3): FF+FB: F, B from the pairs; FB-only: F = 0,
    B from the pairs' H_UD; FB-only-alt: B = H_UR/(1 - H_UR M) from the pairs'
    H_UR.  On a1 trials (r = 0) FF+FB and FB-only predict the same u, so the
    a3 trials are also reported alone.
  * Per subject: mean over the predicted trials of the per-trial error, and
    ratio err(FF+FB) / err(FB-only) of those means; median (min-max) of the
    ratio over the 3 subjects.
  * Variant "closed-loop (study)": U_hat = ((F + B) R - B M D) / (1 + B M)
    from r and d alone (what the study's Fig. 5 did at the lines, for one a5
    and one a6 trial per subject); line errors only.
"""

from __future__ import annotations

import argparse
import glob
import json
import os
import re
import sys
import time

import numpy as np
from scipy.stats import wilcoxon

DATA = "/work/shared/data/cphs2017-sessions"
SUBJECTS = ("dp", "ef", "gy")
PLANTS = ("fo", "so")
FS = 60.0
I0, I1 = 300, 2700
N = I1 - I0
KS = {"fo": np.array([2, 3, 5, 7, 11, 13, 17, 19, 23, 29, 31]), "so": np.array([2, 3, 5, 7, 11, 13, 17])}
NAME_RE = re.compile(
    r"_su17v3_(fo|so)_r-(zer|sos[+-][EOA])_d-(zer|sos[+-][EOA])_s49_p(\d)a(\d)_([+-]1)\.csv$"
)
TWO_INPUT_ASSAYS = (0, 2, 4, 5, 6)


def plant_M(plant, k):
    s = 1j * 2 * np.pi * k / 20.0
    return 1.0 / s if plant == "fo" else 1.0 / (s * (s + 1.0))


def line_mask(plant, code):
    """Boolean mask over the plant's lines for a signal code like 'sos+E'."""
    n = len(KS[plant])
    idx = np.arange(n)
    if code == "zer":
        return np.zeros(n, bool)
    which = code[-1]
    if which == "A":
        return np.ones(n, bool)
    if which == "E":
        return idx % 2 == 0
    return idx % 2 == 1


def load_trials(data):
    trials = []
    for subj in SUBJECTS:
        files = sorted(glob.glob(os.path.join(data, subj, "*.csv")))
        for f in files:
            if f.endswith("_rst1.csv") or f.endswith("_rst2.csv"):
                continue
            m = NAME_RE.search(os.path.basename(f))
            if not m:
                raise SystemExit(f"unexpected file name {f}")
            plant, tcode, dcode, phase, assay, sign = m.groups()
            a = np.loadtxt(f, delimiter=",", comments="#")
            w = a[I0:I1]
            r, u, d, x = w[:, 2], w[:, 3], w[:, 4], w[:, 5]
            e = r - x
            k = KS[plant]
            bins = 2 * k
            spec = {nm: np.fft.rfft(v) / N for nm, v in (("r", r), ("u", u), ("d", d), ("x", x), ("e", e))}
            L = {nm: spec[nm][bins] for nm in spec}
            tm, dm = line_mask(plant, tcode), line_mask(plant, dcode)
            # check the line sets against the data (SPEC 12 rule)
            pr, pd = np.abs(L["r"]) ** 2, np.abs(L["d"]) ** 2
            ref = max(pr.max(), pd.max())
            ok = np.array_equal(pr > 1e-6 * ref, tm) and np.array_equal(pd > 1e-6 * ref, dm)
            if not ok:
                raise SystemExit(f"line sets of {f} disagree with its name")
            trials.append(
                dict(
                    file=os.path.basename(f),
                    subject=subj,
                    plant=plant,
                    assay=int(assay),
                    phase=int(phase),
                    sign=int(sign),
                    tmask=tm,
                    dmask=dm,
                    u=u,
                    L=L,
                )
            )
    return trials


def cmean(vals):
    return np.mean(np.array(vals), axis=0)


def estimates(trs, plant, assays_two=TWO_INPUT_ASSAYS, how="mean"):
    """Return dict with H_UR, H_UD (complex arrays over lines) for 'single' and 'two'."""
    n = len(KS[plant])

    def avg(sel, num, den, mask_key):
        out = np.full(n, np.nan + 0j)
        for i in range(n):
            use = [t for t in sel if t[mask_key][i]]
            if not use:
                continue
            U = np.array([t["L"][num][i] for t in use])
            X = np.array([t["L"][den][i] for t in use])
            if how == "mean":
                out[i] = np.mean(U / X)
            else:  # H1
                out[i] = np.sum(U * np.conj(X)) / np.sum(np.abs(X) ** 2)
        return out

    a3 = [t for t in trs if t["assay"] == 3]
    a1 = [t for t in trs if t["assay"] == 1]
    two = [t for t in trs if t["assay"] in assays_two]
    return {
        "single": {
            "HUR": avg(a3, "u", "r", "tmask"),
            "HUD": avg(a1, "u", "d", "dmask"),
            "n": (len(a3), len(a1)),
        },
        "two": {"HUR": avg(two, "u", "r", "tmask"), "HUD": avg(two, "u", "d", "dmask"), "n": len(two)},
    }


def fb_ff(HUR, HUD, M):
    B = -HUD / (M * (1 + HUD))
    F = HUR * (1 + B * M) - B
    return F, B


def wrapdeg(z):
    return np.degrees(np.angle(z))


def wil(x):
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    if len(x) == 0 or np.all(x == 0):
        return float("nan")
    return float(wilcoxon(x).pvalue)


def predict_errors(trial, F, B, M):
    L = trial["L"]
    Uh = F * L["r"] + B * L["e"]
    spec = np.zeros(N // 2 + 1, complex)
    spec[2 * KS[trial["plant"]]] = Uh * N
    uh = np.fft.irfft(spec, n=N)
    u = trial["u"]
    err_w = np.sqrt(np.mean((u - uh) ** 2) / np.mean(u**2))
    num = np.sum(np.abs(L["u"] - Uh) ** 2)
    den = np.sum(np.abs(L["u"]) ** 2)
    # closed loop from r and d (study's Fig. 5 style)
    Ucl = ((F + B) * L["r"] - B * M * L["d"]) / (1 + B * M)
    num_cl = np.sum(np.abs(L["u"] - Ucl) ** 2)
    return dict(
        err_window=float(err_w),
        err_lines=float(np.sqrt(num / den)),
        err_lines_sq=float(num / den),
        err_lines_closedloop=float(np.sqrt(num_cl / den)),
    )


def fmt(v, w=6, p=3):
    if v is None or (isinstance(v, float) and not np.isfinite(v)):
        return " " * (w - 3) + "nan"
    return f"{v:{w}.{p}f}"


def cplx(z):
    return [[float(np.real(v)), float(np.imag(v))] for v in np.atleast_1d(z)]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", default=DATA)
    ap.add_argument("--out", default=None, help="write the figures as JSON here")
    args = ap.parse_args()
    t0 = time.time()
    trials = load_trials(args.data)
    out = {
        "window_samples": [I0, I1],
        "fs": FS,
        "lines_k": {p: KS[p].tolist() for p in PLANTS},
        "n_trials": len(trials),
        "plants": {},
    }
    P = print
    P(
        f"CPHS 2017 sessions, independent reference (numpy+scipy); {len(trials)} trials loaded "
        f"from {args.data}"
    )
    P(f"window rows {I0}..{I1 - 1} ({N} samples, {N / FS:.0f} s); lines k*2pi/20 rad/s = DFT bin 2k")

    for plant in PLANTS:
        k = KS[plant]
        M = plant_M(plant, k)
        hi = k >= 5
        lo = k <= 3
        po = out["plants"][plant] = {"k": k.tolist(), "hz": (k / 20).tolist(), "subjects": {}}
        P("\n" + "=" * 100)
        P(
            f"PLANT {plant}  (M = {'1/s' if plant == 'fo' else '1/(s(s+1))'}, disturbance at plant input)"
            f"  lines k = {' '.join(map(str, k))}"
        )
        P("=" * 100)

        # ---------------- checks
        chk_plant, umean = [], []
        for t in trials:
            if t["plant"] != plant:
                continue
            L = t["L"]
            chk_plant.append(L["x"] / (M * (L["u"] + L["d"])))
            umean.append(abs(np.mean(t["u"])) / np.sqrt(np.mean(t["u"] ** 2)))
        cp = np.array(chk_plant)
        med_ratio = np.median(cp, axis=0)
        P("check: recorded plant vs continuous M at the lines, median over trials of X/(M(U+D)):")
        P("  k      " + " ".join(f"{kk:7d}" for kk in k))
        P("  |.|    " + " ".join(f"{v:7.3f}" for v in np.abs(med_ratio)))
        P("  deg    " + " ".join(f"{v:7.2f}" for v in wrapdeg(med_ratio)))
        P(f"check: |mean(u)|/RMS(u) over trials: median {np.median(umean):.3f}, max {np.max(umean):.3f}")
        po["check_plant_ratio_median"] = cplx(med_ratio)
        po["check_u_mean_over_rms"] = {"median": float(np.median(umean)), "max": float(np.max(umean))}

        # ---------------- estimates per subject
        est = {}
        for subj in SUBJECTS:
            trs = [t for t in trials if t["subject"] == subj and t["plant"] == plant]
            assert len(trs) == 30, (subj, plant, len(trs))
            e_all = estimates(trs, plant)
            e_h1 = estimates(trs, plant, how="H1")
            srcs = [("single", e_all["single"]), ("pairs_all", e_all["two"])]
            for nm, aset in (
                ("pairs_a0a2", (0, 2)),
                ("pairs_a0a2a6", (0, 2, 6)),
                ("pairs_a0a2a4a5", (0, 2, 4, 5)),
            ):
                srcs.append((nm, estimates(trs, plant, assays_two=aset)["two"]))
            srcs += [("single_H1", e_h1["single"]), ("pairs_all_H1", e_h1["two"])]
            d = {}
            for name, src in srcs:
                F, B = fb_ff(src["HUR"], src["HUD"], M)
                d[name] = dict(HUR=src["HUR"], HUD=src["HUD"], F=F, B=B, FM=np.abs(F * M))
            est[subj] = d
            po["subjects"][subj] = {
                name: {
                    "H_UR": cplx(v["HUR"]),
                    "H_UD": cplx(v["HUD"]),
                    "F": cplx(v["F"]),
                    "B": cplx(v["B"]),
                    "absFM": v["FM"].tolist(),
                }
                for name, v in d.items()
            }

        # ---------------- |F M|
        P("\n|F M| per line (model-inversion factor; 1 = exact inverse of the plant)")
        hdr = "  subj  estimate        " + " ".join(f"{kk:6d}" for kk in k) + "   med k>=5  med k<=3"
        P(hdr)
        fm_sum = {}
        h1diff = max(
            float(np.max(np.abs(est[s][a]["FM"] - est[s][b]["FM"])))
            for s in SUBJECTS
            for a, b in (("single", "single_H1"), ("pairs_all", "pairs_all_H1"))
        )
        po["max_abs_diff_absFM_H1_vs_mean_of_ratios"] = h1diff
        for name in (
            "single",
            "pairs_all",
            "pairs_a0a2",
            "pairs_a0a2a6",
            "pairs_a0a2a4a5",
            "single_H1",
            "pairs_all_H1",
        ):
            per_hi, per_lo = [], []
            for subj in SUBJECTS:
                fm = est[subj][name]["FM"]
                per_hi.append(float(np.median(fm[hi])))
                per_lo.append(float(np.median(fm[lo])))
                if name.endswith("_H1"):
                    continue
                P(
                    f"  {subj:4s}  {name:14s}  "
                    + " ".join(fmt(v) for v in fm)
                    + f"   {fmt(per_hi[-1])}    {fmt(per_lo[-1])}"
                )
            allfm = np.array([est[s][name]["FM"] for s in SUBJECTS])
            per_line_med = np.median(allfm, axis=0)
            if not name.endswith("_H1"):
                P(f"  med   {name:14s}  " + " ".join(fmt(v) for v in per_line_med))
            fm_sum[name] = {
                "per_subject_median_k_ge5": dict(zip(SUBJECTS, per_hi, strict=True)),
                "per_subject_median_k_le3": dict(zip(SUBJECTS, per_lo, strict=True)),
                "median_over_subjects_k_ge5": float(np.median(per_hi)),
                "range_over_subjects_k_ge5": [min(per_hi), max(per_hi)],
                "median_over_subjects_k_le3": float(np.median(per_lo)),
                "range_over_subjects_k_le3": [min(per_lo), max(per_lo)],
                "per_line_median_over_subjects": per_line_med.tolist(),
                "studystyle_median_over_lines_k_ge5": float(np.median(per_line_med[hi])),
                "studystyle_range_over_lines_k_ge5": [
                    float(per_line_med[hi].min()),
                    float(per_line_med[hi].max()),
                ],
                "studystyle_median_over_lines_k_le3": float(np.median(per_line_med[lo])),
            }
        po["absFM_summary"] = fm_sum
        P(f"  (H1 averaging gives the same |F M| as the mean of ratios: largest difference {h1diff:.1e})")
        P(
            "\n|F M| summary (median over the 3 subjects of each subject's median over lines;"
            " [min-max over subjects])"
        )
        P(
            "  estimate       k>=5 (>=0.25 Hz)      k<=3 (<=0.15 Hz)      "
            "study-style k>=5 [min-max over lines]"
        )
        for name, v in fm_sum.items():
            if name.endswith("_H1"):
                continue
            P(
                f"  {name:14s} {v['median_over_subjects_k_ge5']:.3f} [{v['range_over_subjects_k_ge5'][0]:.2f}-"  # noqa: E501
                f"{v['range_over_subjects_k_ge5'][1]:.2f}]     {v['median_over_subjects_k_le3']:.3f} "
                f"[{v['range_over_subjects_k_le3'][0]:.2f}-{v['range_over_subjects_k_le3'][1]:.2f}]"
                f"       {v['studystyle_median_over_lines_k_ge5']:.3f} "
                f"[{v['studystyle_range_over_lines_k_ge5'][0]:.2f}-{v['studystyle_range_over_lines_k_ge5'][1]:.2f}]"
            )

        # ---------------- superposition
        P("\nSuperposition: single-input (a3 / a1) vs two-input ('all' pairs) estimate, per subject x line")
        sp = po["superposition"] = {}
        for resp in ("HUR", "HUD"):
            Hs = np.array([est[s]["single"][resp] for s in SUBJECTS])
            H2 = np.array([est[s]["pairs_all"][resp] for s in SUBJECTS])
            dlog = np.log(np.abs(Hs)) - np.log(np.abs(H2))
            dph = wrapdeg(Hs / H2)
            ratio = np.abs(Hs) / np.abs(H2)
            per_line = []
            P(
                f"  {resp}: line  k   |single/two| dp ef gy        dphase deg dp ef gy"
                "      p(log|.|) p(phase)  [n=3]"
            )
            for i, kk in enumerate(k):
                pl, pp = wil(dlog[:, i]), wil(dph[:, i])
                per_line.append(
                    {
                        "k": int(kk),
                        "ratio": ratio[:, i].tolist(),
                        "dphase_deg": dph[:, i].tolist(),
                        "p_logmag": pl,
                        "p_phase": pp,
                    }
                )
                P(
                    f"        {kk:7d}   "
                    + " ".join(f"{v:5.2f}" for v in ratio[:, i])
                    + "      "
                    + " ".join(f"{v:7.1f}" for v in dph[:, i])
                    + f"      {pl:6.3f}   {pp:6.3f}"
                )
            pooled = {
                "n": int(dlog.size),
                "p_logmag": wil(dlog.ravel()),
                "p_phase": wil(dph.ravel()),
                "median_ratio": float(np.median(ratio)),
                "ratio_min": float(ratio.min()),
                "ratio_max": float(ratio.max()),
                "ratio_q25_q75": [float(np.percentile(ratio, 25)), float(np.percentile(ratio, 75))],
                "median_dphase_deg": float(np.median(dph)),
                "median_abs_dphase_deg": float(np.median(np.abs(dph))),
            }
            # study-style: across-subject medians, paired across lines
            m_s, m_2 = np.median(np.abs(Hs), axis=0), np.median(np.abs(H2), axis=0)
            cm_s, cm_2 = np.mean(Hs / np.abs(Hs), axis=0), np.mean(H2 / np.abs(H2), axis=0)
            study = {
                "n_lines": len(k),
                "p_mag": float(wilcoxon(m_s, m_2).pvalue),
                "p_logmag": float(wilcoxon(np.log(m_s), np.log(m_2)).pvalue),
                "p_phase": wil(wrapdeg(cm_s / cm_2)),
            }
            sp[resp] = {"per_line": per_line, "pooled": pooled, "studystyle_across_lines": study}
            P(
                f"  {resp} pooled over subject x line (n={pooled['n']}): "
                f"Wilcoxon p(log|.|) = {pooled['p_logmag']:.3f},"
                f" p(phase) = {pooled['p_phase']:.3f}; |single/two| median {pooled['median_ratio']:.3f}"
                f" [{pooled['ratio_min']:.2f}-{pooled['ratio_max']:.2f}], IQR {pooled['ratio_q25_q75'][0]:.2f}-"  # noqa: E501
                f"{pooled['ratio_q25_q75'][1]:.2f}; median dphase {pooled['median_dphase_deg']:.1f} deg,"
                f" median |dphase| {pooled['median_abs_dphase_deg']:.1f} deg"
            )
            P(
                f"  {resp} study-style (median over subjects per line, paired across {len(k)} lines):"
                f" p(|.|) = {study['p_mag']:.3f}, p(log|.|) = {study['p_logmag']:.3f},"
                f" p(circular-mean phase) = {study['p_phase']:.3f}"
            )

        # ---------------- prediction
        P("\nPrediction across conditions: U_hat = F R + B E at every line (measured r, e), zero elsewhere")
        pr = po["prediction"] = {}
        for direction, fit_name, targets, label in (
            (
                "single_to_pairs",
                "single",
                TWO_INPUT_ASSAYS,
                "fitted on single-input (a1,a3) -> two-input trials",
            ),
            (
                "pairs_to_single",
                "pairs_all",
                (1, 3),
                "fitted on two-input (all pairs) -> single-input trials",
            ),
        ):
            P(f"  {label}")
            P(
                "    subj  set      err_window: FF+FB  FB-only  FB-alt  ratio  |"
                " err_lines: FF+FB  FB-only  FB-alt"
                "  ratio | closed-loop lines: FF+FB  FB-only ratio"
            )
            dres = pr[direction] = {"per_subject": {}}
            ratios = {}
            for subj in SUBJECTS:
                e = est[subj][fit_name]
                F, B = e["F"], e["B"]
                Balt = e["HUR"] / (1 - e["HUR"] * M)
                models = {"FF+FB": (F, B), "FB-only": (0 * F, B), "FB-alt": (0 * F, Balt)}
                trs = [
                    t
                    for t in trials
                    if t["subject"] == subj and t["plant"] == plant and t["assay"] in targets
                ]
                sets = {"all": trs}
                if direction == "pairs_to_single":
                    sets["a3"] = [t for t in trs if t["assay"] == 3]
                    sets["a1"] = [t for t in trs if t["assay"] == 1]
                sres = dres["per_subject"][subj] = {}
                for sname, st in sets.items():
                    res = {}
                    for mname, (Fm, Bm) in models.items():
                        errs = [predict_errors(t, Fm, Bm, M) for t in st]
                        res[mname] = {key: float(np.mean([q[key] for q in errs])) for key in errs[0]}
                        res[mname]["per_trial"] = {t["file"]: q for t, q in zip(st, errs, strict=True)}
                        res[mname]["n_trials"] = len(st)
                    rw = res["FF+FB"]["err_window"] / res["FB-only"]["err_window"]
                    rl = res["FF+FB"]["err_lines"] / res["FB-only"]["err_lines"]
                    rc = res["FF+FB"]["err_lines_closedloop"] / res["FB-only"]["err_lines_closedloop"]
                    res["ratio_window"], res["ratio_lines"], res["ratio_lines_closedloop"] = rw, rl, rc
                    res["ratio_window_vs_alt"] = res["FF+FB"]["err_window"] / res["FB-alt"]["err_window"]
                    res["ratio_lines_vs_alt"] = res["FF+FB"]["err_lines"] / res["FB-alt"]["err_lines"]
                    ratios.setdefault(sname, []).append(
                        (rw, rl, rc, res["ratio_window_vs_alt"], res["ratio_lines_vs_alt"])
                    )
                    sres[sname] = res
                    P(
                        f"    {subj:4s}  {sname:4s}(n={len(st):2d})     {res['FF+FB']['err_window']:.3f}   "
                        f"{res['FB-only']['err_window']:.3f}   {res['FB-alt']['err_window']:.3f}  {rw:.3f}  |"
                        f"        {res['FF+FB']['err_lines']:.3f}    {res['FB-only']['err_lines']:.3f}   "
                        f"{res['FB-alt']['err_lines']:.3f}  {rl:.3f} |"
                        f"        {res['FF+FB']['err_lines_closedloop']:.3f}    "
                        f"{res['FB-only']['err_lines_closedloop']:.3f}  {rc:.3f}"
                    )
            dres["ratio_summary"] = {}
            for sname, lst in ratios.items():
                a = np.array(lst)
                summ = {
                    nm: {
                        "median": float(np.median(a[:, j])),
                        "min": float(a[:, j].min()),
                        "max": float(a[:, j].max()),
                    }
                    for j, nm in enumerate(
                        ("window", "lines", "lines_closedloop", "window_vs_alt", "lines_vs_alt")
                    )
                }
                dres["ratio_summary"][sname] = summ
                P(
                    f"    ratio err(FF+FB)/err(FB-only), median over subjects [{sname}]: window "
                    f"{summ['window']['median']:.3f} [{summ['window']['min']:.2f}-{summ['window']['max']:.2f}],"  # noqa: E501
                    f" lines {summ['lines']['median']:.3f} "
                    f"[{summ['lines']['min']:.2f}-{summ['lines']['max']:.2f}],"
                    f" closed-loop lines {summ['lines_closedloop']['median']:.3f};"
                    f" vs FB-alt: window {summ['window_vs_alt']['median']:.3f},"
                    f" lines {summ['lines_vs_alt']['median']:.3f}"
                )

    # ---------------- headline
    P("\n" + "=" * 100)
    P("HEADLINE (median over the 3 subjects; per-subject figure = median over lines)")
    for plant in PLANTS:
        s = out["plants"][plant]["absFM_summary"]
        P(
            f"  {plant}: |F M| k>=5: pairs(all) {s['pairs_all']['median_over_subjects_k_ge5']:.3f}, "
            f"pairs(a0+a2) {s['pairs_a0a2']['median_over_subjects_k_ge5']:.3f}, "
            f"pairs(a0+a2+a6) {s['pairs_a0a2a6']['median_over_subjects_k_ge5']:.3f}, single "
            f"{s['single']['median_over_subjects_k_ge5']:.3f};  k<=3: pairs(all) "
            f"{s['pairs_all']['median_over_subjects_k_le3']:.3f}, pairs(a0+a2) "
            f"{s['pairs_a0a2']['median_over_subjects_k_le3']:.3f}, "
            f"single {s['single']['median_over_subjects_k_le3']:.3f}"
        )
        P(
            f"      study-style (per-line median over subjects, median [range] over lines k>=5): single "
            f"{s['single']['studystyle_median_over_lines_k_ge5']:.3f} "
            f"[{s['single']['studystyle_range_over_lines_k_ge5'][0]:.2f}-"
            f"{s['single']['studystyle_range_over_lines_k_ge5'][1]:.2f}], pairs(all) "
            f"{s['pairs_all']['studystyle_median_over_lines_k_ge5']:.3f}"
        )
        pr = out["plants"][plant]["prediction"]
        P(
            f"      prediction ratio err(FF+FB)/err(FB-only): single->pairs window "
            f"{pr['single_to_pairs']['ratio_summary']['all']['window']['median']:.3f}, lines "
            f"{pr['single_to_pairs']['ratio_summary']['all']['lines']['median']:.3f}; pairs->single(a3) window "  # noqa: E501
            f"{pr['pairs_to_single']['ratio_summary']['a3']['window']['median']:.3f}, lines "
            f"{pr['pairs_to_single']['ratio_summary']['a3']['lines']['median']:.3f}"
        )
    P(f"elapsed {time.time() - t0:.1f} s")
    if args.out:
        with open(args.out, "w") as fh:
            json.dump(out, fh, indent=1)
        P(f"JSON written to {args.out}")


if __name__ == "__main__":
    sys.exit(main())
