"""Scan processing: the scan format, turntable synthesis, self-calibration, marker extraction,
sphere-centre estimation, quality gate and evaluation. Imports nothing of ours but the shared
kernel :mod:`markerplan` (version, error roots).

Scans in:

- :mod:`pipeline.scan_format`: the station-scan file format (real and simulated scans);
- :mod:`pipeline.pcap`: a Velodyne packet capture and turntable log -> a station scan;
- :mod:`pipeline.pointsets`: plain point sets (``.xyz``, ``.txt``, ``.csv``);
- :mod:`pipeline.sensor_noise`: the range noise of one return;
- :mod:`pipeline.rig`: the rig's frames and mounting offsets.

One station's chain:

- :mod:`pipeline.stages`: the validated stage configuration;
- :mod:`pipeline.process`: the chain (:func:`pipeline.process.process_station`), running
  :mod:`pipeline.synthesis`, :mod:`pipeline.calibration`, :mod:`pipeline.ground`,
  :mod:`pipeline.clustering`, :mod:`pipeline.gate`, :mod:`pipeline.sphere_fit` (the
  sphere-centre estimators, on the line-of-sight fits of :mod:`pipeline.line_of_sight_fit` and
  the geometric ones of :mod:`pipeline.geometric_sphere_fit`), :mod:`pipeline.quality` and
  :mod:`pipeline.evaluation`, with the compiled inner loops of :mod:`pipeline.kernels`.

A survey's stations and what comes out:

- :mod:`pipeline.survey`: the processing config of a survey's settings, and every scan file
  of a survey through the chain;
- :mod:`pipeline.marker_table`: the marker table (one row per candidate);
- :mod:`pipeline.fates`: where the chain lost each known marker (the stage and its reason);
- :mod:`pipeline.fate_table`: the fate table (one row per known marker in range of a scan, its
  fate and the planner's covariates: the detection model's input);
- :mod:`pipeline.results`: the tables and summary of ``markerplan process``;
- :mod:`pipeline.point_cloud_io`: classified clouds as LAS and PLY;
- :mod:`pipeline.range_study`: centre error and point density against distance.

:mod:`pipeline.network`: many stations' marker tables -> one adjusted network.
"""
