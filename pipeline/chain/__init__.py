"""One station's chain: a station scan -> its marker table, stage by stage.

- :mod:`pipeline.chain.stages`: the validated stage configuration;
- :mod:`pipeline.chain.process`: the chain itself
  (:func:`pipeline.chain.process.process_station`), running the stages below in order;
- :mod:`pipeline.chain.synthesis`: the turntable synthesis (frames -> one station cloud);
- :mod:`pipeline.chain.calibration`: the self-calibration of the mounting offsets;
- :mod:`pipeline.chain.ground`: ground removal;
- :mod:`pipeline.chain.clustering`: Euclidean clustering of what stands above the ground;
- :mod:`pipeline.chain.gate`: the two-box gate and the re-search around each candidate;
- :mod:`pipeline.chain.quality`: per-marker quality metrics and the quality gate (the centres
  themselves come from :mod:`pipeline.sphere_centres`);
- :mod:`pipeline.chain.evaluation`: evaluation against reference marker coordinates.
"""
