"""What ``markerplan plan`` writes.

- :mod:`planner.outputs.plan_file`: ``plan.json``, its one writer, its one reader and the typed
  plan that ``verify`` works on;
- :mod:`planner.outputs.report`: ``markers.csv``, ``markers.geojson``, ``report.md`` and the JSON
  summary;
- :mod:`planner.outputs.chance_report`: the plan's ``detection`` and ``chance`` sections and the
  report's "Chance to work";
- :mod:`planner.outputs.local_report`: a network plan's local accuracy: ``plan.json``'s
  ``local`` section, ``pairs.csv`` and the report's "Local accuracy";
- :mod:`planner.outputs.design_report`: a plan that chose its stations over an area of
  interest: ``plan.json``'s ``design`` section, each station's place on the route and the
  report's "Stations chosen over the area of interest";
- :mod:`planner.outputs.plan_map`: the placement map ``map.png``;
- :mod:`planner.outputs.stand_map`: where the rover can stand, cell by cell over the DEM;
- :mod:`planner.outputs.gis`: ``plan.gpkg`` (with a survey design's route, AOI and candidate
  stations), the stand-map and coverage GeoTIFFs and GeoJSON coordinates, in the DEM's CRS.
"""
