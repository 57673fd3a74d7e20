"""Study configuration: YAML parsed once, at the entry point, into frozen dataclasses.

A config names the HC models, the loop and remnant parameters, the forcing
functions, the timing, the realization seeds, the identification stages of
the registered methods, the selection settings and optionally how to read
measured data. :func:`describe_config` checks every value and reads nothing;
:func:`hcid.assembly.resolve.load_config` reads the file, and what it names, and
resolves what needs other layers. The numerical core only ever sees the
dataclasses of :mod:`hcid.config.types`.

Every error names the dotted key, what is allowed and what was received, e.g.
``identify.direct.na: must be an integer range [lo, hi] with 1 <= lo <= hi <= 30, got [0, 3]``.
"""

from hcid.config.parse import describe_config
from hcid.config.types import (
    Config,
    DataConfig,
    FileSignal,
    Forcing,
    Grid,
    HCModel,
    IdentifyConfig,
    Loop,
    Multisine,
    Plant,
    PlantByFactor,
    Segment,
    Segments,
    SelectionConfig,
    StageConfig,
    Timing,
    Window,
)

__all__ = [
    "Config",
    "DataConfig",
    "FileSignal",
    "Forcing",
    "Grid",
    "HCModel",
    "IdentifyConfig",
    "Loop",
    "Multisine",
    "Plant",
    "PlantByFactor",
    "Segment",
    "Segments",
    "SelectionConfig",
    "StageConfig",
    "Timing",
    "Window",
    "describe_config",
]
