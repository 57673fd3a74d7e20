"""How ``hcid analyse`` groups and decides: its options (:class:`AnalysisOptions`), checked when
made, and their defaults."""

from __future__ import annotations

import numbers
from dataclasses import dataclass
from enum import StrEnum

from hcid.errors import ConfigError
from hcid.pipeline.evidence import MAX_FB_TWINS

__all__ = ["FF_TWINS", "TWINS", "AnalysisOptions", "FfTwinChoice"]

#: Realizations of each twin (FB and FF) per group.
TWINS = 20


#: Where the FF twin's feedforward path comes from: ``own`` (the group's fitted model, SPEC 10),
#: ``study`` (the group with the largest fitted Kpt: a power question for a group whose own
#: fitted feedforward is too weak to tell its twins apart) or ``auto`` (own; study for a group
#: whose own twins no W separates, for each method without a safe interval on its own twins).
class FfTwinChoice(StrEnum):
    """``--ff-twin``'s values (:data:`FF_TWINS`)."""

    AUTO = "auto"
    OWN = "own"
    STUDY = "study"


FF_TWINS = tuple(c.value for c in FfTwinChoice)


@dataclass(frozen=True)
class AnalysisOptions:
    """How ``hcid analyse`` groups and decides (its options; checked when made).

    ``by``: the factors whose runs share one calibrated W (None: ``condition`` if the data set
    has it, else one group; a string is split at commas, as ``--by`` is; a config's plant factor,
    ``loop.plant.by``, is added where missing: :meth:`hcid.pipeline.plants.RunPlants.grouping`); ``twins``:
    realizations of each twin per group and forcing set (also the batch in which more FB twins
    are drawn); ``max_fb_twins``: the most FB twins per forcing set for the runs' p-values
    (None: :data:`MAX_FB_TWINS`, or ``twins`` if more); ``ff_twin``: :data:`FF_TWINS`;
    ``alpha``: each run's test level; ``fdr``: control the false discovery rate over the
    study's runs instead; ``person``: the factor naming the people whose conditions are combined
    in a whole experiment (None: ``subject`` where the data set has it, else one person);
    ``compare``: a factor whose levels are compared across people (:mod:`hcid.pipeline.effects`)."""

    by: tuple[str, ...] | None = None
    twins: int = TWINS
    max_fb_twins: int | None = None
    ff_twin: str = "auto"
    alpha: float = 0.05
    fdr: bool = False
    person: str | None = None
    compare: str | None = None

    def __post_init__(self) -> None:
        if isinstance(self.by, str):  # "subject,condition", as --by takes it
            object.__setattr__(self, "by", tuple(b.strip() for b in self.by.split(",") if b.strip()))
        if self.by is not None and not all(isinstance(b, str) and b for b in self.by):
            raise ConfigError(f"by (--by): must be factor names, got {self.by!r}")
        for name in ("twins", "max_fb_twins"):
            value = getattr(self, name)
            if isinstance(value, numbers.Integral) and not isinstance(value, bool):
                object.__setattr__(self, name, int(value))  # numpy's too
            elif not (value is None and name == "max_fb_twins"):
                raise ConfigError(f"{name} (--{name.replace('_', '-')}): must be an integer, got {value!r}")
        if not 2 <= self.twins <= 1000:
            raise ConfigError(f"twins (--twins): must be an integer in [2, 1000], got {self.twins}")
        if not self.twins <= self.most_fb_twins <= 10000:
            raise ConfigError(
                f"max_fb_twins (--max-fb-twins): must be an integer in [twins ({self.twins}), 10000], "
                f"got {self.max_fb_twins}"
            )
        if not (isinstance(self.alpha, float | int) and 0.0 < self.alpha < 1.0):
            raise ConfigError(f"alpha (--alpha): must be a level in (0, 1), got {self.alpha!r}")
        for name in ("person", "compare"):
            value = getattr(self, name)
            if value is not None and not (isinstance(value, str) and value.isidentifier()):
                raise ConfigError(f"{name} (--{name}): must be a factor name, got {value!r}")
        if self.ff_twin not in FF_TWINS:
            raise ConfigError(
                f"ff_twin (--ff-twin): must be one of {', '.join(FF_TWINS)}, got {self.ff_twin!r}"
            )

    @property
    def most_fb_twins(self) -> int:
        """The default: p down to 0.01, and never fewer than the calibration's twins."""
        return max(MAX_FB_TWINS, self.twins) if self.max_fb_twins is None else self.max_fb_twins
