"""Measured data: readers, the study clock (alignment, gaps, periods), a study's data."""

from bayescal.data.align import Gap, align, fill_gaps, periods_with_gaps
from bayescal.data.measured import MeasuredData, load_measured
from bayescal.data.readers import read_csv, read_epw, read_modelica_table, read_parquet
from bayescal.glossary import glossary_quantity

__all__ = [
    "Gap",
    "MeasuredData",
    "align",
    "fill_gaps",
    "glossary_quantity",
    "load_measured",
    "periods_with_gaps",
    "read_csv",
    "read_epw",
    "read_modelica_table",
    "read_parquet",
]
