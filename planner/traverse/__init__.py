"""The rover's side of a plan: where it can stop, and the traverse between its stops.

- :mod:`planner.traverse.trafficability`: which ground the rover may drive and stop on (slope
  and roughness over its footprint, crater interiors, keep-outs, nodata, a hazard standoff) as a
  ``TrafficMap`` aligned with the DEM;
- :mod:`planner.traverse.stations`: candidate station positions on a grid over trafficable
  ground, with the LiDAR height of the rig;
- :mod:`planner.traverse.ground_paths`: shortest drives between points over trafficable ground
  (8-connected grid graph, Dijkstra): lengths and polylines;
- :mod:`planner.traverse.route`: the closed tour from the route start through the chosen
  stations (PyVRP) and the mission time it costs.
"""
