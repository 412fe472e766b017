"""Planning: candidate sites, the integer program, station accuracy, the area of interest's
coverage, the rover's traverse, survey design (stations, markers and route chosen together),
reduction studies, the CLI."""
