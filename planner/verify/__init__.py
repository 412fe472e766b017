"""``markerplan verify``: simulate a plan on the true terrain, process it, compare achieved with
predicted error.

- :mod:`planner.verify.known_control`: each station registered to its detected markers;
- :mod:`planner.verify.fates`: every planned marker's fate in the chain (the stage that lost
  it, against the simulator's truth; ``fates.csv``, both modes);
- :mod:`planner.verify.network`: markers identified without the simulator's truth and the whole
  network adjusted;
- :mod:`planner.verify.trials`: ``verify --trials N``, the plan verified with independent
  seeds: its pass rate with a Wilson 95 % interval, per station and per station-marker pair.
"""
