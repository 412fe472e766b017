"""What each station sees, written once: ray scene -> visibility matrix -> usable pairs.

The one way plans, their as-built check and reduction studies get a
:class:`~planner.usability.PlanProblem` from terrain: a terrain-only
:class:`visibility.scene.RayScene`, the station x site
:func:`visibility.visibility_matrix.visibility_matrix` with the default rig's angular sampling
(:mod:`visibility.sensor`), and the usability verdict of
:func:`planner.usability.problem_from_visibility`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from planner.usability import PlanProblem, problem_from_visibility
from visibility.scene import RayScene
from visibility.sensor import RigConfig, SensorConfig
from visibility.visibility_matrix import AngularSampling, VisibilityMatrix, visibility_matrix


@dataclass(frozen=True)
class Sight:
    """The visibility of some sites from a plan's stations and the program input it gives.

    Attributes
    ----------
    problem : PlanProblem
    visibility : VisibilityMatrix
    scene : RayScene
        Re-usable for other sites on the same terrain.
    timings_s : dict
        ``"scene"`` (when the scene was built here) and ``"visibility"``, s.
    """

    problem: PlanProblem
    visibility: VisibilityMatrix
    scene: RayScene
    timings_s: dict


def angular_sampling() -> AngularSampling:
    """The default rig's angular sampling (:mod:`visibility.sensor`) for point counts."""
    return AngularSampling(azimuth_step_rad=SensorConfig().azimuth_step_rad,
                           frames_per_turn=RigConfig().frames_per_turn)


def sight_problem(inputs, site_ids, site_xyz: np.ndarray, config, error_model,
                  site_existing: np.ndarray | None = None, scene: RayScene | None = None,
                  progress: bool = True) -> Sight:
    """Ray-cast the stations against some sites and judge every pair.

    Parameters
    ----------
    inputs : planner.planning.PlanInputs
        Uses ``dem``, ``station_ids``, ``station_xyz`` and ``marker_radius_m``.
    site_ids : sequence of str, (n,)
    site_xyz : (n, 3) float
        Marker centres at the sites, site frame, m.
    config : PlanConfig
        Uses ``max_range_m``, ``rays_per_marker`` and the usability settings of
        :func:`~planner.usability.problem_from_visibility`.
    error_model : ErrorModel
    site_existing : (n,) bool, optional
        Markers already in the field (fixed and free in the plan).
    scene : RayScene, optional
        The terrain scene of ``inputs.dem`` when already built.
    progress : bool
        Progress bar on stderr.

    Returns
    -------
    sight : Sight
    """
    timings = {}
    if scene is None:
        t = time.perf_counter()
        scene = RayScene(inputs.dem)
        timings["scene"] = time.perf_counter() - t
    vis = visibility_matrix(scene, inputs.station_xyz, site_xyz, inputs.marker_radius_m,
                            config.max_range_m, config.rays_per_marker, angular_sampling(),
                            progress=progress)
    timings["visibility"] = vis.elapsed_s
    problem = problem_from_visibility(vis, error_model, config, inputs.station_ids,
                                      inputs.station_xyz, site_ids, site_xyz,
                                      site_existing=site_existing)
    return Sight(problem=problem, visibility=vis, scene=scene, timings_s=timings)
