"""The planning problem: what may be placed where, and what each station could count on.

- :mod:`planner.problem.inputs`: the run's inputs (site preset or DEM, stations, existing and
  as-built markers, boundary, exclusions) read strictly into ``PlanInputs``;
- :mod:`planner.problem.candidates`: candidate marker sites on the terrain;
- :mod:`planner.problem.sight`: tiled ray scenes -> visibility matrix -> usable pairs;
- :mod:`planner.problem.visibility_table`: usable pairs from a table computed elsewhere;
- :mod:`planner.problem.usability`: ``PlanProblem``, which pairs count, and the direction rule;
- :mod:`planner.problem.detection_odds`: each pair's covariates and chance of being detected and
  accepted (the detection model's);
- :mod:`planner.problem.terrain_uncertainty`: each pair's chance of being visible on a DEM known
  only to its height error (conditional realisations).
"""
