"""Predicted accuracy of a layout, station by station (no integer program).

- :mod:`planner.accuracy.known_control`: a station registered to known markers by weighted least
  squares, and its predicted 95 % error;
- :mod:`planner.accuracy.network`: network mode, stations and markers estimated together (the
  network's information and covariance, with the adjustment's observation model);
- :mod:`planner.accuracy.growing`: the covariance the network greedy grows one site at a time;
- :mod:`planner.accuracy.checks`: the exact per-station checks of a layout that the planner, the
  baselines and the reduction studies all ask.
"""
