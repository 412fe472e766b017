"""Studies that run the whole chain (simulate -> process -> fit) to answer one question.

- :mod:`planner.studies.range_experiment`: the published range experiment, simulated;
- :mod:`planner.studies.field_summary`: what a field experiment measured, per LiDAR position;
- :mod:`planner.studies.sensor_calibration`: a sensor profile's free parameters fitted to a field
  experiment by simulation;
- :mod:`planner.studies.calibration_report`: the files of ``markerplan calibrate-sensor``;
- :mod:`planner.studies.network`: what planning a network instead of known control changes;
- :mod:`planner.studies.figure_calibration`: how often the 95 % figures are exceeded, by
  Monte-Carlo through the adjustment;
- :mod:`planner.studies.layout_geometry`: a planned layout's geometry as a file, for checking
  a large site's layouts again without ray casting;
- :mod:`planner.studies.loss_study`: where the station chain loses markers, against the
  planner's covariates of each pair (the fate tables of the detection model).
"""
