"""Terrain (DEMs, synthetic lunar sites), the Embree scene, the VLP-16 turntable sensor model,
scan simulation and the station x site visibility matrix."""
