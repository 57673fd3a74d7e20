"""The HC model's discretised paths against scipy.signal.freqz and the continuous-time truth (SPEC 1)."""

import numpy as np
import pytest
from scipy import signal as sps

from hcid.loop.hcmodel import DiscreteLoop, feedback_path, feedforward_path, plant, true_response

W = np.geomspace(0.1, 30.0, 60)


@pytest.fixture(scope="module")
def ff_loop(paper_config):
    return DiscreteLoop.build(paper_config.model("FF"), paper_config.loop, paper_config.timing.sim_dt)


@pytest.mark.parametrize("which", ["feedforward", "feedback", "plant", "remnant"])
def test_discrete_response_equals_freqz(ff_loop, which):
    # DiscreteLoop.response against scipy.signal.freqz of the same (b, a), times the
    # whole-sample delay z^-L (24 samples for He, 35 for Hft at 100 Hz).
    b, a = getattr(ff_loop, which)
    delay = {"feedforward": ff_loop.delay_ft, "feedback": ff_loop.delay_e}.get(which, 0)
    _, h = sps.freqz(b, a, worN=W * ff_loop.dt)
    expected = h * np.exp(-1j * W * ff_loop.dt * delay)
    np.testing.assert_allclose(ff_loop.response(which, W), expected, rtol=1e-10)


def test_delays_are_whole_samples(ff_loop):
    assert (ff_loop.delay_ft, ff_loop.delay_e) == (35, 24)  # SPEC 1: 0.35 s and 0.24 s at 100 Hz


@pytest.mark.parametrize("path", ["feedforward", "feedback"])
def test_tustin_paths_match_the_continuous_truth(paper_config, ff_loop, path):
    # Tustin maps s to (2/T)(z-1)/(z+1): the frequency warps by tan(wT/2)/(T/2), a relative
    # (wT)^2/12 = 7.5e-4 at 3 rad/s with T = 0.01 s; allow 2e-3 below 3 rad/s.
    hft, he = true_response(paper_config.model("FF"), paper_config.loop, W)
    truth = hft if path == "feedforward" else he
    low = W <= 3.0
    h = ff_loop.response(path, W)
    np.testing.assert_allclose(h[low], truth[low], rtol=2e-3)


def test_paths_are_proper_products_with_the_nms(paper_config):
    # SPEC 1: Ynms*Ypt and Ynms*Ype are proper; Ypt = Kpt / Yc / (TI s + 1)^2 (relative degree
    # 2 + 2 - 2 = 2 for the paper's plant), Ype = Kpe (TL s + 1) (relative degree 2 - 1 = 1).
    loop, ff = paper_config.loop, paper_config.model("FF")
    for sys, rel_degree in ((feedforward_path(ff, loop), 2), (feedback_path(ff, loop), 1)):
        num, den = np.trim_zeros(sys.num[0][0], "f"), sys.den[0][0]
        assert len(den) - len(num) == rel_degree
    # Yc = Kc wb / (s (s + wb)) at s = j: 2.75 * 2 / (j (j + 2)).
    assert complex(plant(loop)(1j)) == pytest.approx(5.5 / (1j * (1j + 2)))


# --------------------------------------------------------------------------- python-control's bits


def _control_discrete_loop(model, loop, dt):
    """The reference: the paths formed and discretised by python-control itself (what
    hcid.loop.hcmodel did before hcid.loop._lti), as (b, a) pairs."""
    import control

    def disc(sys, method):
        d = control.sample_system(sys, dt, method=method)
        num = np.atleast_1d(np.squeeze(np.asarray(d.num[0][0], dtype=np.float64)))
        den = np.atleast_1d(np.squeeze(np.asarray(d.den[0][0], dtype=np.float64)))
        b = np.concatenate([np.zeros(den.size - num.size), num])
        return b / den[0], den / den[0]

    yc = loop.plant
    nms = control.tf([loop.w_nms**2], [1.0, 2 * loop.zeta_nms * loop.w_nms, loop.w_nms**2])
    out = {
        "feedback": disc(nms * control.tf([model.Kpe * model.TL, model.Kpe], [1.0]), "bilinear"),
        "plant": disc(control.tf(list(yc.num), list(yc.den)), "bilinear"),
        "remnant": disc(
            control.tf(
                [loop.w_n**3],
                np.polymul([1.0, 2 * loop.zeta_n * loop.w_n, loop.w_n**2], [1.0, loop.w_n]),
            ),
            "zoh",
        ),
    }
    if model.has_feedforward:
        inverse = control.tf(list(yc.den), list(yc.num))
        lag = control.tf([1.0], [model.TI**2, 2 * model.TI, 1.0])
        out["feedforward"] = disc(control.minreal(model.Kpt * nms * inverse * lag, verbose=False), "bilinear")
    return out


def _bits(x):
    return np.ascontiguousarray(x, dtype=np.float64).view(np.int64)


def _loops():
    """Every config's loop and models, and 40 random ones over the plants hcid knows."""
    from pathlib import Path

    from hcid.assembly.resolve import load_config
    from hcid.config.types import HCModel, Loop, Plant

    root = Path(__file__).resolve().parent.parent / "configs"
    for path in sorted(root.glob("*.yaml")):
        config = load_config(path)
        if config.models:
            for model in config.models:
                yield f"{path.stem}:{model.name}", model, config.loop, config.timing.sim_dt
    rng = np.random.default_rng(20261127)
    plants = [
        Plant.second_order(2.75, 2.0),
        Plant.integrator(1.5),
        Plant.double_integrator(3.0),
        Plant("transfer_function", (2.0, 1.0), (1.0, 3.0, 2.0, 0.0), "custom"),
        Plant("transfer_function", (2.0,), (1.0,), "a static gain"),
        Plant("transfer_function", (1.0, 2.0), (1.0, 1.0), "biproper"),
        Plant("transfer_function", (0.0, 0.0, 1.5), (0.0, 1.0, 0.7, 0.0), "leading zeros"),
    ]
    for i in range(40):
        yc = plants[i % len(plants)]
        loop = Loop(
            yc, rng.uniform(6, 14), rng.uniform(0.1, 0.6), rng.uniform(5, 20), rng.uniform(0.1, 0.7), 0.15
        )
        kpt = 0.0 if i % 5 == 0 else rng.uniform(0.3, 1.2)
        model = HCModel(
            f"r{i}",
            kpt,
            rng.uniform(0.05, 0.5),
            rng.uniform(0.1, 0.5),
            rng.uniform(0.5, 3),
            rng.uniform(0.05, 1.0),
            rng.uniform(0.1, 0.4),
        )
        yield f"random {i} ({yc.text})", model, loop, [0.01, 0.005, 0.002][i % 3]
    # minreal cancelling: the plant's den holds the lag (TI s + 1)^2, which the IFM divides by.
    ti, w, z = 0.2, 10.0, 0.3
    den = tuple(np.polymul([ti**2, 2 * ti, 1.0], [1.0, 0.0]))
    yc = Plant("transfer_function", (5.0,), den, "cancels")
    model = HCModel("cancel", 0.8, ti, 0.2, 1.0, 0.3, 0.2)
    yield "cancelling", model, Loop(yc, w, z, 12.0, 0.3, 0.15), 0.01
    yield (
        "Kpe = 0",
        HCModel("zero", 0.8, ti, 0.2, 0.0, 0.3, 0.2),
        Loop(Plant.integrator(1.5), w, z, 12.0, 0.3, 0.15),
        0.01,
    )


@pytest.mark.filterwarnings("ignore:Badly conditioned filter coefficients")  # Kpe = 0, as scipy
@pytest.mark.parametrize(
    ("name", "model", "loop", "dt"), list(_loops()), ids=lambda x: x if isinstance(x, str) else ""
)
def test_discretised_paths_are_python_controls_bits(name, model, loop, dt):
    # Source: python-control's own tf products, minreal and sample_system (the reference path,
    # _control_discrete_loop); hcid.loop._lti repeats its numpy calls, so every coefficient
    # must be the same 64 bits, not merely close.
    built = DiscreteLoop.build(model, loop, dt)
    for which, (b_ref, a_ref) in _control_discrete_loop(model, loop, dt).items():
        b, a = getattr(built, which)
        assert np.array_equal(_bits(b), _bits(b_ref)), (name, which, b, b_ref)
        assert np.array_equal(_bits(a), _bits(a_ref)), (name, which, a, a_ref)


def test_public_paths_are_the_same_transfer_functions(paper_config):
    # The python-control objects the report and the fits read: the same coefficients as
    # python-control's own products.
    import control

    model, loop = paper_config.model("FF"), paper_config.loop
    nms = control.tf([loop.w_nms**2], [1.0, 2 * loop.zeta_nms * loop.w_nms, loop.w_nms**2])
    inverse = control.tf(list(loop.plant.den), list(loop.plant.num))
    lag = control.tf([1.0], [model.TI**2, 2 * model.TI, 1.0])
    ref = control.minreal(model.Kpt * nms * inverse * lag, verbose=False)
    got = feedforward_path(model, loop)
    assert np.array_equal(_bits(got.num[0][0]), _bits(ref.num[0][0]))
    assert np.array_equal(_bits(got.den[0][0]), _bits(ref.den[0][0]))


def test_feedforward_poles_are_python_controls():
    # Source: python-control's TransferFunction.poles() (through _common_den: near-real roots
    # made real, multiplied out, rooted again). Plants with zeros on the imaginary axis put
    # feedforward poles' real parts at rounding level, where a plain np.roots(den) flips the
    # stability verdict of hcid.loop.hcmodel.check_closed_loops (found by a review: 2 of 400).
    import control

    from hcid.loop import _lti

    rng = np.random.default_rng(3)
    for _ in range(300):
        w2 = rng.uniform(0.05, 3.0)
        num = [rng.uniform(0.1, 2.0), 0.0, rng.uniform(0.1, 2.0) * w2]
        den = np.polymul(np.poly(-rng.uniform(0.5, 30.0, 3)), [1.0, 0.0])
        polys = _lti.tf(den, num)  # the inverse plant: its poles are the plant's zeros
        got = _lti.poles(polys)
        ref = control.tf(*polys).poles()
        assert np.array_equal(got.view(np.float64), np.asarray(ref, dtype=complex).view(np.float64))
