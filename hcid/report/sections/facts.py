"""1. Run facts: config, grids, candidates, unstable counts, wall times, package versions."""

from __future__ import annotations

import importlib.metadata

from hcid import methods
from hcid.report.document import Doc

TITLE = "1. Run facts"


def _versions() -> str:
    names = ["hcid", "numpy", "scipy", "control", "numba", "pyarrow", "joblib", "matplotlib"]
    out = []
    for n in names:
        try:
            out.append(f"{n} {importlib.metadata.version(n)}")
        except importlib.metadata.PackageNotFoundError:
            out.append(f"{n} -")
    return ", ".join(out)


def _options(spec, stage) -> str:
    """A stage's options in effect, when any differs from its default (SPEC behaviour otherwise)."""
    return "".join(f", {k} {spec.option(stage, k)}" for k in spec.options) if stage.options else ""


def _range(r) -> str:
    return f"{r[0]}..{r[1]}"


def compute(run, done) -> list[list[str]]:
    config = run.config
    facts = [["config", config.name]]
    if config.simulates:
        facts.append(["models", ", ".join(m.name for m in config.models)])
        facts.append(["seeds", f"{len(config.seeds)} ({config.seeds[0]}..{config.seeds[-1]})"])
    else:
        facts.append(["config kind", "measured data only (no simulation sections)"])
    for method in methods.resolved(config.identify).values():
        for spec in method.stages:
            g = config.identify.stage(spec.name).grid
            i1, i2, _ = spec.inputs
            facts.append(
                [
                    f"{method.name}: stage {spec.name} grid",
                    f"na {_range(g.na)}, nb_{i1} {_range(g.nb1)}, nb_{i2} {_range(g.nb2)}, "
                    f"nk_{i1} {_range(g.nk1)}, nk_{i2} {_range(g.nk2)}"
                    + _options(spec, config.identify.stage(spec.name)),
                ]
            )
    w = config.selection.w_grid
    facts.append(["W grid", f"{len(w)} points, {w[0]:.3g}..{w[-1]:.3g} (log)"])
    for label, per_method in run.criterion_marks().items():
        facts.append([label, ", ".join(f"{m} {v:.4g} (Nf {run.nf()[m]})" for m, v in per_method.items())])
    if run.log is not None:
        lg = run.log.to_pydict()
        n_cand = sum(lg["n_candidates"]) + sum(lg["stage1_candidates"])
        n_unst = sum(lg["n_unstable"]) + sum(lg["stage1_unstable"])
        facts.append(
            ["candidates fitted", f"{n_cand:,} ({n_unst:,} unstable, {n_unst / max(n_cand, 1):.1%})"]
        )
        for method in methods.METHODS.values():
            rows = [i for i, m in enumerate(lg["method"]) if m == method.name]
            if not rows:
                continue
            total = sum(lg["seconds"][i] for i in rows)
            unstable = sum(lg["n_unstable"][i] for i in rows)
            text = f"{total:.0f} s summed over tasks"
            if method.choice_stages:
                first = sum(lg["seconds_stage1"][i] for i in rows)
                unstable_first = sum(lg["stage1_unstable"][i] for i in rows)
                names = ", ".join(s.name for s in method.choice_stages)
                text += (
                    f" ({names} {first:.0f} s, {method.final_stage.name} {total - first:.0f} s); "
                    f"unstable: {names} {unstable_first:,}, {method.final_stage.name} {unstable:,}"
                )
            else:
                text += f"; unstable {unstable:,}"
            facts.append([f"{method.name} identification", text])
    if run.runlog is not None:
        for row in run.runlog.to_pylist():
            facts.append(
                [
                    f"wall time: {row['stage']}",
                    f"{row['seconds']:.1f} s on {row['jobs']} worker(s), {row['finished']}",
                ]
            )
    facts.append(["packages", _versions()])
    return facts


def render(facts: list[list[str]], doc: Doc) -> None:
    doc.text(f"## {TITLE}")
    doc.table(["item", "value"], facts)
