# ---
# jupyter:
#   jupytext:
#     text_representation:
#       extension: .py
#       format_name: percent
#       format_version: '1.3'
# ---

# %% [markdown]
# # 04 — Planning the default site
#
# The planner puts the fewest markers on candidate sites so that every station sees at least
# three usable markers in three of six bearing sectors and its predicted 95 % registration error
# stays within ±10 cm. Usable means: unoccluded (Embree ray casting over the DEM), inside the
# error model's domain, and accurate enough. This notebook runs the same steps as
# `markerplan plan`, on a coarse 2 m candidate grid so it stays quick, and compares the plan
# with a greedy cover, a regular grid and the site's as-built layout.
#
# Figures go to `$MARKERPLAN_NB_OUT` (default: a fresh temporary folder).

# %%
import numpy as np
from nbsetup import OUT, plt, save

from error_model import default_model
from planner.accuracy.checks import evaluate_layout
from planner.config import PlanConfig
from planner.outputs.plan_map import draw_plan_map
from planner.problem.inputs import load_inputs
from planner.problem.usability import REASONS
from planner.run import make_plan

# %% [markdown]
# ## Inputs and configuration

# %%
inputs = load_inputs("default")
config = PlanConfig(grid_spacing_m=2.0, time_limit_s=30.0)
print(f"site {inputs.site_name}: {len(inputs.station_ids)} stations, "
      f"{len(inputs.as_built_ids)} as-built markers; requirement {config.requirement_m} m, "
      f">= {config.min_markers} markers in >= {config.min_sectors} of {config.n_sectors} sectors")

# %% [markdown]
# ## Plan: candidates -> visibility -> integer program (with accuracy cuts) -> baselines

# %%
outcome = make_plan(inputs, config, default_model(), progress=False)
problem, result = outcome.problem, outcome.result
print(f"{problem.n_sites} candidate sites, {problem.pair_station.size} station-site pairs")
for code, text in enumerate(REASONS):
    print(f"  {np.sum(problem.pair_reason == code):6d} pairs: {text}")
print(f"plan: {int(result.selected.sum())} markers, solver status {result.status}, "
      f"{result.iterations} solve(s), {result.n_cuts} accuracy cut(s)")
print("markers:", ", ".join(outcome.selected_ids))

# %% [markdown]
# ## The placement map

# %%
draw_plan_map(outcome, OUT / "04_plan_map.png", dpi=90)

# %% [markdown]
# ## Compared with the baselines and the as-built layout

# %%
rows = [("integer program", int(result.selected.sum()), result.check.all_ok,
         result.check.error_m)]
for b in outcome.baselines:
    chk = evaluate_layout(problem, b.selected, config)
    rows.append((b.name + (f" ({b.spacing_m:g} m)" if b.spacing_m else ""), b.n_markers,
                 b.meets_requirement, chk.error_m))
if outcome.as_built is not None:
    rows.append(("as-built", len(inputs.as_built_ids), outcome.as_built.all_ok,
                 outcome.as_built.error_m))
for name, n, ok, _ in rows:
    print(f"{name:24s} {n:3d} markers  meets requirement: {ok}")

fig, ax = plt.subplots(figsize=(7.5, 4))
x = np.arange(problem.n_stations)
w = 0.8 / len(rows)
for i, (name, n, _, err) in enumerate(rows):
    ax.bar(x + i * w, 100 * np.asarray(err), w, label=f"{name}: {n} markers")
ax.axhline(100 * config.requirement_m, color="k", ls="-.", label="requirement")
ax.set_xticks(x + 0.4 - w / 2, problem.station_ids)
ax.set_ylabel("predicted station error (cm)")
ax.set_yscale("log")
ax.legend(fontsize=8)
fig.tight_layout()
save(fig, "04_baselines.png", dpi=100)
assert result.check.all_ok
assert all(result.selected.sum() <= n for _, n, ok, _ in rows[1:] if ok)
