"""Every figure and printed number the README and docs quote that the code produces, made again on
this machine and checked against the text (`make docs-figures`).

    .venv/bin/python benchmarks/docs_figures.py            # paper study, report figures, lab examples
    .venv/bin/python benchmarks/docs_figures.py --no-paper # the lab examples only (about 2 minutes)

- The paper study (`hcid run configs/paper.yaml`, its report) in ``runs/paper``, reused when there:
  docs/nb_ft_vs_w.png and docs/bode_FF_bic.png are copied from its report.
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--no-paper", action="store_true", help="skip the paper study and its figures")
    args = parser.parse_args()
    print(f"machine: {cpu()}; Python {platform.python_version()}")
    if not args.no_paper:
        paper = ROOT / "runs" / "paper"
        if not (paper / "selection.parquet").exists():
            run(["run", "configs/paper.yaml", "--quiet"])
        run(["report", str(paper)])
        for name in ("nb_ft_vs_w.png", "bode_FF_bic.png"):
            shutil.copyfile(paper / "report" / name, ROOT / "docs" / name)
            print(f"docs/{name}: from {paper / 'report' / name}")
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
    sys.exit(1 if missing else 0)


if __name__ == "__main__":
    main()
