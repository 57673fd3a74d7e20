"""The run report: Markdown and self-contained HTML with PNG figures, from a run's tables.

- :mod:`hcid.report.run`: the run's config and tables, read and checked once.
- :mod:`hcid.report.compute`, :mod:`hcid.report.verdicts`: what is shown, computed (pure).
- :mod:`hcid.report.sections`: one module per section, ``compute`` then ``render``.
- :mod:`hcid.report.figures`: drawing; :mod:`hcid.report.document`: Markdown and HTML.
- :mod:`hcid.report.build`: compute every section, then render and write.
"""

from hcid.report.build import Report, build_report

__all__ = ["Report", "build_report"]
