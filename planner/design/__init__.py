"""Survey design: where the rover stops over an area of interest, its markers and its traverse.

- :mod:`planner.design.run`: the steps from an AOI to chosen stations, markers and route
  (trafficable ground, candidate stations, coverage, the joint program, baselines, routes, the
  hand layout) -> :class:`~planner.design.run.SurveyDesign`;
- :mod:`planner.design.plan`: the chosen stations' marker plan, in route order, made like any
  other plan (:func:`planner.run.make_plan`), with the design attached.
"""
