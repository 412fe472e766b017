"""Predicted accuracy of a layout, station by station (no integer program).

- :mod:`planner.accuracy.known_control`: a station registered to known markers by weighted least
  squares, and its predicted 95 % error;
- :mod:`planner.accuracy.figure`: the 95 % figure of a station's error over its working disc
  (the computed quantile of the worst error, or the conservative ellipsoid figure) and of a
  marker's;
- :mod:`planner.accuracy.network`: network mode, stations and markers estimated together (the
  network's information and covariance, with the adjustment's observation model);
- :mod:`planner.accuracy.network_covariance`: a network layout's pose covariance and the
  stations it determines;
- :mod:`planner.accuracy.network_tangents`: the network's tangent cuts (its convex
  requirements linearised at a covariance);
- :mod:`planner.accuracy.aids`: the pose aids of a network (inclinometer, heading reference
  with a boresight bias, odometry between consecutive stations) as pseudo-observations;
- :mod:`planner.accuracy.requirement`: network accuracy as surveyors state it, a constant plus
  ppm of the distance from the datum;
- :mod:`planner.accuracy.local`: local accuracy, the relative error between neighbouring
  stations (relative position or distance), its 95 % figures and cuts;
- :mod:`planner.accuracy.network_diagnosis`: why a network cannot meet its requirement, station
  by station;
- :mod:`planner.accuracy.growing`: the covariance the network greedy grows one site at a time;
- :mod:`planner.accuracy.checks`: the exact per-station checks of a layout that the planner, the
  baselines and the reduction studies all ask;
- :mod:`planner.accuracy.chance`: a station's chance of passing when planned markers may be
  lost, exactly or with certified bounds (loss sets enumerated by size);
- :mod:`planner.accuracy.network_chance`: a network layout's chance of passing as a whole (its
  accuracy included), with certified bounds over loss sets of its pairs;
- :mod:`planner.accuracy.sampled_chance`: a layout's pass rate over sampled detection outcomes
  (both modes, the network's accuracy included);
- :mod:`planner.accuracy.reliability`: network mode's per-observation reliability (redundancy,
  minimal detectable bias and its largest station shift).
"""
