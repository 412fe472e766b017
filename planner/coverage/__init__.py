"""Coverage of an area of interest (AOI): what must be measured and which stations measure it.

- :mod:`planner.coverage.aoi`: the AOI polygon read from GeoJSON and placed on the DEM (off the
  DEM or on nodata refused);
- :mod:`planner.coverage.grid`: the AOI grid aligned with the DEM (cell centres, ground heights,
  surface normals of the AOI's cells);
- :mod:`planner.coverage.density`: the expected LiDAR point density on the ground of one full
  station scan (the rig's angular sampling, incidence and range);
- :mod:`planner.coverage.sight`: the predicted station x cell coverage matrix (range, incidence,
  density limits and Embree line of sight, tiled and mapped like the marker visibility) and its
  settings;
- :mod:`planner.coverage.raster`: the predicted coverage of chosen stations per cell (count and
  best density), its GeoTIFF, and the summary of cells no candidate station covers;
- :mod:`planner.coverage.achieved`: the coverage achieved by simulated and processed scans of
  chosen stations, rasterised over the AOI grid.
"""
