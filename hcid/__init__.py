"""hcid: identify human-controller models from closed-loop manual-control data.

The public API (:mod:`hcid.api`): :func:`read_records`, :class:`Experiment` and
:class:`Plant`, :func:`identify` returning an :class:`IdentificationResult`
(``select(w)``, ``selection_path()``), the :class:`SelectedModel` it selects
(``frequency_response``, ``simulate``) and :func:`fit_hc`; a whole measured study with
:func:`analyse` (``hcid analyse``: :class:`AnalysisOptions`, :class:`Execution`, returning an
:class:`AnalysisRun`) and :func:`build_report`. Names are loaded on first use, so
``import hcid`` (and ``hcid --help``) stays fast.
"""

from importlib import import_module
from importlib.metadata import PackageNotFoundError, version

from hcid._blas import pin_openblas

pin_openblas()  # before anything imports numpy: the same bits on every machine (hcid/_blas.py)

try:
    __version__ = version("hcid")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0+unknown"

#: Public name -> the module that defines it.
_EXPORTS = {
    "AnalysisOptions": "hcid.pipeline.options",
    "AnalysisRun": "hcid.pipeline.analyse",
    "Execution": "hcid.pipeline.execution",
    "analyse": "hcid.pipeline.analyse",
    "build_report": "hcid.report",
    "Experiment": "hcid.api",
    "IdentificationResult": "hcid.api",
    "Record": "hcid.api",
    "fit_hc": "hcid.api",
    "identification_settings": "hcid.api",
    "identify": "hcid.api",
    "read_records": "hcid.api",
    "Plant": "hcid.config",
    "Multisine": "hcid.config",
    "Segments": "hcid.config",
    "SelectedModel": "hcid.hcfit.selected",
    "SelectionPath": "hcid.selection.over_w",
    "Frontier": "hcid.selection.frontier",
    "HCFit": "hcid.hcfit",
    "HcidError": "hcid.errors",
    "ConfigError": "hcid.errors",
    "DataError": "hcid.errors",
    "IdentificationError": "hcid.errors",
}

__all__ = ["__version__", *sorted(_EXPORTS)]


def __getattr__(name: str):
    if name in _EXPORTS:
        value = getattr(import_module(_EXPORTS[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'hcid' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
