"""``markerplan adjust`` on the planner's side: the plan it reads, and what it writes.

- :mod:`planner.network.plan_geometry`: a ``plan.json`` as the adjustment takes it, and the
  adjustment's configuration resolved against the plan;
- :mod:`planner.network.record`: plain rows and the one record of an adjustment;
- :mod:`planner.network.report`: ``report.md``, read top to bottom as a surveyor does;
- :mod:`planner.network.files`: the tables, covariance, GeoJSON and JSON summary;
- :mod:`planner.network.map`: ``network.png``.
"""
