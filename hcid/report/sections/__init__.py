"""The report's sections, in order: each computes its data from the run, then renders it.

A section is a module with ``TITLE``, ``compute(run, done) -> data`` (pure:
reads the :class:`~hcid.report.run.RunTables` and the data of earlier sections
in ``done``, draws nothing) and ``render(data, doc)`` (adds text, tables and
figure drawings to the :class:`~hcid.report.document.Doc`). To add a section or
a figure, write or extend one module here and list it in :data:`SECTIONS`.
"""

from hcid.report.sections import (
    calibration,
    conditions,
    curves,
    data,
    effects,
    experiment,
    facts,
    handoff,
    hcfit,
    rates,
    responses,
    simulation,
    study,
    verdicts,
)

#: The sections in the order their data are computed (a section may read earlier ones'); the
#: verdicts appear only for the paper's experiment.
SECTIONS = (
    facts,
    experiment,
    simulation,
    curves,
    rates,
    responses,
    handoff,
    verdicts,
    calibration,
    data,
    hcfit,
)
#: The order a reader sees them: the answer (the paper's verdicts) first, then how it was found.
RENDER_ORDER = (verdicts, *(section for section in SECTIONS if section is not verdicts))

#: The sections of a measured study's report (a run of ``hcid analyse``): the answer first, no
#: paper sections; what differs between the compared factor's levels, and a whole experiment's
#: conditions combined per person, after it.
STUDY_SECTIONS = (study, effects, conditions)

__all__ = ["RENDER_ORDER", "SECTIONS", "STUDY_SECTIONS"]
