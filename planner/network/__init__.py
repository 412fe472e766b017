"""What ``markerplan adjust`` writes, from a network adjustment.

- :mod:`planner.network.record`: plain rows and the one record of an adjustment;
- :mod:`planner.network.report`: ``report.md``, read top to bottom as a surveyor does;
- :mod:`planner.network.files`: the tables, covariance, GeoJSON and JSON summary;
- :mod:`planner.network.map`: ``network.png``.
"""
