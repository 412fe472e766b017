"""Planning: candidate sites, the integer program, station accuracy, reduction studies, the CLI."""
