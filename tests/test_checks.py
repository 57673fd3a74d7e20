"""The data checks of hcid analyse (hcid.pipeline.evidence.Checks): reading a group's check
changes nothing it holds."""

from pathlib import Path

import numpy as np

from hcid.assembly.resolve import load_config
from hcid.pipeline.evidence import Checks

ROOT = Path(__file__).resolve().parents[1]


def test_a_group_without_a_test_says_why_and_changes_nothing():
    # Source: a record of white noise has no forcing lines (record_lines refuses it), so the run
    # has no test, and a group with it none either, for the run's reason.
    config = load_config(ROOT / "configs" / "lab_example.yaml")
    n = config.timing.record_samples
    rng = np.random.default_rng(1)
    noise = {k: rng.standard_normal(n) for k in ("ft", "fd", "e", "u")}
    checks = Checks(config, {1: noise})
    problems = dict(checks.problems)
    assert problems[1].startswith("no test: ")
    assert checks.group([1], {}) == (None, problems[1])
    assert checks.problems == problems and checks.problem([1]) == problems[1]
