"""The chance that each station-site pair's marker is detected and accepted, for the planner.

A plan is made before the field; what the field loses (:mod:`pipeline.surveys.fates`) is predicted
by a detection model (:class:`error_model.detection.DetectionModel`, fitted on full-chain fate
tables) from each pair's covariates. :func:`pair_covariates` computes exactly the covariates the
loss study records (:mod:`planner.studies.loss_study`), from the planner's visibility matrix and
terrain: distance, elevation, incidence on the local ground, ground slope, distance to the
nearest crater rim, visible fraction and expected points. :func:`detection_record` is what a
plan records of the model it used.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from visibility.dem import DEM


def terrain_normal(dem: DEM, xy: np.ndarray, step_m: float | None = None) -> np.ndarray:
    """(n, 3) upward unit normals of the terrain at ``xy`` (central differences over one cell,
    or ``step_m``).

    Parameters
    ----------
    dem : DEM
    xy : (n, 2) float
        Points, site frame, m.
    step_m : float, optional
        Half the difference stencil, m (default one DEM cell).
    """
    h = step_m or dem.cell_size_m
    dx = (dem.height_at(xy + [h, 0]) - dem.height_at(xy - [h, 0])) / (2 * h)
    dy = (dem.height_at(xy + [0, h]) - dem.height_at(xy - [0, h])) / (2 * h)
    n = np.column_stack([-dx, -dy, np.ones(len(xy))])
    return n / np.linalg.norm(n, axis=1)[:, None]


def rim_distance(craters: Sequence, xy: np.ndarray) -> np.ndarray:
    """(n,) distance of each point to the nearest crater's rim crest, m (``inf``: no crater).

    Parameters
    ----------
    craters : sequence
        Objects with ``centre_xy_m`` ((2,) m) and ``diameter_m``.
    xy : (n, 2) float
        Points, site frame, m.
    """
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    if not len(craters):
        return np.full(len(xy), np.inf)
    c = np.array([cr.centre_xy_m for cr in craters])
    r = np.array([cr.diameter_m / 2 for cr in craters])
    return np.abs(np.linalg.norm(xy[:, None] - c[None], axis=2) - r[None]).min(axis=1)


def pair_covariates(dem: DEM, craters: Sequence, station_xyz: np.ndarray, site_xyz: np.ndarray,
                    vis) -> dict[str, np.ndarray]:
    """The detection model's covariates of every pair of a visibility matrix.

    Parameters
    ----------
    dem : DEM
        The terrain the markers stand on.
    craters : sequence
        Known craters (``centre_xy_m``, ``diameter_m``); empty when unknown (a user's DEM).
    station_xyz : (s, 3) float
        LiDAR centres, site frame, m.
    site_xyz : (n, 3) float
        Marker centres, site frame, m.
    vis : visibility.visibility_matrix.VisibilityMatrix
        Pairs (``station``, ``site``) with distance, elevation, visible fraction and expected
        points.

    Returns
    -------
    covariates : dict of (p,) float
        ``distance_m``, ``elevation_deg``, ``incidence_deg`` (angle between the line of sight
        and the ground normal at the site), ``slope_deg``, ``rim_distance_m``,
        ``visible_fraction``, ``expected_points``.
    """
    site_xyz = np.asarray(site_xyz, dtype=float)
    station = np.asarray(vis.station, np.int64)
    site = np.asarray(vis.site, np.int64)
    unique_sites, where = np.unique(site, return_inverse=True)
    normal = terrain_normal(dem, site_xyz[unique_sites, :2])
    rim = rim_distance(craters, site_xyz[unique_sites, :2])
    los = site_xyz[site] - np.asarray(station_xyz, dtype=float)[station]
    los /= np.maximum(np.linalg.norm(los, axis=1), 1e-12)[:, None]
    cos_inc = np.abs((los * normal[where]).sum(axis=1))
    return {"distance_m": np.asarray(vis.distance_m, float),
            "elevation_deg": np.degrees(np.asarray(vis.elevation_rad, float)),
            "incidence_deg": np.degrees(np.arccos(np.clip(cos_inc, 0.0, 1.0))),
            "slope_deg": np.degrees(np.arccos(np.clip(normal[where, 2], 0.0, 1.0))),
            "rim_distance_m": rim[where],
            "visible_fraction": np.asarray(vis.visible_fraction, float),
            "expected_points": np.asarray(vis.expected_points, float)}


def pair_detection_probability(model, covariates: dict[str, np.ndarray],
                               visible_probability: np.ndarray | None = None) -> np.ndarray:
    """(p,) P(detected and accepted) of each pair: the model's, times ``P(visible)``.

    Parameters
    ----------
    model : error_model.detection.DetectionModel
    covariates : dict of (p,) float
        :func:`pair_covariates`.
    visible_probability : (p,) float, optional
        The chance that the true terrain lets the station see the marker at all (a planning
        DEM known only to its height error); default 1.
    """
    p = np.clip(np.asarray(model.probability(**covariates), dtype=float), 0.0, 1.0)
    if visible_probability is not None:
        p = p * np.clip(np.asarray(visible_probability, dtype=float), 0.0, 1.0)
    return p


def detection_record(model, name: str) -> dict:
    """What a plan records of its detection model: where it came from and what it uses.

    Parameters
    ----------
    model : error_model.detection.DetectionModel
    name : str
        ``"default"`` or the file it was read from.
    """
    info = model.info
    return {"name": name,
            "features": [f.to_json() for f in model.features],
            "coefficients": [float(c) for c in model.coef],
            "data": info.get("data"),
            "calibration": info.get("calibration")}
