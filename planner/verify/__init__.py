"""``markerplan verify``: simulate a plan on the true terrain, process it, compare achieved with
predicted error.

- :mod:`planner.verify.known_control`: each station registered to its detected markers;
- :mod:`planner.verify.network`: markers identified without the simulator's truth and the whole
  network adjusted.
"""
