"""A planned layout's geometry as a file, so that a layout found on a large site can be checked
again without ray casting (:func:`save_layout`, :func:`load_layout`).

The file (NumPy ``.npz``) holds the stations, the selected sites and the usable pairs between
them with their error-model sigmas, and the configuration the layout was planned for: exactly
what network mode's accuracy depends on. The test suite re-checks the layouts of the
requirement table on ``large`` from these files with an independent covariance (the network
adjustment's full normal matrix, ``tests/planner/test_large_layouts.py``).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from planner.problem.usability import USABLE, PlanProblem


def save_layout(path, problem: PlanProblem, config, selected, meta: dict | None = None
                ) -> Path:
    """Write the layout ``selected`` of ``problem`` with ``config`` to ``path``.

    Parameters
    ----------
    path : str or Path
        The ``.npz`` to write (written whole to a temporary file, then renamed).
    problem : PlanProblem
    config : planner.config.PlanConfig
    selected : (n,) bool
    meta : dict, optional
        JSON-serialisable notes (the case's label, how it was found, its markers).

    Returns
    -------
    path : Path
    """
    sub = problem.restrict(np.asarray(selected, bool))
    use = sub.pair_usable
    control = (np.zeros(sub.n_sites) if sub.site_control_sigma_m is None
               else sub.site_control_sigma_m)
    path = Path(path)
    partial = path.with_name(path.name + ".partial")
    with partial.open("wb") as fh:
        np.savez_compressed(
            fh, station_ids=np.array(sub.station_ids), station_xyz=sub.station_xyz,
            site_ids=np.array(sub.site_ids), site_xyz=sub.site_xyz, site_control_sigma_m=control,
            pair_station=sub.pair_station[use], pair_site=sub.pair_site[use],
            pair_sigma_m=sub.pair_sigma_m[use], config=json.dumps(config.to_dict()),
            meta=json.dumps(meta or {}))
    os.replace(partial, path)
    return path


def load_layout(path) -> tuple[PlanProblem, object, dict]:
    """Read a :func:`save_layout` file.

    Returns
    -------
    problem : PlanProblem
        The layout's sites only (every one selected), its usable pairs; bearings and distances
        recomputed from the positions.
    config : planner.config.PlanConfig
    meta : dict
    """
    from planner.config import config_from_dict

    with np.load(path) as f:
        station_xyz, site_xyz = f["station_xyz"], f["site_xyz"]
        st, si = f["pair_station"].astype(np.int64), f["pair_site"].astype(np.int64)
        diff = site_xyz[si] - station_xyz[st]
        control = f["site_control_sigma_m"]
        problem = PlanProblem(
            station_ids=tuple(str(i) for i in f["station_ids"]), station_xyz=station_xyz,
            site_ids=tuple(str(i) for i in f["site_ids"]), site_xyz=site_xyz,
            site_existing=control > 0, site_cost=np.where(control > 0, 0.0, 1.0),
            pair_station=st, pair_site=si, pair_distance_m=np.linalg.norm(diff, axis=1),
            pair_bearing_rad=np.arctan2(diff[:, 1], diff[:, 0]),
            pair_sigma_m=f["pair_sigma_m"], pair_reason=np.full(st.size, USABLE, np.int8),
            site_control_sigma_m=control if control.any() else None)
        config = config_from_dict(json.loads(str(f["config"])), where=f"layout {path}")
        meta = json.loads(str(f["meta"]))
    return problem, config, meta
