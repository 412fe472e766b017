"""Marker-centre error as a function of distance and angle: fitting (cvxpy), prediction,
domain, serialisation and diagnostics. Imports nothing of ours but :mod:`markerplan`."""
