"""Golden run of configs/ci.yaml: this tool's own output, pinned.

Source of every number below: `hcid run configs/ci.yaml` at commit 0f2e6b9 (before
the issue-9 refactor) and again at f4d80bc (after it), identical; numpy 2.4.6,
scipy 1.17.1, python-control 0.10.2, numba 0.68.1, pyarrow 26.0.1. A change that
moves any of them changes a result and must say so.

Fused multiply-adds in the direct and stage-2 grids (issue 14, after 848e3f3) moved the
last bits of V, so the frontier, selection and breakpoints digests were pinned again
(frontier V within 2.5e-13 relative, the same rows and selections; the `rel=` values
below held). With `arithmetic: unfused` the run gives every earlier digest, those of
../shared/tools/ci_digest.txt, bit for bit: `test_unfused_run_gives_the_earlier_digests`.
"""

from __future__ import annotations

import hashlib
import importlib.metadata
import os
import platform
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
import yaml

from .conftest import CI_CONFIG, ROOT

#: Content digests (sorted columns; names, types, values) as ../shared/tools/table_digest.py computes
#: them. They hold bit for bit with OpenBLAS's Haswell (AVX2)
#: kernels, which the golden run forces: on a CPU with AVX-512 OpenBLAS otherwise picks other kernels
#: (the loop discretisation's linear algebra), which change the last bits of every table (this
#: machine then gives e.g. simulations bf05ffee9c1af780).
DIGESTS = {
    "simulations": "00c6a5dbe626fe3a",
    "simulation_summary": "a5697bcb68eecbd5",
    "frontier": "61241f028c843b68",
    "stage1": "1204f95cec38ebd0",
    "selection": "a64f40b74bb4f4cd",
    "breakpoints": "85fc27b46d625d9d",
}
#: The same run with unfused arithmetic: ../shared/tools/ci_digest.txt, pinned before issue 14.
UNFUSED_DIGESTS = DIGESTS | {
    "frontier": "2a0afb1d6b55ea53",
    "selection": "0874418f1af016d1",
    "breakpoints": "d44bfc2684291daa",
}
#: The digests hold bit for bit only with the packages they were made with.
DIGEST_VERSIONS = {"numpy": "2.4", "scipy": "1.17", "control": "0.10", "numba": "0.68"}


def _run(config: Path, run: Path) -> Path:
    """`hcid run CONFIG` in a process of its own, with OpenBLAS's Haswell kernels."""
    env = dict(os.environ, OPENBLAS_CORETYPE="Haswell", OPENBLAS_NUM_THREADS="1")
    hcid = Path(sys.executable).parent / "hcid"
    subprocess.run([str(hcid), "run", str(config), "--run", str(run), "--quiet"], env=env, check=True)
    return run


@pytest.fixture(scope="module")
def golden_run(tmp_path_factory):
    return _run(CI_CONFIG, tmp_path_factory.mktemp("golden") / "ci")


@pytest.fixture(scope="module")
def unfused_run(tmp_path_factory):
    """configs/ci.yaml with ``identify.direct.arithmetic: unfused`` (stage 2 takes it too)."""
    where = tmp_path_factory.mktemp("unfused")
    raw = yaml.safe_load(CI_CONFIG.read_text())
    raw["identify"]["direct"]["arithmetic"] = "unfused"
    config = where / "ci.yaml"
    config.write_text(yaml.safe_dump(raw))
    return _run(config, where / "ci")


def _digest(path) -> str:
    t = pq.read_table(path)
    t = t.select(sorted(t.column_names))
    h = hashlib.sha256()
    for name in t.column_names:
        c = t.column(name)
        h.update(name.encode())
        h.update(str(c.type).encode())
        h.update(repr(c.to_pylist()).encode())
    return h.hexdigest()[:16]


def test_remnant_gain_and_rms(golden_run):
    rows = pq.read_table(golden_run / "simulation_summary.parquet").to_pylist()
    assert rows[0]["kn"] == pytest.approx(0.019903457778911622, rel=1e-12)
    rms = {(r["model"], r["seed"]): r["rms_e_deg"] for r in rows}
    assert rms[("FB", 1)] == pytest.approx(2.4447932754240003, rel=1e-9)
    assert rms[("FF", 3)] == pytest.approx(1.2537995980083265, rel=1e-9)


def test_thresholds(golden_run):
    th = {(r["method"], r["model"]): r for r in pq.read_table(golden_run / "thresholds.parquet").to_pylist()}
    assert th[("direct", "FB")]["w_fp"] == pytest.approx(0.0017189079696606768, rel=1e-9)
    assert th[("indirect", "FB")]["w_fp"] == pytest.approx(0.042163343884103366, rel=1e-9)
    assert th[("direct", "FF")]["w_fn"] == pytest.approx(0.5530644518183324, rel=1e-9)
    assert th[("indirect", "FF")]["w_fn"] == pytest.approx(0.30963871704840606, rel=1e-9)
    for row in th.values():  # SPEC 4 and 9 at Nf = 960
        assert row["nf"] == 960
        assert row["w_aic"] == pytest.approx(2.083e-3, rel=1e-3)
        assert row["w_bic"] == pytest.approx(7.153e-3, rel=1e-3)
        assert row["w_mbic"] == pytest.approx(0.0214, rel=3e-3)


def test_frontier_rows(golden_run):
    f = pq.read_table(golden_run / "frontier.parquet").to_pylist()
    cols = ("model", "seed", "method", "na", "nb_ft", "nb_e", "nk_ft", "nk_e")
    expected = {
        17: (("FB", 1, "direct", 2, 0, 1, 0, 5), 8.364458136540767e-05, 91.87385718902812),
        333: (("FF", 1, "direct", 3, 3, 1, 22, 4), 9.366387191013554e-05, 92.09094125248103),
        575: (("FF", 3, "indirect", 3, 3, 3, 30, 7), 9.66604734262179e-05, 91.88636856591987),
    }
    assert len(f) == 576
    for i, (key, v, vaf) in expected.items():
        assert tuple(f[i][c] for c in cols) == key
        assert f[i]["v"] == pytest.approx(v, rel=1e-9)
        assert f[i]["vaf_validation"] == pytest.approx(vaf, rel=1e-9)
    s1 = pq.read_table(golden_run / "stage1.parquet").to_pylist()[0]
    assert (s1["na"], s1["nb_ft"], s1["nb_fd"], s1["nk_ft"], s1["nk_fd"]) == (2, 8, 4, 3, 1)
    assert (s1["n_candidates"], s1["n_unstable"]) == (1300, 309)


def _skip_unless_pinned_platform():
    if platform.machine() != "x86_64":
        pytest.skip("digests pinned with OpenBLAS's x86-64 Haswell kernels (rel= goldens still run)")
    for package, prefix in DIGEST_VERSIONS.items():
        version = importlib.metadata.version(package)
        if not version.startswith(prefix):
            pytest.skip(f"digests pinned with {package} {prefix}.x, found {version} (rel= goldens still run)")


def test_content_digests(golden_run):
    _skip_unless_pinned_platform()
    found = {name: _digest(golden_run / f"{name}.parquet") for name in DIGESTS}
    assert found == DIGESTS


def test_unfused_run_gives_the_earlier_digests(unfused_run):
    # Unfused, the engine's arithmetic is that of every hcid before issue 14: all six
    # tables as pinned in ../shared/tools/ci_digest.txt, bit for bit.
    _skip_unless_pinned_platform()
    found = {name: _digest(unfused_run / f"{name}.parquet") for name in UNFUSED_DIGESTS}
    assert found == UNFUSED_DIGESTS


def test_fused_run_keeps_every_row_and_selection(golden_run, unfused_run):
    # Issue 14: with a changed order of arithmetic, V within 1e-12 relative and every
    # selection at every W the same. Every column but V (and the breakpoints' W, which
    # divide differences of log V) is equal; V within 1e-12 (measured: 2.5e-13).
    for name in ("frontier", "selection", "breakpoints", "stage1", "thresholds"):
        fused, unfused = (pq.read_table(run / f"{name}.parquet") for run in (golden_run, unfused_run))
        assert fused.column_names == unfused.column_names and fused.num_rows == unfused.num_rows, name
        for column in fused.column_names:
            x, y = fused[column].to_pylist(), unfused[column].to_pylist()
            if column in ("v", "w_from", "w_to", "w_fp", "w_fn", "w_fn_low", "w_fn_high"):
                x, y = np.array(x, dtype=float), np.array(y, dtype=float)
                rtol = 1e-12 if column == "v" else 1e-8  # a breakpoint W: (log V1 - log V2) / (d2 - d1)
                np.testing.assert_allclose(x, y, rtol=rtol, atol=0, err_msg=f"{name}.{column}")
            else:
                assert x == y or np.array_equal(x, y, equal_nan=True), f"{name}.{column}"


def test_digest_matches_the_shared_tool(golden_run):
    tool = ROOT.parent / "shared" / "tools" / "table_digest.py"
    if not tool.is_file():
        pytest.skip("../shared/tools/table_digest.py is not beside the checkout")
    out = subprocess.run(
        [sys.executable, str(tool), str(golden_run)], capture_output=True, text=True, check=True
    )
    shared = dict(line.split() for line in out.stdout.splitlines())
    assert shared == {name: _digest(golden_run / f"{name}.parquet") for name in DIGESTS}
    pinned = dict(line.split() for line in (tool.parent / "ci_digest.txt").read_text().splitlines())
    assert pinned == UNFUSED_DIGESTS
