"""Shared fixtures: configs and simulated records of the paper study."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hcid.assembly.resolve import load_config

ROOT = Path(__file__).resolve().parents[1]
PAPER_CONFIG = ROOT / "configs" / "paper.yaml"
CI_CONFIG = ROOT / "configs" / "ci.yaml"


@pytest.fixture(scope="session")
def paper_config():
    return load_config(PAPER_CONFIG)


@pytest.fixture(scope="session")
def ci_config():
    return load_config(CI_CONFIG)


def _record(config, model_name: str, seed: int) -> dict[str, np.ndarray]:
    from hcid.loop.simulate import remnant_gain, simulate_realization
    from hcid.methods import shift_forward

    r = simulate_realization(config, config.model(model_name), seed, remnant_gain(config))
    shift = config.identify.shift_samples(config.timing.output_rate)
    ft_s = shift_forward(r.ft, shift)  # SPEC 3: ft_s(k) = ft(k + 25)
    return {"ft": r.ft, "ft_s": ft_s, "fd": r.fd, "e": r.e, "u": r.u, "theta": r.theta, "n": r.n}


@pytest.fixture(scope="session")
def paper_record(paper_config):
    """FF model, seed 1, of configs/paper.yaml at 25 Hz (2048 samples); ft_s is ft shifted 1 s."""
    return _record(paper_config, "FF", 1)


@pytest.fixture(scope="session")
def paper_record_fb(paper_config):
    """FB model, seed 1, of configs/paper.yaml."""
    return _record(paper_config, "FB", 1)


@pytest.fixture()
def ci_raw():
    """configs/ci.yaml as a YAML document, reduced to seed 1 (a fresh copy per test)."""
    import yaml

    raw = yaml.safe_load(CI_CONFIG.read_text())
    raw["seeds"] = [1]
    return raw


def load_data(path, config) -> dict[int, dict[str, np.ndarray]]:
    """One measured file's checked runs for a study, as ``hcid identify --data FILE`` reads them:
    the config's data section, analysis rate and the samples its windows need."""
    from hcid.config.parse import default_data
    from hcid.io.measured import read_runs, samples_needed

    data = config.data if config.data is not None else default_data()
    return read_runs(path, data, config.timing.output_rate, samples_needed(config))[0]


def interrupt_after(monkeypatch, module, name: str, calls: int):
    """Make ``module.name`` raise KeyboardInterrupt from call ``calls + 1`` on (an interrupted
    run, as Ctrl-C would stop it); returns the real function, to put back for the resume."""
    real = getattr(module, name)
    count = {"n": 0}

    def interrupted(*args):
        count["n"] += 1
        if count["n"] > calls:
            raise KeyboardInterrupt
        return real(*args)

    monkeypatch.setattr(module, name, interrupted)
    return real


def report_without_figures(run_dir, draw=(), out=None):
    """``(report.md's text, names of the figures it links)`` of a run as ``hcid report`` renders
    it (the same compute and render), drawing only the figures named in ``draw`` (PNGs into
    ``out``): a test of the text need not draw every figure (about 1 s each)."""
    from hcid.report import figures
    from hcid.report.build import compute_report, render
    from hcid.report.document import to_markdown

    doc = render(compute_report(Path(run_dir)))
    for name in draw:
        figures.save(doc.drawings[name](), Path(out) / name)
    return to_markdown(doc), set(doc.drawings)
