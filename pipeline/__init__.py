"""Scan processing: the scan format, turntable synthesis, self-calibration, marker extraction,
sphere-centre estimation, quality gate and evaluation. Imports nothing of ours but the shared
kernel :mod:`markerplan` (version, error roots)."""
