"""On top of the library: the HTML report (:mod:`prefilter.report.report`) and ``prefilter demo``
(:mod:`prefilter.report.demo`), which renders every method's showcase scenes into one report."""

from prefilter.report.report import Report, line_plot

__all__ = ["Report", "line_plot"]
