# ---
# jupyter:
#   jupytext:
#     text_representation:
#       extension: .py
#       format_name: percent
#       format_version: '1.3'
# ---

# %% [markdown]
# # 02 — Processing one station: detections, rejections and self-calibration
#
# We simulate station S1 of the default site with deliberate mounting errors (vertical-axis
# error, L-frame tilt, turntable-axis offset) and run the published chain: direct/reverse
# self-calibration, synthesis, ground removal, clustering, the two-box gate, re-search,
# sphere-centre fit and the quality gate, then evaluate against the simulator's truth. Only 80
# of the 800 frames are simulated, so far markers get few points — and the quality gate says so.
#
# Figures go to `$MARKERPLAN_NB_OUT` (default: a fresh temporary folder).

# %%
from collections import Counter

import numpy as np
from nbsetup import plt, save

from pipeline.chain.evaluation import reference_from_truth
from pipeline.chain.process import process_station
from pipeline.chain.stages import build_config
from pipeline.chain.synthesis import synthesize
from pipeline.scans.rig import MountingOffsets
from visibility.sensor import RigConfig, SensorConfig
from visibility.simulate import simulate_station
from visibility.sites import load_site

# %% [markdown]
# ## Simulate S1 with known mounting errors

# %%
site = load_site("default")
true_offsets = MountingOffsets(vertical_axis_error_rad=np.radians(0.3),
                               lframe_tilt_rad=np.radians(-0.2), axis_offset_m=(0.010, -0.006))
rig = RigConfig(offsets=true_offsets)
frames = range(0, rig.frames_per_turn, 10)  # every 4.5 deg; frame f and f + 400 face each other
scan, truth = simulate_station(site, 0, SensorConfig(), rig, seed=1, frames=frames)
reference = reference_from_truth(truth)
print(f"{scan.station_id}: {len(frames)} frames, {scan.n_points} points")

# %% [markdown]
# ## Run the chain
# `build_config()` validates every stage's options before anything runs.

# %%
config = build_config()
result = process_station(scan, config, reference)
for stage, seconds in result.timings_s.items():
    print(f"  {stage:24s} {seconds:6.2f} s")
rows = result.rows
accepted = [r for r in rows if r.accepted]
print(f"{len(rows)} candidates passed the two-box gate; {len(accepted)} accepted")
print("rejections:", dict(Counter(r.reason for r in rows if not r.accepted)))

# %% [markdown]
# ## Self-calibration of the three mounting offsets
# The vertical-axis error and the L-frame tilt come from ICP between each frame and the frame
# taken 180° later (direct and reverse faces); the axis offset from making the accepted spheres'
# point clouds most consistent.

# %%
est = result.offsets
table = [("vertical-axis error (deg)", np.degrees(true_offsets.vertical_axis_error_rad),
          np.degrees(est.vertical_axis_error_rad)),
         ("L-frame tilt (deg)", np.degrees(true_offsets.lframe_tilt_rad),
          np.degrees(est.lframe_tilt_rad)),
         ("axis offset x (mm)", 1e3 * true_offsets.axis_offset_m[0], 1e3 * est.axis_offset_m[0]),
         ("axis offset y (mm)", 1e3 * true_offsets.axis_offset_m[1], 1e3 * est.axis_offset_m[1])]
for name, t, e in table:
    print(f"  {name:26s} true {t:8.4f}   estimated {e:8.4f}")

# %% [markdown]
# ## Detections and rejections in the calibrated cloud

# %%
cloud = synthesize(scan, est)
near = cloud.range_m < 22
fig, ax = plt.subplots(figsize=(7.5, 7))
ax.scatter(cloud.xyz_m[near, 0], cloud.xyz_m[near, 1], s=0.05, c="0.6")
ax.plot(*reference.centres_m[:, :2].T, "s", mfc="none", color="k", ms=11, label="truth")
for r in rows:
    colour = "C2" if r.accepted else "C3"
    ax.plot(r.x_m, r.y_m, "o", color=colour, ms=5)
    if not r.accepted:
        ax.annotate(r.reason, (r.x_m, r.y_m), xytext=(3, -8), textcoords="offset points",
                    fontsize=6, color=colour)
ax.plot([], [], "o", color="C2", label="accepted")
ax.plot([], [], "o", color="C3", label="rejected (reason)")
ax.set_aspect("equal")
ax.set_xlabel("x (m, station frame)")
ax.set_ylabel("y (m)")
ax.legend(fontsize=8, loc="lower right")
ax.set_title(f"{scan.station_id}: {len(accepted)} accepted of {len(rows)} candidates")
fig.tight_layout()
save(fig, "02_detections.png")

# %% [markdown]
# ## One marker up close, and the centre errors

# %%
best = min(accepted, key=lambda r: r.distance_m)
pts = cloud.xyz_m[np.linalg.norm(cloud.xyz_m - best.centre_m, axis=1) < 0.3]
truth_c = reference.centres_m[reference.ids.index(best.marker_id)]
fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4.5))
a1.plot(pts[:, 0], pts[:, 2], ".", ms=2, color="0.4", label="points within 0.3 m")
circle = np.linspace(0, 2 * np.pi, 100)
r = config.fit.radius_m
a1.plot(best.x_m + r * np.cos(circle), best.z_m + r * np.sin(circle), color="C2",
        label="fitted sphere")
a1.plot(truth_c[0], truth_c[2], "k+", ms=12, label="true centre")
a1.set_aspect("equal")
a1.set_xlabel("x (m)")
a1.set_ylabel("z (m)")
a1.set_title(f"{best.marker_id} at {best.distance_m:.1f} m: {best.n_points} points")
a1.legend(fontsize=8)
matched = [r for r in rows if r.marker_id and r.error_m is not None]
a2.plot([r.distance_m for r in matched if r.accepted],
        [1e3 * r.error_m for r in matched if r.accepted], "o", color="C2", label="accepted")
a2.plot([r.distance_m for r in matched if not r.accepted],
        [1e3 * r.error_m for r in matched if not r.accepted], "x", color="C3",
        label="rejected (would be biased)")
a2.set_yscale("log")
a2.set_xlabel("distance (m)")
a2.set_ylabel("centre error (mm)")
a2.legend(fontsize=8)
a2.set_title("centre error against truth")
fig.tight_layout()
save(fig, "02_marker_and_errors.png")
print(f"mean error of accepted markers {1e3 * result.summary['mean_error_m']:.1f} mm; "
      f"edge residual RMS {1e3 * result.summary['rms_edge_residual_m']:.1f} mm")
assert accepted and max(r.error_m for r in accepted if r.error_m is not None) < 0.05
