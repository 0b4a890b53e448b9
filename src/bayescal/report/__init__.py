"""Figures and reports (matplotlib, HTML).

:func:`write_report` writes the calibration report (one self-contained HTML
page, its PNG figures and the posterior draws as CSV) from
:class:`ReportInputs`; :mod:`bayescal.report.figures` holds the figure
functions, each usable on its own.
"""

from bayescal.report.html import ReportInputs, write_report

__all__ = ["ReportInputs", "write_report"]
