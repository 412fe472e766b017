"""Scans in: the station-scan format and what it is read from, with the rig and noise contract
that the simulator (:mod:`visibility`) shares with the chain.

- :mod:`pipeline.scans.scan_format`: the station-scan file format (real and simulated scans);
- :mod:`pipeline.scans.pcap`: a Velodyne packet capture and turntable log -> a station scan;
- :mod:`pipeline.scans.pointsets`: plain point sets (``.xyz``, ``.txt``, ``.csv``);
- :mod:`pipeline.scans.sensor_noise`: the range noise of one return;
- :mod:`pipeline.scans.rig`: the rig's frames and mounting offsets.
"""
