"""The table schemas the chain's results are written in and read back from (by
:mod:`pipeline.network`, :mod:`error_model` and :mod:`planner`).

- :mod:`pipeline.tables.marker_table`: the marker table (one row per candidate marker per
  station; the error model's input);
- :mod:`pipeline.tables.fate_table`: the fate table (one row per known marker in range of a
  scan, its fate and the planner's covariates: the detection model's input).
"""
