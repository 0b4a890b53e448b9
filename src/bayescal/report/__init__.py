"""Figures and reports (matplotlib, HTML).

:func:`write_study_report` (:mod:`bayescal.report.study`) decides what the
report of a study shows and :func:`write_report` writes it (one self-contained
HTML page, its PNG figures and the posterior draws as CSV) from
:class:`ReportInputs`; :mod:`bayescal.report.figures` holds the figure
functions, each usable on its own.
"""

from bayescal.report.html import ReportInputs, write_report
from bayescal.report.study import write_study_report

__all__ = ["ReportInputs", "write_report", "write_study_report"]
