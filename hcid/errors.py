"""Exceptions of hcid.

Every error a user can cause (a bad config, a missing or corrupt data file, a
grid that cannot be fitted) is an :class:`HcidError`. The CLI turns these into
one line on stderr and exit code 2, in one place; anything else is a bug and
keeps its traceback.
"""

import numbers


class HcidError(Exception):
    """Base class of the errors hcid reports to the user as one line."""


class ConfigError(HcidError, ValueError):
    """A config key is unknown, of the wrong type, or out of range."""


class DataError(HcidError, ValueError):
    """A data file or table is missing, corrupt, or holds invalid values."""


class IdentificationError(HcidError, ValueError):
    """An identification request cannot be carried out on the given data."""


#: Longest quote of a value in an error message (a message stays one readable line).
QUOTE = 80


def quote(value: object) -> str:
    """A value as an error message quotes it: repr for strings, at most :data:`QUOTE` characters.

    Examples
    --------
    >>> quote("ft"), quote(2.5), len(quote("x" * 500))
    ("'ft'", '2.5', 80)
    """
    text = repr(value) if isinstance(value, str) else str(value)
    return text if len(text) <= QUOTE else text[: QUOTE - 3] + "..."


def checked_rate(rate: object, error: type[HcidError] = ConfigError) -> float:
    """A sample rate as a float number of Hz in (0, 1e6), else ``error`` in one line.

    Examples
    --------
    >>> checked_rate(25)
    25.0
    >>> checked_rate(float("nan"), DataError)
    Traceback (most recent call last):
    ...
    hcid.errors.DataError: rate: must be a positive number of Hz, got nan
    """
    if isinstance(rate, bool) or not isinstance(rate, numbers.Real) or not 0 < rate < 1e6:
        raise error(f"rate: must be a positive number of Hz, got {quote(rate)}")
    return float(rate)
