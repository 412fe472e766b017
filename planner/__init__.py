"""Planning: candidate sites, the integer program, station accuracy, the rover's traverse,
reduction studies, the CLI."""
