"""The marker plan of the stations a survey design chose, made like any other plan.

:func:`design_plan` runs :func:`planner.design.run.design_survey`, then
:func:`planner.run.make_plan` on the chosen stations in route order (ids ``S1``, ``S2``, ...,
each heading the way the rover arrived), so ``plan.json``, the report, the maps, ``verify`` and
``reduce`` treat the result like a plan of given stations; the outcome carries the design.

The second plan is exact for the chosen stations: where the joint program proved its layout
optimal it finds as few markers (the joint optimum could otherwise be improved); with a chance
constraint (``chance_epsilon``), which the joint program does not model, it may need more.
"""

from __future__ import annotations

from dataclasses import replace

from planner.design.run import design_survey
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
    """
    design = design_survey(inputs, config, error_model, aoi, keepouts=keepouts,
                           route_start_xy=route_start_xy, route_start_source=route_start_source,
                           progress=progress, map_groups=map_groups,
                           detection_model=detection_model, hand_layout=hand_layout)
    chosen = replace(inputs, station_ids=design.station_ids,
                     station_xyz=design.station_position_m,
                     station_heading_rad=design.station_heading_rad,
                     sources={**inputs.sources, "stations_chosen": True})
    outcome = make_plan(chosen, config, error_model, model_name, progress=progress,
                        map_groups=map_groups, detection_model=detection_model,
                        detection_name=detection_name)
    timings = {**{f"design_{k}": v for k, v in design.timings_s.items()}, **outcome.timings_s}
    return replace(outcome, design=design, timings_s=timings)
