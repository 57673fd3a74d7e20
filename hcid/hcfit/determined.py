"""What a fit determines (SPEC 11): each parameter's status, with its reason.

A parameter is **undetermined** when its estimate lies on a search bound, its 95%
interval is wider than its plausible range (or its standard error is infinite: the
record does not see it at all), or its correlation with another parameter exceeds
:data:`CORRELATED` in magnitude (tau_pe with the neuromuscular pair, TI with tau_pt).
Every parameter of a fit that does not describe the record (its simulated u is further
from the measured u than u = 0 is: validation VAF below 0%, e.g. a model without
feedforward fitted to a person who uses it, whose loop the fit brings near instability)
is undetermined, whatever its standard error says.
Its value stays in the tables with the reason; group summaries and answer lines
leave it out. Two further flags mark a value that is determined but should be read
with care: outside its plausible range, or not told from 0 (se above |value|).
A parameter held at a literature value is ``fixed``.

The plausible ranges and their sources are in docs/parametric-fit.md.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from hcid.config.fit_settings import FEEDBACK_PARAMETERS
from hcid.errors import DataError
from hcid.hcfit.closed_loop import loop_is_stable
from hcid.hcfit.uncertainty import Z95

__all__ = [
    "CORRELATED",
    "DETERMINED",
    "FROM_MEDIANS",
    "GroupModel",
    "LITERATURE_NMS",
    "PLAUSIBLE",
    "Simulated",
    "group_model",
    "is_flagged",
    "is_on_bound",
    "is_undetermined",
    "nms_undetermined",
    "parameter_status",
    "reason",
]

#: A correlation above this (in magnitude) leaves both parameters of the pair undetermined.
CORRELATED = 0.95

#: Ranges within which values of each parameter have been reported for people tracking with
#: single-, double-integrator and second-order plants (sources in docs/parametric-fit.md).
PLAUSIBLE = {
    "Kpe": (0.05, 20.0),
    "TL": (0.0, 5.0),
    "tau_pe": (0.1, 0.6),
    "w_nms": (5.0, 20.0),
    "zeta_nms": (0.05, 1.0),
    "Kpt": (0.0, 1.5),
    "TI": (0.0, 1.0),
    "tau_pt": (-1.0, 1.0),
}

#: The neuromuscular system's values where a record does not determine it: those of the
#: paper's HC model (McRuer et al. 1968; Laurense et al. 2015; SPEC 1).
LITERATURE_NMS = {"w_nms": 10.1, "zeta_nms": 0.35}

#: The status of a determined parameter.
DETERMINED = "determined"

# Reasons that make a parameter undetermined (the first that holds is given).
_AT_BOUND = "at a search bound"
_INFINITE = "not seen by the data (infinite se)"
_WIDE = "95% interval wider than its plausible range"
_FIXED = "fixed at a literature value"
_NO_SE = "no standard error (its quadratic approximation fails or the estimator gives none)"
_FAILED = "in a failed fit (validation VAF below 0%)"
# Flags on a determined value.
_OUTSIDE = "outside its plausible range"
_ZERO = "not told from 0 (se above |value|)"
_UNDETERMINED_PREFIXES = (_AT_BOUND, _INFINITE, _WIDE, _FIXED, _NO_SE, _FAILED, "correlated with")


def _correlated(partner: str, r: float) -> str:
    return f"correlated with {partner} (r = {r:+.2f})"


def parameter_status(fit) -> dict[str, str]:
    """``{parameter: status}`` of an :class:`hcid.hcfit.HCFit`: :data:`DETERMINED`, or the reason
    it is undetermined or flagged (the first that holds, in the module notes' order)."""
    failed = _failed(fit)
    return {
        name: _FAILED if failed and name not in fit.fixed else status
        for name, status in _own_status(fit).items()
    }


def _failed(fit) -> bool:
    """Whether a fit describes its record worse than u = 0 (validation VAF below 0%; NaN, no
    record given, is no failure)."""
    return fit.vaf_validation < 0.0


def _own_status(fit) -> dict[str, str]:
    """Each parameter's status from its own estimate, se and correlation (the fit's VAF aside)."""
    out = {}
    for i, name in enumerate(fit.names):
        value, se = fit.estimates[i], fit.se[i]
        lo, hi = PLAUSIBLE[name]
        r = fit.correlation[i]
        if name in fit.fixed:
            out[name] = _FIXED
        elif fit.at_bound[i]:
            out[name] = _AT_BOUND
        elif math.isinf(se):
            out[name] = _INFINITE
        elif math.isnan(se):
            out[name] = _NO_SE
        elif 2.0 * Z95 * se > hi - lo:
            out[name] = _WIDE
        elif math.isfinite(r) and abs(r) > CORRELATED:
            out[name] = _correlated(fit.partner[i], r)
        elif not lo <= value <= hi:
            out[name] = _OUTSIDE
        elif se > abs(value):
            out[name] = _ZERO
        else:
            out[name] = DETERMINED
    return out


def is_undetermined(status: str) -> bool:
    """Whether a status (:func:`parameter_status`) leaves the value out of group summaries."""
    return status.startswith(_UNDETERMINED_PREFIXES)


def is_on_bound(status: str) -> bool:
    """Whether a status says the value sits on a search bound."""
    return status.startswith(_AT_BOUND)


def is_flagged(status: str) -> bool:
    """Whether a status marks a determined value to read with care (outside its plausible range,
    or not told from 0): kept in summaries, marked where shown."""
    return status in (_OUTSIDE, _ZERO)


def reason(status: str) -> str:
    """A status without its figures, to count runs by reason: ``correlated with TL``."""
    return status.split(" (r =")[0]


def nms_undetermined(fit) -> bool:
    """Whether the fit leaves either neuromuscular parameter undetermined (not counting ``fixed``,
    nor "no standard error": an estimator without standard errors, the frequency target, says
    nothing either way; nor a failed fit's: the pair's own estimates decide the refit)."""
    status = _own_status(fit)
    return any(
        is_undetermined(status[n]) and status[n] != _NO_SE and n not in fit.fixed for n in LITERATURE_NMS
    )


@dataclass(frozen=True)
class GroupModel:
    """A group's model built from what its runs' fits determine (SPEC 11).

    Attributes
    ----------
    values : dict of str to float
        Per parameter, the median over the runs that determine it; where none does, the
        literature value (neuromuscular pair) or the median over all runs brought into the
        parameter's plausible range. In a fallback, the values of the run taken, as fitted.
    taken : str
        Whose values these are: :data:`FROM_MEDIANS`, or the run taken in their place.
    undetermined : tuple of str
        The parameters no run determines (in the fallback: those the run taken does not).
    notes : tuple of str
        Why the medians were not taken, and every value its simulation changes beyond its
        routine rounding (a delay fitted at 0 s brought to one sample), in words.
    """

    values: dict
    taken: str
    undetermined: tuple[str, ...]
    notes: tuple[str, ...] = ()

    @property
    def source(self) -> str:
        """How the model was built, in one line: :data:`FROM_MEDIANS` exactly where nothing
        else was done, else whose values were taken with the notes in one pair of parentheses
        (``run 5's own model (the medians make an unstable loop with the plant; tau_pe ...)``)."""
        return f"{self.taken} ({'; '.join(self.notes)})" if self.notes else self.taken

    def noting(self, *notes: str) -> GroupModel:
        """The same model with ``notes`` added (what else its twins change, in words)."""
        return GroupModel(self.values, self.taken, self.undetermined, self.notes + notes)


@dataclass(frozen=True)
class Simulated:
    """A model's values as a simulation takes them (what :func:`group_model`'s ``simulated``
    gives, e.g. :func:`hcid.pipeline.twin_values.twin_model`).

    Attributes
    ----------
    values : dict of str to float
        The values as simulated, each in the range the simulation accepts.
    changes : tuple of str
        Each value brought into that range, in words (empty where none had to be).
    problem : str
        Why the simulation cannot take the model at all ("" where it can): a value that no
        simulation of a person could take, or a loop that is unstable as simulated.
    """

    values: dict
    changes: tuple[str, ...] = ()
    problem: str = ""


#: Whose values a group's model takes where its medians can make its twins (``GroupModel.taken``).
FROM_MEDIANS = "medians of the values its runs determine"


def group_model(
    fits: Sequence, labels: Sequence[str], num_c, den_c, simulated: Callable[[dict], Simulated] | None = None
) -> GroupModel:
    """The group's model from its runs' fits.

    Each parameter is the median over the runs whose fit determines it
    (:func:`is_undetermined`). Where those values cannot make the group's twins, the fallback
    is the run whose own model can and that lies nearest the medians (the sum over parameters
    of the squared difference over the parameter's plausible range). A model can make twins
    where its values as simulated make a stable loop with the plant (:func:`loop_is_stable`)
    and the simulation takes them. A failed fit (validation VAF below 0%) is never the
    fallback, nor in the medians of parameters no run determines (unless every fit failed).

    Parameters
    ----------
    fits : sequence of :class:`hcid.hcfit.HCFit`
        The group's runs' fits, each with the same parameters.
    labels : sequence of str
        The runs' names in the fallback's words (``run 3``).
    num_c, den_c : ndarray
        The plant's polynomials in s, highest power first.
    simulated : callable, optional
        A model's values as its twins simulate them (:class:`Simulated`); None: as they are.
        The simulation needs every value in its range: a value brought into it keeps the
        model's behaviour nearest what was fitted (a delay fitted at 0 s, on its bound, says
        only that it is shorter than the fit can tell from the neuromuscular lag, and one
        sample of the simulation is the shortest it can take); ``notes`` says so.

    Raises
    ------
    DataError
        Where neither the medians nor any run's own model can make twins: no fallback exists.
    """
    statuses = [parameter_status(f) for f in fits]
    names = fits[0].names
    described = [f for f in fits if not _failed(f)] or list(fits)
    values, none = {}, []
    for p in names:
        kept = [f.values[p] for f, st in zip(fits, statuses, strict=True) if not is_undetermined(st[p])]
        if kept:
            values[p] = float(np.median(kept))
            continue
        none.append(p)
        if p in LITERATURE_NMS:
            values[p] = LITERATURE_NMS[p]
        else:  # the data say little: the median over the runs, brought into its plausible range
            values[p] = float(np.clip(np.median([f.values[p] for f in described]), *PLAUSIBLE[p]))

    def why_not(candidate: dict) -> tuple[str, tuple[str, ...]]:
        """Why a model's values cannot make twins ("" where they can), and what simulating
        them changes."""
        sim = Simulated(candidate) if simulated is None else simulated(candidate)
        finite = all(math.isfinite(v) for v in sim.values.values())
        # Stable as simulated (the twins) and as fitted (the likelihood ratio's fits start there:
        # hcid.pipeline.line_statistics); a delay rounded to whole samples can tell them apart.
        loop = FEEDBACK_PARAMETERS  # the loop's stability reads these alone
        as_fitted = {p: candidate[p] for p in loop} if all(p in candidate for p in loop) else sim.values
        if finite and not (
            loop_is_stable(sim.values, num_c, den_c) and loop_is_stable(as_fitted, num_c, den_c)
        ):
            return "make an unstable loop with the plant", sim.changes
        if sim.problem or not finite:
            return f"cannot make twins: {sim.problem or 'a value is not finite'}", sim.changes
        return "", sim.changes

    medians_fail, changes = why_not(values)
    if not medians_fail:
        return GroupModel(values, FROM_MEDIANS, tuple(none), changes)

    def distance(fit) -> float:
        return sum(((fit.values[p] - values[p]) / (PLAUSIBLE[p][1] - PLAUSIBLE[p][0])) ** 2 for p in names)

    for _, i in sorted((distance(f), i) for i, f in enumerate(fits) if not _failed(f)):
        fails, changes = why_not(fits[i].values)
        if not fails:
            its_own = tuple(p for p in names if is_undetermined(statuses[i][p]))
            taken = f"{labels[i]}'s own model"
            return GroupModel(dict(fits[i].values), taken, its_own, (f"the medians {medians_fail}", *changes))
    raise DataError(
        "neither the medians of its runs' fits nor any run's own model (of those that describe "
        f"their data) makes a stable loop{' that its twins can simulate' if simulated else ''} "
        f"(the medians {medians_fail})"
    )
