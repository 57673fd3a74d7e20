"""The paper's figures and fixed numbers (SPEC sections 5 and 6), in one place.

The figures are printed beside this tool's, never tuned to. The fixed numbers
are those of the paper's own analysis that are not properties of a config.
"""

from hcid.config import Multisine, Segments

#: Table 2: RMS(e) in deg per model.
RMS_E_DEG = {"FB": 2.43, "FF": 1.22}
#: Section 4: realizations per model, the n of the paper's W_FP (an extreme over n realizations).
N_REALIZATIONS = 50
#: Section 5.2: the largest W with a false positive (FB), per method.
W_FP = {"direct": 1.2e-2, "indirect": 3.7e-2}
#: Section 5.2: FF mean nb_ft >= 2 up to this W, both methods.
W_FN = 0.26
#: Fig. 9: the W at which FF models lose their feedforward.
W_NO_FEEDFORWARD = 0.47
#: Fig. 7a: the feedforward gain the FB false positives resemble.
KPT_FALSE_POSITIVE = 0.2
#: Section 5 (SPEC 5): frequencies (rad/s) at which identified paths are compared with the true ones.
FREQUENCY_RANGE = (0.1, 30.0)
#: Section 5.3: the feedforward is accurate below this frequency (rad/s) at W_BIC.
FEEDFORWARD_ACCURATE_BELOW = 3.0
#: Fig. 10: direct's errors below indirect's under these frequencies (rad/s), per path.
DIRECT_BETTER_BELOW = {"hft": 8.0, "he": 7.0}

#: The paper's plant Yc = Kc wb / (s (s + wb)), Kc = 2.75, wb = 2: (numerator, denominator) in s.
PLANT = ((5.5,), (1.0, 2.0, 0.0))
#: SPEC 1: w_nms, zeta_nms, w_n, zeta_n and var(n)/var(u) of the paper's loop.
LOOP = (10.1, 0.35, 12.7, 0.26, 0.15)
#: Table 2: the FB and FF models (rad/s, s).
MODELS = {
    "FB": {"Kpt": 0.0, "TI": 0.0, "tau_pt": 0.0, "Kpe": 0.75, "TL": 0.4, "tau_pe": 0.24},
    "FF": {"Kpt": 0.8, "TI": 0.25, "tau_pt": 0.35, "Kpe": 0.75, "TL": 0.4, "tau_pe": 0.24},
}


def is_paper_experiment(config) -> bool:
    """Whether a config simulates the paper's experiment with the paper's HC models: its plant,
    the disturbance at the plant output, a multisine disturbance, a segments target, the
    neuromuscular and remnant parameters of SPEC 1, and every model one of Table 2's (the
    claims of SPEC 6 and Table 2's RMS(e) are compared only then)."""
    loop = config.loop
    return (
        config.simulates
        and (loop.plant.num, loop.plant.den) == PLANT
        and (loop.w_nms, loop.zeta_nms, loop.w_n, loop.zeta_n, loop.remnant_ratio) == LOOP
        and loop.disturbance_at == "output"
        and isinstance(config.disturbance, Multisine)
        and isinstance(config.target, Segments)
        and all(_parameters(m) == MODELS.get(m.name) for m in config.models)
    )


def _parameters(model) -> dict[str, float]:
    return {k: getattr(model, k) for k in ("Kpt", "TI", "tau_pt", "Kpe", "TL", "tau_pe")}
