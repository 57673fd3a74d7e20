"""Every figure the README and docs quote of what the code gives today, made again on this machine
and checked against the text (`make docs-figures`).

    .venv/bin/python benchmarks/docs_figures.py              # everything (about 20 minutes; paper reused)
    .venv/bin/python benchmarks/docs_figures.py --no-paper --no-sessions   # about 5 minutes
    .venv/bin/python benchmarks/docs_figures.py --write      # the marked figures rewritten from this run

**Marked figures.** A figure of the docs that the code gives today stands between
``<!-- fig NAME -->`` and ``<!-- /fig -->`` (invisible in the rendered page; a table or a few
words): this script makes each NAME again and fails where the text differs, printing both
(``--write`` puts what this machine printed in its place). A NAME ``time:STUDY`` marks a wall
time, written as a range (``40 to 90 s``): it fails where the wall time measured here lies
outside. Figures in dated records (docs/benchmarks.md, a "measured DATE" paragraph that names its
commit) are records of their day and are not checked.

What it makes:

- The paper study (`hcid run configs/paper.yaml`, its report) in ``runs/paper``, reused when there:
  docs/nb_ft_vs_w.png and docs/bode_FF_bic.png are copied from its report, and the numbers
  docs/paper-results.md quotes looked up in that page, each as the page writes it.
- The two lab examples (`hcid analyse configs/lab_example.yaml --data configs/lab_example`, and
  lab_weak) in fresh run directories under ``runs/docs-figures``, timed: their tables against the
  truth (`benchmarks/lab_study.py`'s), and each answer line the README quotes (the lines in its
  code blocks that start with ``condition=``, up to the first ``...``) looked up in what this
  machine printed.
- The shared recordings (`../shared/data/cphs2017`, `--by plant`), fresh and timed, and the
  session folders (`../shared/data/cphs2017-sessions`, `--by subject`, resumed in
  ``runs/cphs2017_sessions_fo`` and ``_so``; ``--no-sessions`` skips them) with the independent
  reference `benchmarks/cphs_sessions_reference.py`. Where the shared data are absent, their
  marks are listed as not checked.

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
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "data"
#: A marked figure: ``<!-- fig NAME -->`` what the docs say ``<!-- /fig -->``.
MARK = re.compile(r"<!-- fig (?P<name>[\w:.-]+) -->(?P<body>.*?)<!-- /fig -->", re.S)
#: The documents whose marks are checked.
DOCS = ("README.md", *sorted(str(p.relative_to(ROOT)) for p in (ROOT / "docs").glob("*.md")))
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
    return timed(args)[0]


#: The highest load average (before or after) at which a wall time is judged against the docs'
#: range: beyond, other work shares the cores and the time says little.
BUSY = float(os.cpu_count() or 1)
#: The loads each timed command saw, by its wall time's name.
LOADS: dict[str, tuple[float, float]] = {}


def timed(args: list[str], name: str | None = None) -> tuple[str, float]:
    """``hcid ARGS`` in a subprocess: its output and its wall time (the load before and after
    kept under ``name``)."""
    before, start = os.getloadavg()[0], time.perf_counter()
    out = subprocess.run(HCID + args, cwd=ROOT, env=ENV, capture_output=True, text=True)
    if out.returncode != 0:
        sys.exit(f"hcid {' '.join(args)} failed:\n{out.stdout}{out.stderr}")
    if name:
        LOADS[name] = (before, os.getloadavg()[0])
    return out.stdout, time.perf_counter() - start


def fresh(name: str) -> Path:
    out_dir = ROOT / "runs" / "docs-figures" / name
    if out_dir.exists():
        shutil.rmtree(out_dir)
    return out_dir


def in_range(text: str, seconds: float) -> bool:
    """Whether a wall time lies in a range the docs write as ``A to B s`` (or ``min``)."""
    found = re.fullmatch(r"\s*([\d.]+) to ([\d.]+) (s|min)\s*", text)
    if not found:
        return False
    scale = 60.0 if found[3] == "min" else 1.0
    return float(found[1]) * scale <= seconds <= float(found[2]) * scale


def check_marks(
    made: dict[str, str], times: dict[str, float], skipped: tuple[str, ...], write: bool
) -> list[str]:
    """Every mark of the docs against what this run made: the ones that differ, and a mark nothing
    makes (a misspelt name) unless its part was ``skipped`` (its name starts so). With ``write``,
    each made figure is put in its mark's place (a block stays a block)."""

    def made_in(m: re.Match) -> str:
        if m["name"] not in made:
            return m[0]
        figure = made[m["name"]].strip()
        body = f"\n{figure}\n" if "\n" in m["body"] else figure
        return f"<!-- fig {m['name']} -->{body}<!-- /fig -->"

    wrong, unchecked = [], []
    for doc in DOCS:
        path = ROOT / doc
        text = path.read_text()
        for m in MARK.finditer(text):
            name, said = m["name"], m["body"].strip()
            study = name.split(":", 1)[1] if name.startswith("time:") else None
            if name.startswith(skipped) or (study and study.startswith(skipped)):
                unchecked.append(f"{doc} {name}")
            elif study is not None and study not in times or study is None and name not in made:
                wrong.append(f"{doc} {name}: nothing makes this figure (a misspelt name?)")
            elif study is not None and not in_range(said, times[study]):
                seen = f"measured {times[study]:.1f} s at load {'/'.join(f'{x:.1f}' for x in LOADS[study])}"
                if max(LOADS[study]) > BUSY:
                    unchecked.append(f"{doc} {name} ({seen}: the machine was busy)")
                else:
                    wrong.append(f"{doc} {name}: {seen}, the text says {said!r}")
            elif study is None and said != made[name].strip():
                wrong.append(f"{doc} {name}: the text says\n{said}\nthis machine made\n{made[name].strip()}")
        if write:
            path.write_text(MARK.sub(made_in, text))
    for name in unchecked:
        print(f"not checked here: {name}")
    return wrong


def lab_examples(made: dict[str, str], times: dict[str, float]) -> str:
    """The two lab examples, fresh and timed: their findings against the truth; returns what
    they printed."""
    import lab_study
    from _tables import remnant_shares

    printed = ""
    for name in ("lab_example", "lab_weak"):
        out_dir = fresh(name)
        out, times[name] = timed(["analyse", f"configs/{name}.yaml", "--data", f"configs/{name}",
                                  "--run", str(out_dir), "--jobs", "2", "--quiet"], name)  # fmt: skip
        printed += out
        load = "/".join(f"{x:.1f}" for x in LOADS[name])
        answers = "\n".join(line for line in out.splitlines() if line.startswith("condition="))
        print(f"\n## {name}: {times[name]:.1f} s wall (load {load} before/after)\n{answers}")
        found = lab_study.findings(lab_study.make.STUDIES[name], out_dir, ROOT / "configs" / f"{name}.yaml")
        for key, text in found.items():
            made[f"{name}:{key}"] = text
        groups = {g["group"]: g for g in _groups(out_dir) if g["method"] == "direct"}
        made[f"{name}:compensatory-Kpt"] = f"{groups['condition=compensatory']['fitted_Kpt']:.2g}"
        made[f"{name}:remnant"] = remnant_shares(out_dir)
    return printed


def _groups(run_dir: Path) -> list[dict]:
    import pyarrow.parquet as pq

    return pq.read_table(run_dir / "analysis_groups.parquet").to_pylist()


def shared_recordings(made: dict[str, str], times: dict[str, float]) -> bool:
    """The CPHS recordings, `--by plant`, fresh and timed (False where the data are absent)."""
    from _tables import calibration_table, evidence_table, remnant_shares

    if not (SHARED / "cphs2017").is_dir():
        print(f"\n## shared recordings: {SHARED / 'cphs2017'} absent, not made")
        return False
    tables = {"calibration": [], "evidence": []}
    for plant in ("fo", "so"):
        out_dir = fresh(f"cphs_{plant}")
        data = f"../shared/data/cphs2017/*_{plant}_*.csv"
        args = ["analyse", f"configs/cphs2017_{plant}.yaml", "--data", data, "--by", "plant", "--run",
                str(out_dir), "--jobs", "2", "--quiet"]  # fmt: skip
        _, times[f"cphs_{plant}"] = timed(args, f"cphs_{plant}")
        load = "/".join(f"{x:.1f}" for x in LOADS[f"cphs_{plant}"])
        print(f"\n## CPHS {plant}: {times[f'cphs_{plant}']:.1f} s wall (load {load} before/after)")
        for key, make in (("calibration", calibration_table), ("evidence", evidence_table)):
            lines = make(out_dir).splitlines()
            tables[key] += lines if not tables[key] else lines[2:]
        made[f"cphs:remnant-{plant}"] = remnant_shares(out_dir)
    made.update({f"cphs:{key}": "\n".join(lines) for key, lines in tables.items()})
    return True


def sessions(made: dict[str, str]) -> bool:
    """The session folders, `--by subject` (resumed), and the independent reference (False where
    the data are absent)."""
    from _tables import feedforward_by_person, session_table

    if not (SHARED / "cphs2017-sessions").is_dir():
        print(f"\n## sessions: {SHARED / 'cphs2017-sessions'} absent, not made")
        return False
    runs = {}
    for plant in ("fo", "so"):
        runs[plant] = ROOT / "runs" / f"cphs2017_sessions_{plant}"
        _, seconds = timed(["analyse", f"configs/cphs2017_sessions_{plant}.yaml", "--data",
                            f"../shared/data/cphs2017-sessions/*/*_{plant}_*", "--by", "subject",
                            "--run", str(runs[plant]), "--jobs", "2", "--quiet"])  # fmt: skip
        print(f"\n## sessions {plant}: {seconds:.1f} s wall (resumed where {runs[plant]} held results)")
    made["sessions:findings"] = session_table(runs["fo"], runs["so"])
    made["sessions:by-person"] = feedforward_by_person(runs["fo"], runs["so"])
    ref = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "cphs_sessions_reference.py")], cwd=ROOT,
                         env=ENV, capture_output=True, text=True, check=True).stdout  # fmt: skip
    headline = ref[ref.index("HEADLINE") :].splitlines()
    kept = "\n".join(line for line in headline if not line.startswith("elapsed"))
    made["sessions:reference"] = f"```\n{kept}\n```"
    return True


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
    parser.add_argument("--no-sessions", action="store_true", help="skip the session folders")
    parser.add_argument("--write", action="store_true", help="put what this run made in the docs' marks")
    args = parser.parse_args()
    print(f"machine: {cpu()}; Python {platform.python_version()}")
    sys.path.insert(0, str(ROOT / "benchmarks"))
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
        for label, text in paper_numbers(paper).items():
            found = text in page
            wrong += [] if found else [f"docs/paper-results.md {label}: {text}"]
            print(
                f"docs/paper-results.md {label}: {text} {'(as quoted)' if found else '(NOT as quoted there)'}"
            )
    made: dict[str, str] = {}
    times: dict[str, float] = {}
    printed = lab_examples(made, times)
    skipped = ("sessions:",) if args.no_sessions else ()
    if not shared_recordings(made, times):
        skipped += ("cphs:", "cphs_")
    if not args.no_sessions and not sessions(made):
        skipped += ("sessions:",)
    flat = " ".join(printed.split())
    missing = [piece for piece in quoted_answers((ROOT / "README.md").read_text())
               if " ".join(piece.split()) not in flat]  # fmt: skip
    print(f"\nREADME's quoted answers: {'every piece printed here' if not missing else 'NOT printed here:'}")
    for line in missing:
        print(f"  {line}")
    wrong += check_marks(made, times, skipped, args.write)
    print(f"\nmarked figures: {len(made)} made here; " + ("every one as the docs say" if not wrong else
          f"{len(wrong)} differ{' (written now)' if args.write else ''}:"))  # fmt: skip
    for line in wrong:
        print(f"  {line}")
    print(f"\nmachine at the end: {cpu()}")
    sys.exit(1 if missing or (wrong and not args.write) else 0)


if __name__ == "__main__":
    main()
