"""What each station sees, written once: tiled ray scenes -> visibility matrix -> usable pairs.

The one way plans, their as-built check, stand maps and reduction studies get a
:class:`~planner.problem.usability.PlanProblem` from terrain: the station x site
:func:`visibility.visibility_matrix.tiled_visibility` (stations in blocks, each cast through a
terrain-only :class:`visibility.scene.RayScene` of the DEM tile within its reach, so no step
holds a mesh of the whole site) with the default rig's angular sampling
(:mod:`visibility.sensor`), and the usability verdict of
:func:`planner.problem.usability.problem_from_visibility`.

On a DEM with nodata the rays cross filled heights that nobody measured: a sight line whose
ground track crosses a nodata cell (:func:`crosses_nodata`) is not counted on (judged occluded),
since unknown terrain could hide the marker.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from planner.problem.usability import OCCLUDED, PlanProblem, problem_from_visibility
from visibility.sensor import RigConfig, SensorConfig
from visibility.visibility_matrix import AngularSampling, VisibilityMatrix, tiled_visibility


@dataclass(frozen=True)
class Sight:
    """The visibility of some sites from a plan's stations and the program input it gives.

    Attributes
    ----------
    problem : PlanProblem
    visibility : VisibilityMatrix
    timings_s : dict
        ``"scene"`` (tile scenes built, summed) and ``"visibility"`` (ray casting, summed), s.
    """

    problem: PlanProblem
    visibility: VisibilityMatrix
    timings_s: dict


def angular_sampling() -> AngularSampling:
    """The default rig's angular sampling (:mod:`visibility.sensor`) for point counts."""
    return AngularSampling(azimuth_step_rad=SensorConfig().azimuth_step_rad,
                           frames_per_turn=RigConfig().frames_per_turn)


def sight_problem(inputs, site_ids, site_xyz: np.ndarray, config, error_model,
                  site_existing: np.ndarray | None = None, progress: bool = True,
                  map_groups=map, desc: str = "visibility", detection_model=None) -> Sight:
    """Ray-cast the stations against some sites and judge every pair.

    Parameters
    ----------
    inputs : planner.problem.inputs.PlanInputs
        Uses ``dem``, ``station_ids``, ``station_xyz`` and ``marker_radius_m``.
    site_ids : sequence of str, (n,)
    site_xyz : (n, 3) float
        Marker centres at the sites, site frame, m.
    config : PlanConfig
        Uses ``max_range_m``, ``rays_per_marker`` and the usability settings of
        :func:`~planner.problem.usability.problem_from_visibility`.
    error_model : ErrorModel
    site_existing : (n,) bool, optional
        Markers already in the field (fixed and free in the plan).
    progress : bool
        Progress bar on stderr.
    map_groups : callable
        How the station groups are mapped over (built-in ``map`` by default; a distributed
        map for a cluster), see :func:`~visibility.visibility_matrix.tiled_visibility`.
    desc : str
        The progress bar's label (the stand map's is ``"stand map"``: each bar of a run has
        its own).
    detection_model : error_model.detection.DetectionModel, optional
        Gives every pair its chance of being detected and accepted
        (:func:`planner.problem.detection_odds.pair_detection_probability`), times the chance
        that the terrain shows it when the DEM declares a height error
        (``inputs.height_error``, :func:`planner.problem.terrain_uncertainty.visible_probability`).

    Returns
    -------
    sight : Sight
        Usable pairs whose sight line crosses nodata (:func:`crosses_nodata`) are judged
        occluded.
    """
    vis, stats = tiled_visibility(inputs.dem, inputs.station_xyz, site_xyz,
                                  inputs.marker_radius_m, config.max_range_m,
                                  config.rays_per_marker, angular_sampling(),
                                  map_groups=map_groups, progress=progress, desc=desc)
    timings = {"scene": stats["scene_s"], "visibility": vis.elapsed_s}
    problem = problem_from_visibility(vis, error_model, config, inputs.station_ids,
                                      inputs.station_xyz, site_ids, site_xyz,
                                      site_existing=site_existing)
    if inputs.dem.valid is not None:
        problem = _unknown_terrain_occludes(problem, inputs.dem)
    if detection_model is not None:
        problem = replace(problem, pair_detection_p=_detection_p(
            inputs, vis, site_xyz, config, detection_model, map_groups))
    return Sight(problem=problem, visibility=vis, timings_s=timings)


def _detection_p(inputs, vis: VisibilityMatrix, site_xyz: np.ndarray, config, model,
                 map_groups) -> np.ndarray:
    """(p,) each pair's chance of being detected and accepted (the terrain's chance of showing
    it included when the DEM declares a height error)."""
    from planner.problem.detection_odds import pair_covariates, pair_detection_probability

    visible = None
    if getattr(inputs, "height_error", None) is not None:
        from planner.problem.terrain_uncertainty import visible_probability

        visible = visible_probability(inputs, vis, site_xyz, config, map_groups=map_groups)
    covariates = pair_covariates(inputs.dem, inputs.craters, inputs.station_xyz, site_xyz, vis)
    return pair_detection_probability(model, covariates, visible)


def _unknown_terrain_occludes(problem: PlanProblem, dem) -> PlanProblem:
    """``problem`` with its usable pairs whose sight line crosses nodata judged occluded."""
    usable = np.flatnonzero(problem.pair_usable)
    over = crosses_nodata(dem, problem.station_xyz[problem.pair_station[usable], :2],
                          problem.site_xyz[problem.pair_site[usable], :2])
    reason = problem.pair_reason.copy()
    reason[usable[over]] = OCCLUDED
    return replace(problem, pair_reason=reason)


#: Most sample points :func:`crosses_nodata` holds at once (24 bytes each, with indices).
_SAMPLES_PER_CHUNK = 4_000_000


def crosses_nodata(dem, start_xy: np.ndarray, end_xy: np.ndarray) -> np.ndarray:
    """Whether each 2-D segment crosses a nodata cell of the DEM (or leaves it).

    Each segment is sampled every half cell, both ends included; a sample counts as nodata
    when the cell it falls in (the nearest cell centre) is not valid
    (:meth:`~visibility.dem.DEM.valid_mask`) or it lies off the grid.

    Parameters
    ----------
    dem : visibility.dem.DEM
        Terrain, site frame.
    start_xy, end_xy : (p, 2) float
        Segment ends (a station and a site), site frame, m.

    Returns
    -------
    crosses : (p,) bool

    Examples
    --------
    >>> from visibility.dem import DEM
    >>> valid = np.ones((5, 9), bool); valid[:, 4] = False
    >>> dem = DEM(np.zeros((5, 9)), (0.0, 0.0), 1.0, valid=valid)
    >>> crosses_nodata(dem, np.array([[0.0, 2.0], [0.0, 0.0]]),
    ...                np.array([[8.0, 2.0], [3.0, 4.0]])).tolist()
    [True, False]
    """
    start = np.asarray(start_xy, dtype=float).reshape(-1, 2)
    delta = np.asarray(end_xy, dtype=float).reshape(-1, 2) - start
    step = 0.5 * dem.cell_size_m
    n = np.ceil(np.hypot(delta[:, 0], delta[:, 1]) / step).astype(np.int64) + 1
    valid = dem.valid_mask()
    ny, nx = valid.shape
    x0, y0 = dem.origin_m
    crosses = np.zeros(len(start), dtype=bool)
    first = 0
    while first < len(start):
        last = first + max(1, int(np.searchsorted(np.cumsum(n[first:]), _SAMPLES_PER_CHUNK)))
        k = np.arange(first, last)
        pair = np.repeat(k - first, n[k])
        offset = np.cumsum(n[k]) - n[k]
        t = (np.arange(pair.size) - offset[pair]) / np.maximum(n[k] - 1, 1)[pair]
        x = start[k, 0][pair] + t * delta[k, 0][pair]
        y = start[k, 1][pair] + t * delta[k, 1][pair]
        i = np.rint((x - x0) / dem.cell_size_m).astype(np.int64)
        j = np.rint((y - y0) / dem.cell_size_m).astype(np.int64)
        off = (i < 0) | (i >= nx) | (j < 0) | (j >= ny)
        bad = off | ~valid[np.clip(j, 0, ny - 1), np.clip(i, 0, nx - 1)]
        crosses[k] = np.bincount(pair, weights=bad, minlength=k.size) > 0
        first = last
    return crosses
