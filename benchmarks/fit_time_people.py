"""Wall time of the default parametric fit per CPHS recording, in whichever checkout runs it.

Fits every one of the 12 recordings of ../shared/data/cphs2017/ with and without feedforward by
``hcid.hcfit.fit_parametric(FitSettings(), ...)``, the checkout's default estimator, as ``hcid analyse``'s
step 2 does, one process, one fit at a time. Run it in two checkouts side by side to compare
defaults (issue 33: before and after):

    .venv/bin/python benchmarks/fit_time_people.py            # this checkout
    PYTHONPATH=/path/to/other .venv/bin/python benchmarks/fit_time_people.py
"""

from __future__ import annotations

import os
import statistics
import time
from pathlib import Path

import control
import numpy as np

import hcid
from hcid.hcfit import FitSettings, TrackingRecord, fit_parametric

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "cphs2017"
PLANTS = {"fo": control.tf([1.0], [1.0, 0.0]), "so": control.tf([1.0], [1.0, 1.0, 0.0])}


def main() -> None:
    settings = FitSettings()
    print(f"hcid from {Path(hcid.__file__).parent}; default target {settings.target}")
    columns = {"time": "time", "ft": "ref", "fd": "dis", "u": "inp", "theta": 6}
    seconds = {p: [] for p in PLANTS}
    used = set()
    for path in sorted(DATA.glob("*.csv")):
        plant = path.name.split("_")[1]
        (r,) = hcid.read_records(path, columns=columns, rate=25.0, lead_in=5.0).values()
        x = {k: np.asarray(getattr(r, k))[:1000] for k in ("ft", "fd", "e", "u")}
        record = TrackingRecord(x["ft"], x["e"], x["u"], 25.0, slice(63, 531), slice(531, 1000), fd=x["fd"])
        for ff in (True, False):
            start = time.perf_counter()
            fit = fit_parametric(settings, PLANTS[plant], ff, record=record, disturbance_at="input")
            seconds[plant].append(time.perf_counter() - start)
            used.add((plant, fit.target))
    for plant, s in seconds.items():
        print(f"{plant}: median {statistics.median(s):.3f} s per fit, total {sum(s):.2f} s ({len(s)} fits)")
    print(f"estimators used: {sorted(used)}; load average {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
