# ---
# jupyter:
#   jupytext:
#     text_representation:
#       extension: .py
#       format_name: percent
#       format_version: '1.3'
# ---

# %% [markdown]
# # 05 — How many markers can go? The marker-reduction trade-off
#
# The published field layout used 11 markers for 7 stations. Which of them are really needed?
# For every count `k` we ask an integer program for the `k` markers that minimise the **worst
# station's** predicted error (95 % registered-position error over a 10 m working radius), and
# whether every station still has three directions and ±10 cm. This is what
# `markerplan reduce as-built --site default --out DIR` writes; here we call the library directly.
#
# Figures go to `$MARKERPLAN_NB_OUT` (default: a fresh temporary folder).

# %%
import numpy as np
from nbsetup import OUT, plt, save

from error_model import default_model
from planner.config import PlanConfig
from planner.problem.inputs import load_inputs
from planner.reduction.plot import plot_tradeoff
from planner.reduction.report import reduce_record
from planner.reduction.study import layout_problem, read_layout, run_study

# %% [markdown]
# ## The site and its as-built layout
# `load_inputs` assembles the default preset: a 60 m DEM with craters and rocks, 7 stations
# (centre + hexagon of radius 12 m) and the as-built markers (inner hexagon at 6 m, outer
# pentagon at 18 m). The station-marker pairs are ray-cast through the terrain and judged with
# the shipped error model.

# %%
inputs = load_inputs("default")
layout = read_layout("as-built", inputs)
config = PlanConfig(time_limit_s=30.0)
model = default_model()
problem, mask, timings = layout_problem(inputs, layout, config, model, progress=False)
print(f"{problem.n_stations} stations, {problem.n_sites} markers, "
      f"{problem.pair_usable.sum()} usable station-marker pairs of {problem.pair_station.size}")

# %% [markdown]
# ## The trade-off curve, drop order and per-marker losses

# %%
study = run_study(problem, config, mask)
curve = study.curve
print(f"fewest markers meeting the directions: {curve.k_directions}; "
      f"meeting ±{config.requirement_m * 100:g} cm too: {curve.k_feasible}; "
      f"all points proven optimal: {curve.proven}")
print(" k  worst[cm]  mean[cm]  ok   kept")
for p in curve.points:
    kept = " ".join(problem.site_ids[j] for j in np.flatnonzero(p.selected))
    print(f"{p.k:2d}  {100 * p.worst_error_m:8.2f}  {100 * p.mean_error_m:8.2f}  "
          f"{'yes' if p.meets_requirement else 'no ':3s}  {kept}")
print("drop order:", ", ".join(problem.site_ids[s.removed] for s in study.drop))

# %% [markdown]
# The curve is monotone: fewer markers never make the worst station better. The greedy drop
# order (one marker at a time, always the least harmful) is nested, so it can end above the
# optimum at the same count — the dotted line in the figure.

# %%
doc = reduce_record(study, layout, inputs, "default", {"input": "as-built"})
plot_tradeoff(doc, OUT / "05_tradeoff.png")

# %% [markdown]
# ## Which station limits each count?
# Per-station predicted errors of the optimal subsets (rows: stations, columns: markers kept).

# %%
err = np.array([p.error_m for p in curve.points]).T * 100
fig, ax = plt.subplots(figsize=(7, 3.8))
im = ax.imshow(err, aspect="auto", cmap="viridis")
ax.set_xticks(range(len(curve.points)), [p.k for p in curve.points])
ax.set_yticks(range(problem.n_stations), problem.station_ids)
ax.set_xlabel("markers kept")
ax.set_title("predicted station error (cm) of the minimax subsets")
fig.colorbar(im, ax=ax)
fig.tight_layout()
save(fig, "05_per_station.png", dpi=100)

# %% [markdown]
# ## Robustness: losing one marker of the full layout

# %%
for m in study.losses:
    failing = ", ".join(problem.station_ids[s] for s in m.failing) or "none"
    print(f"without {problem.site_ids[m.marker]}: worst {100 * m.worst_error_m:.2f} cm, "
          f"failing stations: {failing}")
assert all(b.worst_error_m >= a.worst_error_m * (1 - 1e-9)
           for a, b in zip(curve.points, curve.points[1:], strict=False))
print(f"{study.markers_that_can_go} of {study.n_layout} markers can go.")
