"""``markerplan verify``: simulate a plan on the true terrain, process it, compare achieved with
predicted error.

- :mod:`planner.verify.known_control`: each station registered to its detected markers;
- :mod:`planner.verify.fates`: every planned marker's fate in the chain (the stage that lost
  it, against the simulator's truth; ``fates.csv``, both modes);
- :mod:`planner.verify.network`: markers identified without the simulator's truth and the whole
  network adjusted;
- :mod:`planner.verify.network_report`: a network verification's ``verify.json``,
  ``verify.md`` and summary line;
- :mod:`planner.verify.local_pairs`: a plan's local requirement verified, each station pair's
  achieved relative error against its prediction;
- :mod:`planner.verify.rig_draws`: each trial's rig, drawn from the mounting offsets'
  tolerances;
- :mod:`planner.verify.trials`: ``verify --trials N`` (both modes), the plan verified with
  independent seeds and rig offsets drawn from the user's tolerances: its pass rate with a
  Wilson 95 % interval beside its predicted pass probability, per station and per
  station-marker pair beside the predicted detection probabilities.
"""
