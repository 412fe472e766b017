"""Scan processing: the scan format, turntable synthesis, self-calibration, marker extraction,
sphere-centre estimation, quality gate and evaluation. Imports nothing of ours but the shared
kernel :mod:`markerplan` (version, error roots).

Each package imports only those listed before it (``tests/test_layering.py`` holds this):

- :mod:`pipeline.kernels`: the compiled inner loops (numba) of the rig's frame transforms, the
  ground, the gate and the sphere fits;
- :mod:`pipeline.tables`: the marker- and fate-table schemas, written by the chain and read by
  :mod:`error_model` and :mod:`planner`;
- :mod:`pipeline.scans`: scans in (the station-scan format, pcap and point-set readers) and the
  rig and range-noise contract shared with the simulator;
- :mod:`pipeline.sphere_centres`: the sphere-centre estimators;
- :mod:`pipeline.chain`: one station's chain (:func:`pipeline.chain.process.process_station`):
  synthesis, self-calibration, ground, clustering, gate, centre fits, quality gate, evaluation;
- :mod:`pipeline.surveys`: a survey's stations through the chain, and what comes out (tables,
  fates, point clouds, the range study);
- :mod:`pipeline.network`: many stations' marker tables -> one adjusted network.
"""
