"""What pinning OpenBLAS's Haswell kernels costs (issue 47; hcid/_blas.py): `hcid run
configs/ci.yaml` in fresh run directories, alternately with the kernels hcid pins and with the
ones OpenBLAS picks for this CPU itself, side by side in one run.

    .venv/bin/python benchmarks/blas_kernels.py [--repeats 3] [--config configs/ci.yaml]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def own_kernels() -> str:
    """The kernels OpenBLAS picks for this CPU when nothing is set."""
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_CORETYPE"}
    probe = ("import numpy, threadpoolctl; print(next(i.get('architecture') for i in "
             "threadpoolctl.threadpool_info() if i['internal_api'] == 'openblas'))")  # fmt: skip
    return subprocess.run(
        [sys.executable, "-c", probe], env=env, capture_output=True, text=True
    ).stdout.strip()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--config", default="configs/ci.yaml")
    args = parser.parse_args()
    info = Path("/proc/cpuinfo").read_text().splitlines() if Path("/proc/cpuinfo").exists() else []
    cpu = next((line.split(":", 1)[1].strip() for line in info if "model name" in line), "?")
    own = own_kernels()
    print(f"CPU {cpu}; OpenBLAS's own kernels here: {own}; load {os.getloadavg()[0]:.2f}")
    walls: dict[str, list[float]] = {"Haswell": [], own: []}
    with tempfile.TemporaryDirectory(prefix="hcid-blas-") as tmp:
        for i in range(args.repeats):
            for kernels in walls:
                env = dict(os.environ, OPENBLAS_CORETYPE=kernels, OPENBLAS_NUM_THREADS="1")
                run = Path(tmp) / f"{kernels}-{i}"
                start = time.perf_counter()
                subprocess.run([str(ROOT / ".venv" / "bin" / "hcid"), "run", args.config, "--run", str(run),
                                "--quiet"], env=env, check=True, capture_output=True)  # fmt: skip
                walls[kernels].append(time.perf_counter() - start)
    base = statistics.median(walls["Haswell"])
    for kernels, w in walls.items():
        ratio = statistics.median(w) / base
        each = ", ".join(f"{x:.2f}" for x in w)
        median = statistics.median(w)
        print(f"{kernels:>10}: median {median:.2f} s over {len(w)} ({each}); {ratio:.3f} x Haswell's")
    print(f"load at the end {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
