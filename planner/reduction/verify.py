"""``markerplan reduce --verify``: simulate and process the stations at chosen points of the
trade-off curve, with :func:`planner.verify.known_control.verify_plans` (simulator + pipeline +
4-DoF WLS registration; every count's stations as one map), and set the achieved registration errors
beside the predicted ones."""

from __future__ import annotations

import numpy as np

from markerplan.errors import ConfigError
from planner.outputs.plan_file import PlannedStation, SurveyPlan
from planner.verify.known_control import verify_plans


def default_counts(study) -> tuple[int, ...]:
    """The full layout and the fewest markers meeting the requirement (or the curve's end)."""
    ks = [study.curve.points[0].k]
    last = study.curve.k_feasible or study.curve.points[-1].k
    if last not in ks:
        ks.append(last)
    return tuple(ks)


def _counts_iv(study, ks) -> tuple[int, ...]:
    on_curve = [p.k for p in study.curve.points]
    bad = [k for k in ks if k not in on_curve]
    if bad:
        raise ConfigError(f"`verify_k` must be counts on the curve ({min(on_curve)}.."
                          f"{max(on_curve)}), got {', '.join(map(str, bad))}")
    return tuple(dict.fromkeys(ks))


def point_plan(study, inputs, k: int) -> SurveyPlan:
    """The plan of the curve's ``k``-marker subset, for the verifier.

    Parameters
    ----------
    study : ReductionStudy
    inputs : PlanInputs
        Terrain, station headings and marker radius of the study.
    k : int
        A count on the curve.
    """
    prob, cfg = study.problem, study.config
    p = study.curve.at(k)
    sel = np.flatnonzero(p.selected)
    stations = tuple(
        PlannedStation(sid, prob.station_xyz[s].astype(float),
                       float(inputs.station_heading_rad[s]), float(p.error_m[s]),
                       tuple(prob.site_ids[j]
                             for j in prob.pair_site[prob.selected_pairs(s, p.selected)]))
        for s, sid in enumerate(prob.station_ids))
    return SurveyPlan(dem=inputs.dem, stations=stations,
                      marker_ids=tuple(prob.site_ids[j] for j in sel),
                      marker_xyz_m=prob.site_xyz[sel].astype(float),
                      marker_radius_m=inputs.marker_radius_m, requirement_m=cfg.requirement_m,
                      working_radius_m=cfg.working_radius_m)


def verify_points(study, inputs, ks, error_model, seed: int = 0, progress: bool = True,
                  offsets=None, executor=None) -> dict:
    """Verify the curve at the counts ``ks`` (default :func:`default_counts`).

    Parameters
    ----------
    study : ReductionStudy
    inputs : PlanInputs
    ks : sequence of int or None
        Counts on the curve.
    error_model : ErrorModel
        Registration weights.
    seed : int
        Simulation seed (the same for every count, so differences come from the markers).
    progress : bool
    offsets : pipeline.scans.rig.MountingOffsets, optional
        True mounting offsets of the simulated rig (default: none); see
        :func:`planner.verify.known_control.verify_plan`.
    executor : planner.distributed.Executor, optional
        Where the stations run, every point's together under one progress bar (default: in
        this process).

    Returns
    -------
    record : dict
        ``{"seed", "points": [{"k", "markers", "predicted_worst_error_m",
        "achieved_worst_error_m", "achieved_mean_error_m", "passed", "stations": [...]}]}``;
        a station whose pose could not be registered has ``achieved_error_m`` None, and then
        the point's ``achieved_worst_error_m`` is None too.
    """
    ks = default_counts(study) if ks is None else _counts_iv(study, ks)
    plans = [point_plan(study, inputs, k) for k in ks]
    all_checks = verify_plans(plans, error_model, seed=seed, progress=progress, offsets=offsets,
                              executor=executor, names=[f"k={k}" for k in ks])
    points = []
    for k, plan, checks in zip(ks, plans, all_checks, strict=True):
        achieved = [c.achieved_error_m for c in checks]
        finite = [a for a in achieved if a is not None]
        points.append({
            "k": k, "markers": list(plan.marker_ids),
            "predicted_worst_error_m": max(s.predicted_error_m for s in plan.stations),
            "achieved_worst_error_m": (max(finite) if len(finite) == len(achieved)
                                       else None),
            "achieved_mean_error_m": float(np.mean(finite)) if finite else None,
            "passed": all(c.passed for c in checks),
            "stations": [{"id": c.station_id, "predicted_error_m": c.predicted_error_m,
                          "achieved_error_m": c.achieved_error_m,
                          "n_detected_markers": c.n_detected, "n_planned_markers": c.n_planned,
                          "passed": c.passed, "reason": c.reason} for c in checks]})
    return {"seed": seed, "method": "planner.verify.known_control.verify_plan (simulate_markers -> "
            "process_station -> 4-DoF WLS -> registration error over the working radius)",
            "points": points}
