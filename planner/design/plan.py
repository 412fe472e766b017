"""The marker plan of the stations a survey design chose, made like any other plan.

:func:`design_plan` runs :func:`planner.design.run.design_survey`, then
:func:`planner.run.make_plan` on the chosen stations in route order (ids ``S1``, ``S2``, ...,
each heading the way the rover arrived), so ``plan.json``, the report, the maps, ``verify`` and
``reduce`` treat the result like a plan of given stations; the outcome carries the design.

The route is a closed traverse: in network mode with odometry the plan's
``odometry_loop_m`` is the distance the rover drives from the last station back to the route
start and on to the first (the route's last and first legs), so the odometry's closing
reading ties the last station to the first (:mod:`planner.accuracy.aids`).

The second plan is exact for the chosen stations: where the joint program proved its layout
optimal it finds as few markers (the joint optimum could otherwise be improved); with a chance
constraint (``chance_epsilon``), which the joint program does not model, it may need more.
"""

from __future__ import annotations

from dataclasses import replace

from markerplan.errors import ConfigError
from planner.design.run import SurveyDesign, design_survey
from planner.problem.inputs import PlanInputs
from planner.run import PlanOutcome, make_plan


def design_plan(inputs: PlanInputs, config, error_model, aoi, model_name: str = "default",
                keepouts=(), route_start_xy=None, route_start_source: str = "given",
                progress: bool = True, map_groups=map, detection_model=None,
                detection_name: str = "default", hand_layout: bool = True) -> PlanOutcome:
    """Choose stations, markers and traverse over ``aoi``, then plan the stations' markers.

    Parameters are those of :func:`planner.design.run.design_survey` and
    :func:`planner.run.make_plan`.

    Returns
    -------
    outcome : PlanOutcome
        The chosen stations' plan; ``outcome.design`` the survey design.

    Raises
    ------
    ConfigError
        ``odometry_loop_m`` given: the route sets it.
    """
    if config.odometry_loop_m is not None:
        raise ConfigError(f"`odometry_loop_m` ({config.odometry_loop_m:g} m) of a plan over an "
                          "area of interest is the distance its route drives back to the first "
                          "station, set from the route; drop odometry_loop_m")
    design = design_survey(inputs, config, error_model, aoi, keepouts=keepouts,
                           route_start_xy=route_start_xy, route_start_source=route_start_source,
                           progress=progress, map_groups=map_groups,
                           detection_model=detection_model, hand_layout=hand_layout)
    chosen = replace(inputs, station_ids=design.station_ids,
                     station_xyz=design.station_position_m,
                     station_heading_rad=design.station_heading_rad,
                     sources={**inputs.sources, "stations_chosen": True})
    outcome = make_plan(chosen, closed_traverse(config, design), error_model, model_name,
                        progress=progress,
                        map_groups=map_groups, detection_model=detection_model,
                        detection_name=detection_name)
    timings = {**{f"design_{k}": v for k, v in design.timings_s.items()}, **outcome.timings_s}
    return replace(outcome, design=design, timings_s=timings)


def closed_traverse(config, design: SurveyDesign):
    """``config`` (a :class:`~planner.config.PlanConfig`) with the route's closing legs as the
    odometry's ``odometry_loop_m``: the route's last leg (last station -> start) plus its first
    (start -> first station), m; unchanged outside network mode, without odometry, or with
    fewer than two stations (no other station to close on)."""
    if not (config.network and config.odometry.any and design.order.size > 1):
        return config
    leg = design.route.leg_m
    return config.replace(odometry_loop_m=float(leg[-1] + leg[0]))
