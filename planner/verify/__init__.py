"""``markerplan verify``: simulate a plan on the true terrain, process it, compare achieved with
predicted error.

- :mod:`planner.verify.known_control`: each station registered to its detected markers;
- :mod:`planner.verify.fates`: every planned marker's fate in the chain (the stage that lost
  it, against the simulator's truth; ``fates.csv``, both modes);
- :mod:`planner.verify.network`: markers identified without the simulator's truth and the whole
  network adjusted;
- :mod:`planner.verify.network_identify`: the association of its detections with the planned
  markers, and the stations it ties to the datum station;
- :mod:`planner.verify.network_datum`: its datum, the plan's reference station or the lander's
  control points known to their sigma;
- :mod:`planner.verify.network_aids`: the plan's pose aids (heading reference, odometry)
  simulated for it;
- :mod:`planner.verify.levelling`: the true tilt of its stations, levelled to the body's
  local vertical;
- :mod:`planner.verify.network_report`: a network verification's ``verify.json``,
  ``verify.md`` and summary line;
- :mod:`planner.verify.local_pairs`: a plan's local requirement verified, each station pair's
  achieved relative error against its prediction;
- :mod:`planner.verify.station_rule`: the plan's rule for one station's detections (count
  and directions), as both modes judge it;
- :mod:`planner.verify.rig_draws`: each trial's rig, drawn from the mounting offsets'
  tolerances;
- :mod:`planner.verify.trials`: ``verify --trials N`` (both modes), the plan verified with
  independent seeds and rig offsets drawn from the user's tolerances: its pass rate with a
  Wilson 95 % interval beside its predicted pass probability, per station and per
  station-marker pair beside the predicted detection probabilities.
"""
