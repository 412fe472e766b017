# ---
# jupyter:
#   jupytext:
#     text_representation:
#       extension: .py
#       format_name: percent
#       format_version: '1.3'
# ---

# %% [markdown]
# # 01 — Synthetic lunar terrain and the tilted VLP-16 on a turntable
#
# The planner needs terrain (craters, rocks, slopes cause occlusion) and a sensor model (where
# the beams go, how many points land on a marker). This notebook shows the `default` site — a
# 40 m crater test field modelled on the published experiment — the scan pattern of a VLP-16
# tilted 90° on a turntable, and one simulated station with only a few turntable steps.
#
# Figures go to `$MARKERPLAN_NB_OUT` (default: a fresh temporary folder).

# %%
import numpy as np
from matplotlib.colors import LightSource
from nbsetup import plt, save

from pipeline.chain.synthesis import synthesize
from pipeline.scans.rig import MountingOffsets, frame_poses
from visibility.sensor import RigConfig, SensorConfig, firing_pattern, sensor_directions
from visibility.simulate import simulate_station
from visibility.sites import load_site

# %% [markdown]
# ## The default site
# A fractal surface (2 cm RMS at 1 m) on a 1.5° regional slope, five named craters 3–8 m
# across, random small craters from a power-law size distribution, three boulders and random
# rocks. Stations: the centre and a hexagon of radius 12 m; as-built markers: an inner hexagon
# (6 m) and an outer pentagon (18 m).

# %%
site = load_site("default")
dem = site.dem
xmin, xmax, ymin, ymax = dem.extent()
print(f"DEM {dem.shape[1]} x {dem.shape[0]} cells of {dem.cell_size_m} m, heights "
      f"{dem.heights_m.min():.2f}..{dem.heights_m.max():.2f} m; {len(site.craters)} craters, "
      f"{len(site.rock_radii_m)} rocks")

fig, ax = plt.subplots(figsize=(7, 6.5))
shade = LightSource(azdeg=315, altdeg=25).hillshade(dem.heights_m, dx=dem.cell_size_m,
                                                     dy=dem.cell_size_m)
ax.imshow(shade, extent=(xmin, xmax, ymin, ymax), origin="lower", cmap="gray")
for c in site.craters:
    if c.diameter_m >= 2.5:
        ax.add_patch(plt.Circle(c.centre_xy_m, c.diameter_m / 2, fill=False, color="C1", lw=0.8))
ax.plot(*site.station_xy_m.T, "^", color="C0", ms=9, label="stations")
ax.plot(*site.marker_centres_m[:, :2].T, "o", color="red", ms=6, label="as-built markers")
for sid, (x, y) in zip(site.station_ids, site.station_xy_m, strict=True):
    ax.annotate(sid, (x, y), xytext=(4, 4), textcoords="offset points", color="C0")
ax.plot(*np.vstack([site.boundary_xy_m, site.boundary_xy_m[:1]]).T, "--", color="C2",
        label="working area")
ax.set_xlabel("x (m, site frame)")
ax.set_ylabel("y (m)")
ax.legend(loc="lower right", fontsize=8)
ax.set_title("default site: hillshade, craters >= 2.5 m")
fig.tight_layout()
save(fig, "01_site.png")

# %% [markdown]
# A profile through the largest crater (8 m, centred at x = 13.75 m, y = 10 m): raised rim,
# bowl about a fifth of the diameter deep in fresh craters, shallower when degraded.

# %%
x = np.linspace(4.0, 24.0, 400)
profile = dem.height_at(np.column_stack([x, np.full_like(x, 10.0)]))
fig, ax = plt.subplots(figsize=(7, 2.5))
ax.plot(x, profile, color="k")
ax.set_xlabel("x (m) along y = 10 m")
ax.set_ylabel("height (m)")
ax.set_aspect(3)
fig.tight_layout()
save(fig, "01_crater_profile.png")

# %% [markdown]
# ## The scan pattern
# The VLP-16's 16 lasers fire at fixed elevations (−15° … +15°) while the head spins. Tilted
# 90° on the L-bracket, the spin sweeps a **vertical** circle and the 16 beams fan out
# horizontally; the turntable then steps that fan around in azimuth. Below: beam directions in
# the station frame for three turntable angles (one LiDAR revolution each).

# %%
sensor = SensorConfig()
laser, az = firing_pattern(sensor.rpm)
d_sensor = sensor_directions(laser, az)
print(f"{sensor.rpm} rpm: azimuth step {np.degrees(sensor.azimuth_step_rad):.3f} deg, "
      f"{laser.size} firings per revolution")
fig, ax = plt.subplots(figsize=(7, 3.5))
for angle_deg, colour in ((0, "C0"), (30, "C1"), (60, "C2")):
    rot, _ = frame_poses(np.radians([angle_deg]), MountingOffsets())
    d = d_sensor[::7] @ rot[0].T
    ax.plot(np.degrees(np.arctan2(d[:, 1], d[:, 0])), np.degrees(np.arcsin(d[:, 2])), ".",
            ms=1, color=colour, label=f"turntable {angle_deg} deg")
ax.set_xlabel("azimuth in the station frame (deg)")
ax.set_ylabel("elevation (deg)")
ax.legend(markerscale=8, fontsize=8)
ax.set_title("one frame = one vertical fan of 16 scan lines")
fig.tight_layout()
save(fig, "01_scan_pattern.png")

# %% [markdown]
# ## One simulated station, with few frames
# A full station takes 800 frames; 20 frames (every 18°) are enough to see the geometry. The
# simulator casts every beam into an Embree scene of the terrain plus the marker spheres and
# adds range noise; the pipeline's synthesis rotates each frame into the station frame.

# %%
rig = RigConfig()
frames = range(0, rig.frames_per_turn, 40)
scan, truth = simulate_station(site, 0, sensor, rig, seed=1, frames=frames)
cloud = synthesize(scan)
print(f"station {scan.station_id}: {len(frames)} of {scan.n_frames} frames simulated, "
      f"{scan.n_points} points")
markers = truth["markers"]
centres = np.array([m["centre_station_m"] for m in markers])
n_points = np.array([m["n_points"] for m in markers])
dist = np.linalg.norm(centres, axis=1)

fig, (a1, a2) = plt.subplots(1, 2, figsize=(12, 5))
near = cloud.range_m < 25
sc = a1.scatter(cloud.xyz_m[near, 0], cloud.xyz_m[near, 1], c=cloud.xyz_m[near, 2], s=0.2,
                cmap="terrain")
a1.plot(centres[:, 0], centres[:, 1], "o", mfc="none", color="red", ms=9, label="markers")
a1.set_aspect("equal")
a1.set_xlabel("x (m, station frame)")
a1.set_ylabel("y (m)")
a1.legend(fontsize=8)
a1.set_title(f"{scan.station_id}: {len(frames)} frames, points within 25 m")
fig.colorbar(sc, ax=a1, label="z (m)")
a2.semilogy(dist, np.maximum(n_points, 0.5), "o")
for m, x_, y_ in zip(markers, dist, np.maximum(n_points, 0.5), strict=True):
    a2.annotate(m["id"], (x_, y_), xytext=(3, 3), textcoords="offset points", fontsize=8)
a2.set_xlabel("distance to marker (m)")
a2.set_ylabel("points on the marker (0 shown as 0.5)")
a2.set_title("returns per marker fall with distance (and occlusion)")
fig.tight_layout()
save(fig, "01_station.png")
assert scan.n_points > 0 and n_points.max() > 0
