"""What ``markerplan adjust`` reports, as plain rows and one record, from an adjustment result.

Every writer (:mod:`planner.network.files`, :mod:`planner.network.report`,
:mod:`planner.network.map`) reads the numbers from here, so a figure is computed once and means
the same in every file:

- :func:`station_rows`: adjusted pose, sigmas, 95 % ellipsoid semi-axes and the 95 % station
  error over the working radius (the figure the +-10 cm requirement is about);
- :func:`marker_rows`: adjusted centres, sigmas and 95 % ellipsoid semi-axes;
- :func:`observation_rows`: every identified detection with its residuals, redundancy numbers,
  the test of the point observation (3-D) and the per-component w-tests, minimal detectable
  biases and their effect, its robust weight, and whether data snooping flagged or removed it;
- :func:`variance_rows`: the estimated variance components of observation groups;
- :func:`parameter_rows`: the order and names of the covariance matrix's rows;
- :func:`global_test`: the test of the variance factor (Baarda's B-method);
- :func:`adjustment_record`: the machine-readable summary (``adjustment.json``).

All lengths in metres, site frame; angles in degrees in the tables (radians in the covariance).
Covariances are a-priori (sigma0 = 1): the error model's sigmas are taken as known, and the
global test says whether the data agree with them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy.stats import chi2

from markerplan.provenance import provenance

#: Schema of ``adjustment.json``.
SCHEMA = "markerplan-adjustment"
SCHEMA_VERSION = 1

#: chi-square 95 % quantile with 2 dof: the map's horizontal error ellipses.
CHI2_2_95 = float(chi2.ppf(0.95, 2))

#: Level of the two-sided global test of the variance factor.
GLOBAL_TEST_ALPHA = 0.05

#: Redundancy number below which an observation is weakly controlled: less than a tenth of an
#: error in it shows in its own residual (surveying practice; 0 means uncontrolled).
WEAK_REDUNDANCY = 0.1

STATION_COLUMNS = (
    "station_id", "reference", "x_m", "y_m", "z_m", "heading_deg", "roll_deg", "pitch_deg",
    "sigma_x_m", "sigma_y_m", "sigma_z_m", "sigma_heading_deg", "sigma_roll_deg",
    "sigma_pitch_deg", "ellipsoid_major_m", "ellipsoid_middle_m", "ellipsoid_minor_m",
    "station_error_95_m", "meets_requirement", "n_observations", "n_removed")
MARKER_COLUMNS = (
    "marker_id", "x_m", "y_m", "z_m", "sigma_x_m", "sigma_y_m", "sigma_z_m",
    "ellipsoid_major_m", "ellipsoid_middle_m", "ellipsoid_minor_m", "control", "n_stations",
    "stations", "offset_from_plan_m")
OBSERVATION_COLUMNS = (
    "station_id", "marker_id", "status", "x_m", "y_m", "z_m", "distance_m", "sigma_m",
    "residual_x_m", "residual_y_m", "residual_z_m", "redundancy_x", "redundancy_y",
    "redundancy_z", "w_x", "w_y", "w_z", "max_abs_w", "mdb_x_m", "mdb_y_m", "mdb_z_m",
    "mdb_effect_m", "removed_in_round", "test_statistic", "test_dof", "test_p_value", "test_w",
    "mdb_3d_m", "robust_weight")
VARIANCE_COLUMNS = ("group", "n_observations", "redundancy", "sigma0_squared", "sd")
PARAMETER_COLUMNS = ("index", "parameter", "kind", "id", "name", "value", "sigma")


@dataclass(frozen=True)
class AdjustmentRun:
    """An adjustment result with what the outputs say about how it was made.

    Attributes
    ----------
    result : pipeline.network.adjustment.NetworkAdjustment
    observations : pipeline.network.observations.NetworkObservations
        The observations given to the adjustment (before data snooping).
    config : dict
        The resolved configuration (JSON-serialisable): options, datum, settings.
    working_radius_m : float
        Radius over which a station's registered cloud is assessed, m.
    requirement_m : float
        Required 95 % station error, m.
    error_figure : {"quantile", "ellipsoid"}
        How the 95 % station error is computed (:mod:`planner.accuracy.figure`).
    identity : str
        How markers were identified across stations (``plan``, ``geometry``, ``table``).
    frame : str
        The site frame, in words (local metres, or the CRS of the plan's DEM).
    inputs : list of dict
        The marker tables (and plan, control) read, with their SHA-256.
    error_model : str
        The error model's name.
    unidentified : list of (str, (3,) float, str)
        ``(station_id, xyz_m, reason)`` of detections without a marker id (left out), station
        frame.
    plan_markers : dict of str to (3,) float
        Planned centres by marker id (empty without a plan), site frame.
    crs : str or None
        The CRS (WKT) the coordinates are in: the plan's, when a station is held at its
        planned pose; else ``None`` (a local frame).
    relative : planner.accuracy.local.LocalRequirement or None
        The pairs of stations whose relative error ellipses are reported, and the allowance
        they are judged against (:mod:`planner.network.relative`); None for none.
    """

    result: Any
    observations: Any
    config: dict
    working_radius_m: float
    requirement_m: float
    error_figure: str
    identity: str
    frame: str
    inputs: list = field(default_factory=list)
    error_model: str = ""
    unidentified: list = field(default_factory=list)
    plan_markers: dict = field(default_factory=dict)
    crs: str | None = None
    relative: Any = None


def ellipsoid_axes(cov3: np.ndarray) -> np.ndarray:
    """Semi-axes of the 95 % error ellipsoids of points, largest first, m
    (:meth:`pipeline.network.adjustment.NetworkAdjustment.ellipsoid`, reordered).

    Parameters
    ----------
    cov3 : (k, 3, 3) float
        Covariances of points, m^2.

    Returns
    -------
    axes : (k, 3) float

    Examples
    --------
    >>> np.round(ellipsoid_axes(np.diag([4e-4, 1e-4, 0.0])[None]), 4).tolist()
    [[0.0559, 0.028, 0.0]]
    """
    from pipeline.network.adjustment import NetworkAdjustment

    return np.array([NetworkAdjustment.ellipsoid(c)[0][::-1]
                     for c in np.asarray(cov3, dtype=float)]).reshape(-1, 3)


def horizontal_ellipse(cov3: np.ndarray) -> tuple[float, float, float]:
    """Semi-major and semi-minor axes (m) and the major axis' angle from +x (deg) of a point's
    95 % horizontal error ellipse (the x-y block of its covariance, chi2 with 2 dof).

    Examples
    --------
    >>> a, b, angle = horizontal_ellipse(np.diag([1e-4, 4e-4, 1.0]))
    >>> round(a, 4), round(b, 4), round(angle, 1)
    (0.049, 0.0245, 90.0)
    """
    w, v = np.linalg.eigh(np.asarray(cov3, dtype=float)[:2, :2])
    w = np.clip(w, 0.0, None)
    angle = math.degrees(math.atan2(v[1, 1], v[0, 1])) % 180.0
    return (math.sqrt(CHI2_2_95 * w[1]), math.sqrt(CHI2_2_95 * w[0]), angle)


def station_errors(pose_cov: np.ndarray, heading_rad: np.ndarray,
                   working_radius_m: float, figure: str) -> np.ndarray:
    """95 % station error over the station's working disc
    (:meth:`planner.accuracy.figure.ErrorFigure.station_errors`).

    That figure takes the rim points' offsets ``q`` in the site frame for both the heading
    and the tilt lever arms; the tilt's lever arm is the offset in the station frame. Turning
    the translation block into the station frame (``Rz(heading)^T``) makes the two frames one,
    so the figure is exact at any heading (the eigenvalues do not change under the rotation).

    Parameters
    ----------
    pose_cov : (k, 6, 6) float
        Pose covariances (x, y, z, heading, roll, pitch), m and rad.
    heading_rad : (k,) float
        Adjusted headings.
    working_radius_m : float
    figure : {"quantile", "ellipsoid"}
        Which 95 % figure (:mod:`planner.accuracy.figure`).

    Returns
    -------
    error_m : (k,) float

    Examples
    --------
    A station known to 1 cm per axis and exactly in angle: the error is the translation's.

    >>> cov = np.zeros((1, 6, 6)); cov[0, :3, :3] = np.eye(3) * 1e-4
    >>> np.round(station_errors(cov, np.zeros(1), 10.0, "ellipsoid"), 4).tolist()
    [0.028]
    """
    from pipeline.scans.rig import rot_z
    from planner.accuracy.figure import ErrorFigure

    cov = np.asarray(pose_cov, dtype=float).reshape(-1, 6, 6)
    turn = np.tile(np.eye(6), (cov.shape[0], 1, 1))
    turn[:, :3, :3] = np.swapaxes(rot_z(np.asarray(heading_rad, dtype=float)), 1, 2)
    return ErrorFigure(figure).station_errors(turn @ cov @ np.swapaxes(turn, 1, 2),
                                              working_radius_m)


def global_test(sigma0_squared: float, dof: int, alpha: float = GLOBAL_TEST_ALPHA) -> dict:
    """Chi-square test of the a-posteriori variance factor.

    ``dof * sigma0^2`` follows chi2(dof) when the error model's sigmas are right. Above the
    upper bound (the ``1 - alpha / 2`` quantile) the data are noisier than the model says, or
    hold a blunder: the test fails. Below the lower bound the model is pessimistic: the test
    passes with that verdict, since the predicted errors are then conservative. (Baarda's
    B-method would tie ``alpha`` to the w-test's, but for hundreds of degrees of freedom that
    ``alpha`` exceeds 0.3: a false alarm in every third survey.)

    Parameters
    ----------
    sigma0_squared : float
        A-posteriori variance factor.
    dof : int
        Degrees of freedom (redundancy) of the adjustment.
    alpha : float
        Level of the two-sided range.

    Returns
    -------
    test : dict
        ``statistic`` (sigma0^2), ``dof``, ``alpha``, ``lower`` and ``upper`` (bounds of
        sigma0^2), ``passed``, ``verdict`` (``ok``, ``noisier than the error model``,
        ``error model pessimistic``); all ``None`` but ``dof`` and ``alpha`` without
        redundancy.

    Examples
    --------
    >>> t = global_test(1.02, 100)
    >>> t["passed"], round(t["lower"], 3), round(t["upper"], 3)
    (True, 0.742, 1.296)
    >>> [(t["passed"], t["verdict"]) for t in (global_test(1.5, 100), global_test(0.5, 100))]
    [(False, 'noisier than the error model'), (True, 'error model pessimistic')]
    """
    if dof <= 0 or not math.isfinite(sigma0_squared):
        return {"statistic": None, "dof": int(dof), "alpha": alpha, "lower": None,
                "upper": None, "passed": None, "verdict": None}
    lower = float(chi2.ppf(alpha / 2.0, dof) / dof)
    upper = float(chi2.isf(alpha / 2.0, dof) / dof)
    verdict = ("noisier than the error model" if sigma0_squared > upper else
               "error model pessimistic" if sigma0_squared < lower else "ok")
    return {"statistic": float(sigma0_squared), "dof": int(dof), "alpha": alpha,
            "lower": lower, "upper": upper, "passed": bool(sigma0_squared <= upper),
            "verdict": verdict}


def _pose_covariances(result) -> np.ndarray:
    return np.array([result.station_covariance(i)
                     for i in range(len(result.observations.station_ids))]).reshape(-1, 6, 6)


def _marker_covariances(result) -> np.ndarray:
    return np.array([result.marker_covariance(j)
                     for j in range(len(result.observations.marker_ids))]).reshape(-1, 3, 3)


def _reference_station(result) -> str | None:
    datum = result.datum
    if datum.kind != "station":
        return None
    return datum.reference_id(result.observations.station_ids)


def station_rows(run: AdjustmentRun) -> list[dict]:
    """One row per station (:data:`STATION_COLUMNS`), in the adjustment's order.

    Parameters
    ----------
    run : AdjustmentRun

    Returns
    -------
    rows : list of dict
        Positions in m (site frame), angles and their sigmas in degrees, the 95 % ellipsoid's
        semi-axes and the 95 % station error over ``run.working_radius_m`` in m.
    """
    res = run.result
    obs = res.observations
    cov = _pose_covariances(res)
    sig = np.sqrt(np.clip(np.diagonal(cov, axis1=1, axis2=2), 0.0, None))
    axes = ellipsoid_axes(cov[:, :3, :3])
    err = station_errors(cov, res.pose[:, 3], run.working_radius_m, run.error_figure)
    ref = _reference_station(res)
    removed = [r.station_id for r in res.rejected]
    rows = []
    for i, sid in enumerate(obs.station_ids):
        x, y, z, h, roll, pitch = (float(v) for v in res.pose[i])
        rows.append({
            "station_id": sid, "reference": sid == ref, "x_m": x, "y_m": y, "z_m": z,
            "heading_deg": math.degrees(h) % 360.0, "roll_deg": math.degrees(roll),
            "pitch_deg": math.degrees(pitch), "sigma_x_m": sig[i, 0], "sigma_y_m": sig[i, 1],
            "sigma_z_m": sig[i, 2], "sigma_heading_deg": math.degrees(sig[i, 3]),
            "sigma_roll_deg": math.degrees(sig[i, 4]), "sigma_pitch_deg": math.degrees(sig[i, 5]),
            "ellipsoid_major_m": axes[i, 0], "ellipsoid_middle_m": axes[i, 1],
            "ellipsoid_minor_m": axes[i, 2], "station_error_95_m": float(err[i]),
            "meets_requirement": bool(err[i] <= run.requirement_m),
            "n_observations": int(np.sum(obs.station == i)), "n_removed": removed.count(sid)})
    return rows


def marker_rows(run: AdjustmentRun) -> list[dict]:
    """One row per marker (:data:`MARKER_COLUMNS`), in the adjustment's order.

    Parameters
    ----------
    run : AdjustmentRun

    Returns
    -------
    rows : list of dict
        Centres, sigmas and 95 % ellipsoid semi-axes in m (site frame); the stations that saw
        the marker; its distance from the plan's centre (``None`` without one).
    """
    res = run.result
    obs = res.observations
    cov = _marker_covariances(res)
    sig = np.sqrt(np.clip(np.diagonal(cov, axis1=1, axis2=2), 0.0, None))
    axes = ellipsoid_axes(cov)
    control = {c.marker_id for c in res.datum.control}
    rows = []
    for j, mid in enumerate(obs.marker_ids):
        stations = sorted({obs.station_ids[s] for s in obs.station[obs.marker == j]},
                          key=obs.station_ids.index)
        planned = run.plan_markers.get(mid)
        rows.append({
            "marker_id": mid, **dict(zip(("x_m", "y_m", "z_m"),
                                         (float(v) for v in res.marker_xyz_m[j]), strict=True)),
            "sigma_x_m": sig[j, 0], "sigma_y_m": sig[j, 1], "sigma_z_m": sig[j, 2],
            "ellipsoid_major_m": axes[j, 0], "ellipsoid_middle_m": axes[j, 1],
            "ellipsoid_minor_m": axes[j, 2], "control": mid in control,
            "n_stations": len(stations), "stations": " ".join(stations),
            "offset_from_plan_m": (None if planned is None else
                                   float(np.linalg.norm(res.marker_xyz_m[j] - planned)))})
    return rows


def observation_rows(run: AdjustmentRun, critical_value: float) -> list[dict]:
    """One row per observation given to the adjustment (:data:`OBSERVATION_COLUMNS`).

    ``status`` is ``removed`` (data snooping took it out; its statistics are those of the round
    it was removed in: only the point test's), ``flagged`` (kept although the test of the
    point observation, ``test_w``, exceeds ``critical_value``: snooping was off or stopped,
    or the estimation was robust) or ``kept``. ``test_statistic`` is ``T`` (chi-square with
    ``test_dof`` degrees of freedom), ``test_w`` its p-value's normal deviate; ``w_x`` ...
    and ``max_abs_w`` are the per-component w-tests, ``mdb_3d_m`` the point test's MDB in
    its worst direction.

    Parameters
    ----------
    run : AdjustmentRun
    critical_value : float
        Critical value of the normalised point test
        (:func:`pipeline.network.reliability.critical_value`).

    Returns
    -------
    rows : list of dict
        In the order of ``run.observations``; residuals in site-frame axes, m.
    """
    from pipeline.network.reliability import chi2_logsf

    res = run.result
    given, kept = run.observations, res.observations
    removal = {(r.station_id, r.marker_id): r for r in res.rejected}
    p_value = np.exp(chi2_logsf(res.point.statistic, res.point.dof))
    rows, j = [], 0
    for i in range(len(given.station)):
        sid, mid = given.station_ids[given.station[i]], given.marker_ids[given.marker[i]]
        xyz = given.xyz_m[i]
        row = {"station_id": sid, "marker_id": mid, "x_m": float(xyz[0]), "y_m": float(xyz[1]),
               "z_m": float(xyz[2]), "distance_m": float(np.linalg.norm(xyz)),
               "sigma_m": float(given.sigma_m[i])}
        if j < len(kept.station) and _same(kept, j, sid, mid, xyz):
            w = res.w_test[j]
            test_w = float(res.point.w[j])
            row.update(status="flagged" if test_w > critical_value else "kept",
                       max_abs_w=float(np.abs(w).max()), mdb_effect_m=float(res.mdb_effect_m[j]),
                       removed_in_round=None, test_statistic=float(res.point.statistic[j]),
                       test_dof=int(res.point.dof[j]), test_p_value=float(p_value[j]),
                       test_w=test_w, mdb_3d_m=float(res.mdb_point_m[j]),
                       robust_weight=float(res.robust_weight[j]))
            for a, axis in enumerate("xyz"):
                row.update({f"residual_{axis}_m": float(res.residuals_m[j, a]),
                            f"redundancy_{axis}": float(res.redundancy[j, a]),
                            f"w_{axis}": float(w[a]), f"mdb_{axis}_m": float(res.mdb_m[j, a])})
            j += 1
        else:
            r = removal.get((sid, mid))
            row.update({c: None for c in OBSERVATION_COLUMNS if c not in row})
            row.update(status="removed")
            if r is not None:
                row.update(removed_in_round=int(r.round), test_statistic=float(r.statistic),
                           test_dof=int(r.dof), test_w=float(r.w), test_p_value=float(
                               np.exp(chi2_logsf(np.array([r.statistic]), np.array([r.dof]))[0])))
        rows.append(row)
    if j != len(kept.station):
        raise RuntimeError("the adjustment's kept observations are not a subsequence of the "
                           "observations given to it")
    return rows


def variance_rows(result) -> list[dict]:
    """The estimated variance components (:data:`VARIANCE_COLUMNS`), one row per group, then
    the whole network (``group`` ``all``: the a-posteriori variance factor, the redundancy its
    degrees of freedom); empty when none were estimated.

    Parameters
    ----------
    result : pipeline.network.adjustment.NetworkAdjustment

    Returns
    -------
    rows : list of dict
        ``sigma0_squared`` and its standard deviation ``sd`` under the model, dimensionless.
    """
    if not result.variance_components:
        return []
    rows = [{"group": c.group, "n_observations": c.n_observations, "redundancy": c.redundancy,
             "sigma0_squared": c.sigma0_squared, "sd": c.sd}
            for c in result.variance_components]
    dof, s2 = int(result.dof), float(result.sigma0_squared)
    rows.append({"group": "all", "n_observations": len(result.observations.station),
                 "redundancy": float(dof), "sigma0_squared": s2,
                 "sd": s2 * math.sqrt(2.0 / dof) if dof > 0 else None})
    return rows


def _same(obs, j: int, sid: str, mid: str, xyz: np.ndarray) -> bool:
    return (obs.station_ids[obs.station[j]] == sid and obs.marker_ids[obs.marker[j]] == mid
            and np.array_equal(obs.xyz_m[j], xyz))


def parameter_rows(result) -> list[dict]:
    """The unknowns in the order of the covariance matrix (:data:`PARAMETER_COLUMNS`): the
    stations' poses first, then the markers' centres; ``value`` and ``sigma`` in m or rad.

    Parameters
    ----------
    result : pipeline.network.adjustment.NetworkAdjustment

    Returns
    -------
    rows : list of dict
        ``parameter`` is ``<id>.<name>``, e.g. ``S1.heading_rad``, ``M3.z_m``.
    """
    from pipeline.network.observations import POSE_PARAMETERS

    obs = result.observations
    names = [("station", sid, p) for sid in obs.station_ids for p in POSE_PARAMETERS]
    names += [("marker", mid, p) for mid in obs.marker_ids for p in ("x_m", "y_m", "z_m")]
    values = np.concatenate([np.asarray(result.pose, float).ravel(),
                             np.asarray(result.marker_xyz_m, float).ravel()])
    sigma = np.sqrt(np.clip(result.covariance.diagonal(), 0.0, None))
    return [{"index": k, "parameter": f"{i}.{p}", "kind": kind, "id": i, "name": p,
             "value": float(values[k]), "sigma": float(sigma[k])}
            for k, (kind, i, p) in enumerate(names)]


def adjustment_record(run: AdjustmentRun, stations: list[dict], markers: list[dict],
                      observations: list[dict], files: list[str]) -> dict:
    """The ``adjustment.json`` document (schema :data:`SCHEMA`).

    Parameters
    ----------
    run : AdjustmentRun
    stations, markers, observations : list of dict
        The rows of :func:`station_rows`, :func:`marker_rows` and :func:`observation_rows`.
    files : list of str
        The files written beside it.

    Returns
    -------
    doc : dict
        ``schema``, ``schema_version``, ``provenance`` (configuration, version, inputs, error
        model, solver and its status), ``frame``, ``datum``, ``identity``, ``statistics``,
        ``global_test``, ``data_snooping`` (rejected and flagged observations), ``robust``
        (:func:`robust_record`), ``variance_components`` (:func:`variance_rows`, or ``None``),
        ``reliability``, ``requirement``, ``stations`` and ``markers`` (ids and 95 % figures),
        ``files``.
    """
    from pipeline.network.reliability import critical_value

    res, settings = run.result, run.result.settings
    k = critical_value(settings.alpha0)
    kept = [o for o in observations if o["status"] != "removed"]
    stats = _statistics(res)
    test = global_test(res.sigma0_squared, res.dof)
    converged = res.iterations < settings.max_iterations
    solver = {"name": "Gauss-Newton weighted least squares (pipeline.network.adjustment)",
              "status": "converged" if converged else "iteration limit reached",
              "iterations": int(res.iterations), "max_iterations": int(settings.max_iterations)}
    prov = provenance(run.config, inputs=run.inputs, error_model=run.error_model, solver=solver)
    worst = max(stations, key=lambda s: s["station_error_95_m"])
    return {
        "schema": SCHEMA, "schema_version": SCHEMA_VERSION, "provenance": prov,
        "frame": run.frame,
        "datum": datum_record(res),
        "identity": {"method": run.identity,
                     "n_detections": len(observations) + len(run.unidentified),
                     "n_identified": len(observations),
                     "unidentified": [{"station_id": s, "x_m": float(p[0]), "y_m": float(p[1]),
                                       "z_m": float(p[2]), "reason": why}
                                      for s, p, why in run.unidentified]},
        "statistics": {**stats, "sigma0_squared": float(res.sigma0_squared),
                       "sigma0": math.sqrt(max(float(res.sigma0_squared), 0.0))},
        "global_test": test,
        "data_snooping": {
            "enabled": bool(settings.snooping), "alpha0": settings.alpha0,
            "beta0": settings.beta0, "critical_value": k,
            "test": "point observation (3-D): T = v^T Q_vv^-1 v ~ chi2(3); w = Phi^-1(1 - p/2)",
            "critical_value_T": float(chi2.isf(settings.alpha0, 3)),
            "rejected": [{"station_id": r.station_id, "marker_id": r.marker_id,
                          "w": float(r.w), "T": float(r.statistic), "dof": int(r.dof),
                          "round": int(r.round)} for r in res.rejected],
            "flagged": [{"station_id": o["station_id"], "marker_id": o["marker_id"],
                         "w": o["test_w"], "max_abs_w": o["max_abs_w"]}
                        for o in kept if o["status"] == "flagged"]},
        "robust": robust_record(res, kept),
        "variance_components": (None if settings.variance_components is None else
                                {"groups": settings.variance_components,
                                 "components": variance_rows(res)}),
        "reliability": reliability_summary(kept),
        "requirement": {"requirement_m": run.requirement_m,
                        "working_radius_m": run.working_radius_m,
                        "error_figure": run.error_figure,
                        "n_stations_meeting": sum(s["meets_requirement"] for s in stations),
                        "worst_station": worst["station_id"],
                        "worst_station_error_95_m": worst["station_error_95_m"]},
        "stations": [{"id": s["station_id"], "station_error_95_m": s["station_error_95_m"],
                      "ellipsoid_major_m": s["ellipsoid_major_m"],
                      "meets_requirement": s["meets_requirement"]} for s in stations],
        "markers": [{"id": m["marker_id"], "ellipsoid_major_m": m["ellipsoid_major_m"],
                     "n_stations": m["n_stations"]} for m in markers],
        "files": files,
    }


def robust_record(result, kept: list[dict]) -> dict | None:
    """The robust estimation: estimator, tuning constants, rounds and the down-weighted
    observations (weight below 1, lowest first); ``None`` without one.

    Parameters
    ----------
    result : pipeline.network.adjustment.NetworkAdjustment
    kept : list of dict
        Rows of :func:`observation_rows` of the kept observations.
    """
    settings = result.settings
    if settings.robust is None:
        return None
    constants = ({"k": settings.robust_k0} if settings.robust == "huber" else
                 {"k0": settings.robust_k0, "k1": settings.robust_k1})
    down = sorted((o for o in kept if o["robust_weight"] < 1.0),
                  key=lambda o: (o["robust_weight"], o["station_id"], o["marker_id"]))
    return {"estimator": settings.robust, "constants": constants,
            "rounds": int(result.robust_rounds),
            "statistic": "w of the point test, with the observations' own weights",
            "downweighted": [{"station_id": o["station_id"], "marker_id": o["marker_id"],
                              "weight": o["robust_weight"], "w": o["test_w"]} for o in down]}


def datum_record(result) -> dict:
    """The datum: kind, reference station, control points and a line naming it.

    Parameters
    ----------
    result : pipeline.network.adjustment.NetworkAdjustment

    Returns
    -------
    datum : dict
        ``kind``, ``reference_station`` (``None`` unless ``station``), ``control``,
        ``description``.
    """
    datum = result.datum
    return {"kind": datum.kind, "reference_station": _reference_station(result),
            "control": [{"marker_id": c.marker_id, "xyz_m": c.xyz_m.tolist(),
                         "sigma_m": c.sigma_m.tolist()} for c in datum.control],
            "description": datum.describe(result.observations.station_ids)}


def _statistics(result) -> dict:
    obs = result.observations
    n = len(obs.station)
    return {"n_stations": len(obs.station_ids), "n_markers": len(obs.marker_ids),
            "n_observations": n, "n_observation_components": 3 * n,
            "n_unknowns": 6 * len(obs.station_ids) + 3 * len(obs.marker_ids),
            "dof": int(result.dof), "iterations": int(result.iterations),
            "n_rejected": len(result.rejected)}


def reliability_summary(kept: list[dict]) -> dict:
    """Internal and external reliability over the kept observations (rows of
    :func:`observation_rows`): redundancy numbers, weakly controlled observations, the largest
    MDB and its effect.

    Examples
    --------
    >>> row = {"station_id": "S1", "marker_id": "M1", "redundancy_x": 0.5,
    ...        "redundancy_y": 0.05, "redundancy_z": 0.5, "mdb_x_m": 0.01, "mdb_y_m": 0.04,
    ...        "mdb_z_m": 0.01, "mdb_effect_m": 0.02}
    >>> s = reliability_summary([row])
    >>> s["min_redundancy"], s["n_weak"], s["largest_mdb"]["mdb_m"]
    (0.05, 1, 0.04)
    """
    if not kept:
        return {"mean_redundancy": None, "min_redundancy": None, "n_weak": 0,
                "n_uncontrolled": 0, "largest_mdb": None, "largest_mdb_effect": None}
    r = np.array([[o[f"redundancy_{a}"] for a in "xyz"] for o in kept], dtype=float)
    mdb = np.array([max(o[f"mdb_{a}_m"] for a in "xyz") for o in kept], dtype=float)
    effect = np.array([o["mdb_effect_m"] for o in kept], dtype=float)
    rmin = r.min(axis=1)
    finite = np.isfinite(mdb)

    def at(values: np.ndarray, key: str) -> dict | None:
        if not np.isfinite(values).any():
            return None
        k = int(np.nanargmax(np.where(np.isfinite(values), values, -np.inf)))
        return {"station_id": kept[k]["station_id"], "marker_id": kept[k]["marker_id"],
                key: float(values[k])}

    return {"mean_redundancy": float(r.mean()), "min_redundancy": float(r.min()),
            "n_weak": int(np.sum(rmin < WEAK_REDUNDANCY)),
            "n_uncontrolled": int(np.sum(~finite)),
            "largest_mdb": at(mdb, "mdb_m"), "largest_mdb_effect": at(effect, "mdb_effect_m")}


def frame_note(datum_kind: str, reference: str, plan_given: bool,
               plan_dem: str | None = None, crs: str | None = None) -> str:
    """The site frame of an adjustment, in words.

    With a plan (or control points) it is theirs: the plan's frame
    (:data:`planner.outputs.report.FRAME_NOTE`, or its DEM's); without either, the network defines
    it: the reference station's levelled frame, or for a free network the frame the stations were
    chained into from the reference. ``crs`` (WKT) names the plan's CRS when it has one.

    Examples
    --------
    >>> frame_note("station", "S1", plan_given=False)  # doctest: +ELLIPSIS
    "reference station S1's levelled frame: origin at its LiDAR centre, x along its heading, ..."
    """
    from planner.outputs.report import FRAME_NOTE

    if datum_kind == "control":
        return ("the control points' frame (x, y horizontal, z up, metres); "
                "not geographic coordinates unless the control points are")
    if plan_given and crs is not None:
        from planner.outputs.gis import crs_name

        return (f"site frame of the plan's DEM {Path(plan_dem or 'DEM').name}: its CRS, "
                f"{crs_name(crs)}" + (f"; station {reference} held at its planned pose"
                                      if datum_kind == "station" else ""))
    if plan_given:
        frame = FRAME_NOTE if plan_dem is None else (
            f"site frame of the plan's DEM {Path(plan_dem).name}: its projected CRS when it has "
            "one, else local metres (x, y horizontal, z up)")
        return frame + (f"; station {reference} held at its planned pose"
                        if datum_kind == "station" else "")
    local = "(local metres, not geographic coordinates)"
    if datum_kind == "free":
        return (f"local frame of the network, chained from station {reference}'s levelled "
                f"frame; origin and orientation held at the stations' centroid and mean heading "
                + local)
    return (f"reference station {reference}'s levelled frame: origin at its LiDAR centre, x "
            f"along its heading, z up {local}")
