"""Make the synthetic example data file of configs/example_data.yaml.

SYNTHETIC, made with hcid's own simulator so a walkthrough and the tests have
a file in the layout of a measured one: three runs of an FF-like controller
(Kpt = 0.6, TL = 0.35 s; otherwise configs/paper.yaml's FF model), remnant
seeds 1001..1003, 25 Hz. Run from the project root:

    .venv/bin/python configs/example_data/make.py
"""

import dataclasses
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.csv as pacsv

from hcid.assembly.resolve import load_config
from hcid.loop.simulate import remnant_gain, simulate_realization

HERE = Path(__file__).resolve().parent


def main() -> None:
    config = load_config(HERE.parent / "paper.yaml")
    subject = dataclasses.replace(config.model("FF"), name="subject", Kpt=0.6, TL=0.35)
    kn = remnant_gain(config)
    columns = {name: [] for name in ("trial", "time_s", "target", "disturbance", "error", "stick")}
    for trial, seed in enumerate((1001, 1002, 1003), start=1):
        r = simulate_realization(config, subject, seed, kn)
        columns["trial"].append(np.full(r.t.size, trial))
        columns["time_s"].append(np.round(r.t, 6))
        for name, values in (("target", r.ft), ("disturbance", r.fd), ("error", r.e), ("stick", r.u)):
            columns[name].append(values)
    table = pa.table({k: np.concatenate(v) for k, v in columns.items()})
    pacsv.write_csv(table, HERE / "subject_synthetic.csv")


if __name__ == "__main__":
    main()
