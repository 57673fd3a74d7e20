"""Every figure and printed number the README and docs quote that the code produces, made again on
this machine and checked against the text (`make docs-figures`).

    .venv/bin/python benchmarks/docs_figures.py            # paper study, report figures, lab examples
    .venv/bin/python benchmarks/docs_figures.py --no-paper # the lab examples only (about 2 minutes)

- The paper study (`hcid run configs/paper.yaml`, its report) in ``runs/paper``, reused when there:
  docs/nb_ft_vs_w.png and docs/bode_FF_bic.png are copied from its report, and the numbers
  docs/paper-results.md quotes (RMS(e), var(n)/var(u), W_FP, W_FN, W_AIC, W_BIC, the candidate
  counts) computed from its tables and looked up in that page, each as the page writes it.
- The two lab examples (`hcid analyse configs/lab_example.yaml --data configs/lab_example`, and
  lab_weak) in fresh run directories under ``runs/docs-figures``: their answer lines printed, and
  each answer line the README quotes (the lines in its code blocks that start with ``condition=``,
  up to the first ``...``) looked up in what this machine printed.

It prints the machine first: results depend on the CPU through BLAS and the compiled kernels
(docs/measured-studies.md, "Results and the CPU"), so a figure in the docs holds on the machine
named beside it.
"""

from __future__ import annotations

import argparse
import os
import platform
import re
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
HCID = [sys.executable, "-m", "hcid"]
ENV = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}


def cpu() -> str:
    info = Path("/proc/cpuinfo").read_text().splitlines() if Path("/proc/cpuinfo").exists() else []
    names = [line.split(":", 1)[1].strip() for line in info if "model name" in line]
    name = names[0] if names else platform.processor()
    flags = next((line for line in info if line.startswith("flags")), "")
    simd = "AVX-512" if "avx512f" in flags else "AVX2" if "avx2" in flags else "no AVX2"
    return f"{name} ({simd}), {os.cpu_count()} cores, load {os.getloadavg()[0]:.2f}"


def run(args: list[str]) -> str:
    out = subprocess.run(HCID + args, cwd=ROOT, env=ENV, capture_output=True, text=True)
    if out.returncode != 0:
        sys.exit(f"hcid {' '.join(args)} failed:\n{out.stdout}{out.stderr}")
    return out.stdout


def quoted_answers(text: str) -> list[str]:
    """What a text quotes of the answer lines: every line of a code block holding ``condition=``
    answers, cut at each ``...`` into its pieces (a wrapped line is still a piece of a printed one)."""
    pieces = []
    for block in re.findall(r"^```[a-z]*\n(.*?)^```", text, flags=re.S | re.M):
        if "condition=" not in block:
            continue
        for line in block.splitlines():
            pieces += [p.strip(" ()") for p in line.split("...") if len(p.strip(" ()")) >= 8]
    return pieces


def paper_numbers(run: Path) -> dict[str, str]:
    """What docs/paper-results.md quotes of the paper study, from its tables, formatted as the page
    writes it."""
    import numpy as np
    import pyarrow.parquet as pq

    summary = pq.read_table(run / "simulation_summary.parquet").to_pylist()
    thresholds = {(r["method"], r["model"]): r for r in pq.read_table(run / "thresholds.parquet").to_pylist()}
    log = pq.read_table(run / "identify_log.parquet").to_pydict()
    rms = {m: np.mean([r["rms_e_deg"] for r in summary if r["model"] == m]) for m in ("FB", "FF")}
    ratio = np.mean([r["noise_ratio_disturbance_only"] for r in summary])
    fb, ff = (thresholds[("direct", "FB")], thresholds[("indirect", "FB")]), (
        thresholds[("direct", "FF")], thresholds[("indirect", "FF")])  # fmt: skip
    out = {
        "RMS(e) FB, FF": f"{rms['FB']:.3f} / {rms['FF']:.3f}",
        "var(n)/var(u), disturbance only": f"{ratio:.4f}",
        "W_FP direct (verdict table)": f"{fb[0]['w_fp']:.3g}",
        "W_FP indirect (verdict table)": f"{fb[1]['w_fp']:.3g}",
        "W_FN direct, indirect": f"{ff[0]['w_fn']:.3f} / {ff[1]['w_fn']:.3f}",
        "W_AIC / W_BIC": f"{fb[0]['w_aic']:.2e} / {fb[0]['w_bic']:.2e}",
        "candidates": f"{sum(log['n_candidates']) + sum(log['stage1_candidates']):,}",
        "unstable": f"{sum(log['n_unstable']) + sum(log['stage1_unstable']):,}",
    }
    return {k: v.replace("e-03", "e-3") for k, v in out.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--no-paper", action="store_true", help="skip the paper study and its figures")
    args = parser.parse_args()
    print(f"machine: {cpu()}; Python {platform.python_version()}")
    wrong: list[str] = []
    if not args.no_paper:
        paper = ROOT / "runs" / "paper"
        if not (paper / "selection.parquet").exists():
            run(["run", "configs/paper.yaml", "--quiet"])
        run(["report", str(paper)])
        for name in ("nb_ft_vs_w.png", "bode_FF_bic.png"):
            shutil.copyfile(paper / "report" / name, ROOT / "docs" / name)
            print(f"docs/{name}: from {paper / 'report' / name}")
        page = (ROOT / "docs" / "paper-results.md").read_text()
        wrong = []
        for label, text in paper_numbers(paper).items():
            found = text in page
            wrong += [] if found else [label]
            print(
                f"docs/paper-results.md {label}: {text} {'(as quoted)' if found else '(NOT as quoted there)'}"
            )
    readme = (ROOT / "README.md").read_text()
    printed = ""
    for name in ("lab_example", "lab_weak"):
        out_dir = ROOT / "runs" / "docs-figures" / name
        if out_dir.exists():
            shutil.rmtree(out_dir)
        out = run(["analyse", f"configs/{name}.yaml", "--data", f"configs/{name}", "--run", str(out_dir),
                   "--quiet"])  # fmt: skip
        printed += out
        answers = [line for line in out.splitlines() if line.startswith("condition=")]
        print(f"\n## {name}\n" + "\n".join(answers))
    flat = " ".join(printed.split())
    missing = [piece for piece in quoted_answers(readme) if " ".join(piece.split()) not in flat]
    verdict = "every piece printed here" if not missing else "NOT printed here:"
    print(f"\nREADME's quoted answers: {verdict}")
    for line in missing:
        print(f"  {line}")
    sys.exit(1 if missing or (not args.no_paper and wrong) else 0)


if __name__ == "__main__":
    main()
