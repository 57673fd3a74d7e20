"""Make the SYNTHETIC data file of configs/integrator_example.yaml.

Not measured on a person: four 45 s trials simulated with hcid's own simulator,
an FF controller (Kpt = 0.7, TI = 0.2 s, tau_pt = 0.2 s, Kpe = 2.2, TL = 0,
tau_pe = 0.25 s; remnant seeds 2001..2004) on the example's integrator plant with
the disturbance at its input, simulated at 300 Hz and written at 60 Hz as a lab's
logger would: '#' header lines, its own column names, the system output instead of
the error. Run from the project root:

    .venv/bin/python configs/integrator_example/make.py
"""

import dataclasses
from pathlib import Path

from hcid.assembly.resolve import load_config
from hcid.config import HCModel
from hcid.loop.simulate import remnant_gain, simulate_realization

HERE = Path(__file__).resolve().parent
RATE = 60.0  # Hz, the logger's
TRIAL = 45.0  # s: 5 s lead-in + the 40 s measurement window
SEEDS = (2001, 2002, 2003, 2004)


def main() -> None:
    config = load_config(HERE.parent / "integrator_example.yaml")
    # 300 Hz, written at 60 Hz; keep two 40 s periods (periodic for the decimation's FFT)
    # and write the last 45 s of them.
    timing = dataclasses.replace(
        config.timing, sim_rate=300.0, output_rate=RATE, run_in=10.0, window=80.0, periods=1
    )
    config = dataclasses.replace(config, timing=timing)
    subject = HCModel("subject", Kpt=0.7, TI=0.2, tau_pt=0.2, Kpe=2.2, TL=0.0, tau_pe=0.25)
    kn = remnant_gain(config)
    n = round(TRIAL * RATE)
    lines = [
        "# SYNTHETIC data made by configs/integrator_example/make.py with the hcid simulator, not measured",
        "# integrator plant 1.5/s, disturbance at the plant input, 60 Hz, 45 s trials with a 5 s lead-in",
        "# subject model: Kpt 0.7, TI 0.2 s, tau_pt 0.2 s, Kpe 2.2, TL 0, tau_pe 0.25 s; seeds "
        + ", ".join(map(str, SEEDS)),
        "trial,time,target,control_output,disturbance,system_output",
    ]
    for trial, seed in enumerate(SEEDS, start=1):
        r = simulate_realization(config, subject, seed, kn)
        for k in range(n):
            j = r.t.size - n + k
            lines.append(f"{trial},{k / RATE:.9f},{r.ft[j]:.9g},{r.u[j]:.9g},{r.fd[j]:.9g},{r.theta[j]:.9g}")
    (HERE / "trials_synthetic.csv").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
