"""A survey's stations and what comes out of them.

- :mod:`pipeline.surveys.survey`: the processing config of a survey's settings, and every scan
  file of a survey through the chain;
- :mod:`pipeline.surveys.fates`: where the chain lost each known marker (the stage and its
  reason);
- :mod:`pipeline.surveys.results`: the tables and summary of ``markerplan process``;
- :mod:`pipeline.surveys.point_cloud_io`: classified clouds as LAS and PLY;
- :mod:`pipeline.surveys.range_study`: centre error and point density against distance.
"""
