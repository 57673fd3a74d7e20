"""Golden run of configs/ci.yaml: this tool's own output, pinned.

Source of every number below: `hcid run configs/ci.yaml` at commit 0f2e6b9 (before
the issue-9 refactor) and again at f4d80bc (after it), identical; numpy 2.4.6,
scipy 1.17.1, python-control 0.10.2, numba 0.68.1, pyarrow 26.0.1. A change that
moves any of them changes a result and must say so.
"""

from __future__ import annotations

import hashlib
import importlib.metadata
import os
import platform
import subprocess
import sys
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from .conftest import CI_CONFIG, ROOT

#: Content digests (sorted columns; names, types, values) as ../shared/tools/table_digest.py computes
#: them, equal to ../shared/tools/ci_digest.txt. They hold bit for bit with OpenBLAS's Haswell (AVX2)
#: kernels, which the golden run forces: on a CPU with AVX-512 OpenBLAS otherwise picks other kernels
#: (the loop discretisation's linear algebra), which change the last bits of every table (this
#: machine then gives e.g. simulations bf05ffee9c1af780).
DIGESTS = {
    "simulations": "00c6a5dbe626fe3a",
    "simulation_summary": "a5697bcb68eecbd5",
    "frontier": "2a0afb1d6b55ea53",
    "stage1": "1204f95cec38ebd0",
    "selection": "0874418f1af016d1",
    "breakpoints": "d44bfc2684291daa",
}
#: The digests hold bit for bit only with the packages they were made with.
DIGEST_VERSIONS = {"numpy": "2.4", "scipy": "1.17", "control": "0.10", "numba": "0.68"}


@pytest.fixture(scope="module")
def golden_run(tmp_path_factory):
    """`hcid run configs/ci.yaml` in a process of its own, with OpenBLAS's Haswell kernels."""
    run = tmp_path_factory.mktemp("golden") / "ci"
    env = dict(os.environ, OPENBLAS_CORETYPE="Haswell", OPENBLAS_NUM_THREADS="1")
    hcid = Path(sys.executable).parent / "hcid"
    subprocess.run([str(hcid), "run", str(CI_CONFIG), "--run", str(run), "--quiet"], env=env, check=True)
    return run


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


def test_content_digests(golden_run):
    if platform.machine() != "x86_64":
        pytest.skip("digests pinned with OpenBLAS's x86-64 Haswell kernels (rel= goldens still run)")
    for package, prefix in DIGEST_VERSIONS.items():
        version = importlib.metadata.version(package)
        if not version.startswith(prefix):
            pytest.skip(f"digests pinned with {package} {prefix}.x, found {version} (rel= goldens still run)")
    found = {name: _digest(golden_run / f"{name}.parquet") for name in DIGESTS}
    assert found == DIGESTS


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
    assert pinned == DIGESTS
