"""Make the SYNTHETIC example lab studies of configs/lab_example.yaml and configs/lab_weak.yaml.

Not measured on people: 4 subjects x 2 conditions x 3 trials simulated with hcid's own
simulator on the integrator example's experiment (plant 1.5/s, disturbance at the plant
input, the two 10-sine forcing functions), written one file per trial as a lab's logger
would: 60 Hz, 45 s with a 5 s lead-in, '#' lines with the column names on the last one,
the factors in the file name (``{subject}_{condition}_trial{trial}.csv``).

- ``lab_example``: in ``pursuit`` the target is shown and every subject uses feedforward
  (Kpt 0.6 to 1.0); in ``compensatory`` only the error is shown and no subject does (Kpt = 0).
  (A condition whose name starts with ``pursuit`` has feedforward: benchmarks/lab_study.py makes
  larger studies with :func:`make`.)
- ``lab_weak``: the same design, but the feedforward is weak (Kpt 0.12 to 0.25) and the
  remnant twice as strong: twins that no W separates (the report's honest answer).

Subjects differ in their parameters (STUDIES below; the same feedback in both conditions);
every trial has its own remnant seed. Run from the project root:

    .venv/bin/python configs/lab_example/make.py            # both studies
    .venv/bin/python configs/lab_example/make.py lab_weak   # one
"""

import dataclasses
import sys
from pathlib import Path

from hcid.assembly.resolve import load_config
from hcid.config import HCModel
from hcid.loop.simulate import remnant_gain, simulate_realization

HERE = Path(__file__).resolve().parent
RATE = 60.0  # Hz, the logger's
TRIAL = 45.0  # s: 5 s lead-in + the 40 s measurement window
TRIALS = (1, 2, 3)
CONDITIONS = ("pursuit", "compensatory")
#: Each study's subjects' true parameters: feedback (both conditions), then feedforward (pursuit
#: only); the remnant's gain as a multiple of the integrator example's; the first remnant seed.
STUDIES = {
    "lab_example": {
        "truth": {
            "S1": {"Kpe": 2.0, "TL": 0.15, "tau_pe": 0.24, "Kpt": 0.8, "TI": 0.20, "tau_pt": 0.20},
            "S2": {"Kpe": 2.4, "TL": 0.10, "tau_pe": 0.28, "Kpt": 1.0, "TI": 0.15, "tau_pt": 0.25},
            "S3": {"Kpe": 1.7, "TL": 0.20, "tau_pe": 0.22, "Kpt": 0.6, "TI": 0.25, "tau_pt": 0.15},
            "S4": {"Kpe": 2.2, "TL": 0.12, "tau_pe": 0.30, "Kpt": 0.9, "TI": 0.20, "tau_pt": 0.30},
        },
        "remnant": 1.0,
        "seed": 3000,
    },
    "lab_weak": {
        "truth": {
            "S1": {"Kpe": 2.0, "TL": 0.15, "tau_pe": 0.24, "Kpt": 0.20, "TI": 0.20, "tau_pt": 0.20},
            "S2": {"Kpe": 2.4, "TL": 0.10, "tau_pe": 0.28, "Kpt": 0.25, "TI": 0.15, "tau_pt": 0.25},
            "S3": {"Kpe": 1.7, "TL": 0.20, "tau_pe": 0.22, "Kpt": 0.12, "TI": 0.25, "tau_pt": 0.15},
            "S4": {"Kpe": 2.2, "TL": 0.12, "tau_pe": 0.30, "Kpt": 0.18, "TI": 0.20, "tau_pt": 0.30},
        },
        "remnant": 2.0,
        "seed": 5000,
    },
}
#: lab_example's truth, by subject (tests and benchmarks compare with it).
TRUTH = STUDIES["lab_example"]["truth"]


def model(subject: str, condition: str, truth: dict = TRUTH) -> HCModel:
    """The subject's HC model in the condition: feedforward only where the condition's name
    starts with ``pursuit``."""
    p = truth[subject]
    if not condition.startswith("pursuit"):
        return HCModel(f"{subject}_{condition}", 0.0, 0.0, 0.0, p["Kpe"], p["TL"], p["tau_pe"])
    return HCModel(f"{subject}_{condition}", p["Kpt"], p["TI"], p["tau_pt"], p["Kpe"], p["TL"], p["tau_pe"])


def make(study: str | dict, folder: Path) -> None:
    """Write a study's files into ``folder``: one of STUDIES by name, or a spec of the same
    keys (``truth``, ``remnant``, ``seed``, and optionally ``conditions`` and ``trials``)."""
    spec = STUDIES[study] if isinstance(study, str) else study
    config = load_config(HERE.parent / "integrator_example.yaml")
    # 300 Hz, written at 60 Hz; two 40 s periods (periodic for the decimation's FFT), the
    # last 45 s of them written.
    timing = dataclasses.replace(
        config.timing, sim_rate=300.0, output_rate=RATE, run_in=10.0, window=80.0, periods=1
    )
    config = dataclasses.replace(config, timing=timing)
    kn = spec["remnant"] * remnant_gain(config)
    n = round(TRIAL * RATE)
    seed = spec["seed"]
    folder.mkdir(exist_ok=True)
    for subject in spec["truth"]:
        for condition in spec.get("conditions", CONDITIONS):
            for trial in spec.get("trials", TRIALS):
                seed += 1
                r = simulate_realization(config, model(subject, condition, spec["truth"]), seed, kn)
                lines = [
                    "# SYNTHETIC: made by configs/lab_example/make.py with the hcid simulator, not measured",
                    f"# subject {subject}, condition {condition}, trial {trial}, remnant seed {seed}",
                    "# time,target,disturbance,error,stick",
                ]
                for k in range(n):
                    j = r.t.size - n + k
                    lines.append(f"{k / RATE:.6f},{r.ft[j]:.7g},{r.fd[j]:.7g},{r.e[j]:.7g},{r.u[j]:.7g}")
                path = folder / f"{subject}_{condition}_trial{trial}.csv"
                path.write_text("\n".join(lines) + "\n")


def main(argv: list[str]) -> None:
    for study in argv or list(STUDIES):
        make(study, HERE.parent / study)


if __name__ == "__main__":
    main(sys.argv[1:])
