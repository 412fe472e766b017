# ---
# jupyter:
#   jupytext:
#     text_representation:
#       extension: .py
#       format_name: percent
#       format_version: '1.3'
# ---

# %% [markdown]
# # 03 — The marker-centre error model: fit, diagnostics, domain
#
# The planner predicts how well a station is registered from the error of each marker centre,
# modelled as a function of distance and elevation angle (the seed study's multivariate
# analysis). Here we build a **small** range-study table — a few simulated scans of markers
# 2–30 m away on a 7° slope (so elevation varies independently of distance), processed by the
# pipeline — fit the model on it, draw the diagnostics, and look at its domain: the model only
# vouches for distances and angles it has seen.
#
# Figures go to `$MARKERPLAN_NB_OUT` (default: a fresh temporary folder).

# %%
import numpy as np
from nbsetup import OUT, plt, save

from error_model import default_model
from error_model.diagnostics import plot_diagnostics, summary_text
from error_model.fit import fit_error_model
from error_model.table import EXTRA_COLUMNS, read_marker_tables
from markerplan.constants import GOLDEN_ANGLE_RAD
from pipeline.chain.evaluation import reference_from_truth
from pipeline.chain.process import process_station
from pipeline.chain.stages import build_config
from pipeline.tables.marker_table import write_marker_table
from visibility.dem import DEM
from visibility.simulate import simulate_markers

# %% [markdown]
# ## A small range study
# Five scans of 16 markers each (distances 2–30 m, golden-angle azimuths, rotated between
# scans) on a plane rising 7° towards +x; 100 of the 800 frames per scan, no mounting errors
# (calibration off), so far markers get few points and the quality gate rejects them.

# %%
cell = 0.2
axis = np.arange(-35.0, 35.0 + cell / 2, cell)
xx, _ = np.meshgrid(axis, axis)
dem = DEM(0.12 * xx, (-35.0, -35.0), cell)
distances = np.array([2, 3, 4, 5, 6, 7, 8, 10, 12, 14, 16, 18, 20, 23, 26, 30], float)
config = build_config({"calibrate": {"enabled": False}})
rows = []
for rep in range(5):
    az = GOLDEN_ANGLE_RAD * np.arange(distances.size) + np.radians(40.0 * rep)
    xy = np.column_stack([distances * np.cos(az), distances * np.sin(az)])
    centres = np.column_stack([xy, dem.height_at(xy) + 0.10])
    station = np.array([0.0, 0.0, dem.height_at(np.zeros((1, 2)))[0] + 1.0])
    scan, truth = simulate_markers(dem, station, 0.0, centres, seed=rep,
                                   frames=range(0, 800, 8), station_id=f"R{rep}")
    rows += process_station(scan, config, reference_from_truth(truth)).rows
path = write_marker_table(OUT / "03_markers.csv", rows)
table = read_marker_tables(path)
accepted = sum(r.accepted for r in rows)
print(f"{len(rows)} detections, {accepted} accepted -> {path.name}")

# %% [markdown]
# ## Fit
# Sigma (RMS 3D centre error) and a 95 % envelope, both monotone in distance, as piecewise-
# linear functions of distance and |elevation|; the basis is picked by cross-validation and
# optional predictors (visible fraction, point count) are kept only if they help.

# %%
model = fit_error_model(table, {"n_bootstrap": 0}, seed=0,
                        description="notebook 03: 5 small simulated range-study scans")
print(summary_text(model))
plot_diagnostics(model, table, OUT / "03_diagnostics.png")

# %% [markdown]
# ## The domain
# Outside the distances and elevations it was fitted on, a prediction is flagged
# `in_domain = False`; the planner treats such station-marker pairs as unusable unless told
# otherwise. With 100 frames per scan, nothing beyond ~15 m survived the quality gate, so the
# domain stops there.

# %%
lo, hi = model.domain.distance_range_m
print(f"fitted distances {lo:.1f}-{hi:.1f} m")
d = np.linspace(1.0, 35.0, 120)
e = np.radians(np.linspace(-30.0, 15.0, 90))
dd, ee = np.meshgrid(d, e)
# optional predictors (if the fit kept any) at their median in the table
extras = {name: np.full(dd.shape, float(np.nanmedian(table[EXTRA_COLUMNS[name]])))
          for name in model.predictors[2:]}
pred = model.predict(dd, ee, **extras)
shipped = default_model()
fig, (a1, a2) = plt.subplots(1, 2, figsize=(12, 4.5))
im = a1.pcolormesh(dd, np.degrees(ee), 1e3 * np.where(pred.in_domain, pred.q95_m, np.nan),
                   shading="auto", cmap="magma_r")
fig.colorbar(im, ax=a1, label="95 % envelope (mm), in domain only")
a1.set_xlabel("distance (m)")
a1.set_ylabel("elevation (deg)")
a1.set_title("this fit: envelope inside its domain")
for m, label in ((model, "this notebook's fit"), (shipped, "shipped default model")):
    p = m.predict(d, np.full(d.size, np.radians(-5.0)),
                  **{k: np.full(d.size, v[0, 0]) for k, v in extras.items()
                     if k in m.predictors})
    line, = a2.plot(d, 1e3 * p.sigma_m, label=f"{label}: sigma")
    a2.plot(d[~p.in_domain], 1e3 * p.sigma_m[~p.in_domain], "x", color=line.get_color(), ms=3)
a2.set_xlabel("distance (m) at elevation -5 deg (x: outside the domain)")
a2.set_ylabel("sigma (mm)")
a2.legend(fontsize=8)
fig.tight_layout()
save(fig, "03_domain.png")
assert np.all(np.diff(model.predict(d, np.radians(-5.0), **{k: v[0, 0] for k, v in
                                                            extras.items()}).sigma_m) >= -1e-12)
