"""One planning run, end to end: candidates -> visibility -> program -> baselines.

The CLI (``markerplan plan``), the benchmarks and notebooks call
:func:`planner.problem.inputs.load_inputs` and :func:`make_plan`. Candidate sites are
:mod:`planner.problem.candidates`, what each station sees :mod:`planner.problem.sight`, the plan
:func:`planner.program.plan_sites`, the baselines :mod:`planner.program.baselines` and the as-built
check :func:`planner.accuracy.checks.evaluate_layout`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from markerplan.errors import ConfigError, InputFileError
from planner.accuracy.chance import PlanChance, plan_chance, station_odds
from planner.accuracy.checks import LayoutCheck, evaluate_layout, station_infos
from planner.accuracy.network_chance import NetworkChance, network_chance
from planner.accuracy.sampled_chance import SampledChance, sampled_chance
from planner.problem.candidates import Candidates, candidate_sites
from planner.problem.inputs import PlanInputs
from planner.problem.sight import sight_problem
from planner.problem.usability import PlanProblem
from planner.program import PlanResult, plan_sites
from planner.program.baselines import Baseline, greedy_cover, network_baseline, regular_grid


@dataclass
class PlanOutcome:
    """A finished planning run (inputs, intermediate products, the plan and the baselines;
    ``candidates`` and ``visibility`` are ``None`` for a plan from a visibility table).

    ``detection`` records the detection model the pairs' chances came from
    (:func:`planner.problem.detection_odds.detection_record`; ``None``: none, every planned
    marker counted as detected); then ``chance`` holds the plan's exact per-station figures
    (:func:`planner.accuracy.chance.plan_chance`; count and directions only in network mode)
    and ``sampled`` its pass rate over sampled detection outcomes
    (:func:`planner.accuracy.sampled_chance.sampled_chance`); in network mode
    ``network_chance`` the whole network's certified chance with its accuracy
    (:func:`planner.accuracy.network_chance.network_chance`); ``baseline_chances`` each
    baseline's certified chance of passing (network mode: the whole network's), by its name.
    ``design``: a plan whose stations were chosen over an area of interest
    (:func:`planner.design.plan.design_plan`) carries the survey design
    (:class:`planner.design.run.SurveyDesign`); ``None`` for given stations.
    """

    inputs: PlanInputs
    config: object
    model_name: str
    problem: PlanProblem
    candidates: Candidates | None
    visibility: object | None
    result: PlanResult
    baselines: list[Baseline]
    as_built: LayoutCheck | None
    timings_s: dict
    detection: dict | None = None
    chance: PlanChance | None = None
    sampled: SampledChance | None = None
    baseline_chances: dict | None = None
    network_chance: NetworkChance | None = None
    design: object | None = None

    @property
    def selected_ids(self) -> list[str]:
        return [self.problem.site_ids[j] for j in np.flatnonzero(self.result.selected)]


def build_problem(inputs: PlanInputs, config, error_model, progress: bool = True,
                  map_groups=map, detection_model=None, clear_of_stations: bool = True
                  ) -> tuple[PlanProblem, Candidates, object, dict]:
    """Candidates + visibility matrix + usability (:func:`planner.problem.sight.sight_problem`, its
    station groups mapped over by ``map_groups``) -> the program's input.

    Returns ``(problem, candidates, visibility, timings_s)``; existing markers, then control
    points (with their sigmas, :attr:`~planner.problem.usability.PlanProblem.
    site_control_sigma_m`), are appended to the candidate sites (ids as given) and fixed.
    With ``detection_model`` every pair gets its chance of being detected and accepted.
    ``clear_of_stations`` false keeps the candidate sites near the stations (stations that are
    only candidates, :mod:`planner.design`, keep their clearance in the program instead).
    """
    timings = {}
    t = time.perf_counter()
    cand = candidate_sites(inputs.dem, config, boundary=inputs.boundary_xy,
                           exclusions=inputs.exclusions,
                           station_xy=inputs.station_xyz if clear_of_stations else None,
                           craters=inputs.craters, marker_radius_m=inputs.marker_radius_m)
    timings["candidates"] = time.perf_counter() - t
    control_ids = [c.marker_id for c in inputs.control]
    site_ids = list(cand.ids) + list(inputs.existing_ids) + control_ids
    if len(set(site_ids)) != len(site_ids):
        raise InputFileError("existing marker or control point ids clash with candidate ids "
                             "(C00000...) or with each other; rename them")
    site_xyz = np.vstack([cand.centre_m, inputs.existing_xyz]
                         + [c.xyz_m[None] for c in inputs.control])
    fixed = len(inputs.existing_ids) + len(control_ids)
    existing = np.r_[np.zeros(len(cand), bool), np.ones(fixed, bool)]
    sight = sight_problem(inputs, site_ids, site_xyz, config, error_model,
                          site_existing=existing, progress=progress, map_groups=map_groups,
                          detection_model=detection_model)
    timings.update(sight.timings_s)
    problem = sight.problem
    if control_ids:
        # the planner's prior is isotropic: each point's largest sigma (conservative)
        sigma = np.r_[np.zeros(len(site_ids) - len(control_ids)),
                      [c.sigma_m.max() for c in inputs.control]]
        problem = replace(problem, site_control_sigma_m=sigma)
    return problem, cand, sight.visibility, timings


def make_plan(inputs: PlanInputs, config, error_model, model_name: str = "default",
              problem: PlanProblem | None = None, progress: bool = True,
              map_groups=map, detection_model=None, detection_name: str = "default",
              samples: int | None = None) -> PlanOutcome:
    """Run the whole plan: candidates, visibility, integer program, baselines, as-built check.

    Parameters
    ----------
    inputs : PlanInputs
    config : PlanConfig
    error_model : ErrorModel
        Used unless ``problem`` is given.
    model_name : str
        How the error model is named in the outputs.
    problem : PlanProblem, optional
        Plan from this (e.g. a ``--visibility`` table) instead of ray casting.
    progress : bool
        Progress bars on stderr.
    map_groups : callable
        How the ray casting's station groups are mapped over (built-in ``map``: one at a time
        here), see :func:`planner.problem.sight.sight_problem`.
    detection_model : error_model.detection.DetectionModel, optional
        Gives each pair its chance of detection (ignored with ``problem``, which carries its
        own or none); with ``config.chance_epsilon`` the plan holds with that chance.
    detection_name : str
        How the detection model is named in the outputs.
    samples : int, optional
        Sampled detection outcomes for the plan's pass rate (0: none); default the config's
        ``pass_rate_samples``.
    """
    timings: dict = {}
    cand = vis = None
    if inputs.control and not config.network:
        raise ConfigError("control points (`control_path`) are network mode's datum: plan in "
                          "network mode (network = true), or list the points as `existing` "
                          "markers")
    if inputs.control and config.datum == "free":
        raise ConfigError("control points (`control_path`) are a datum, and a free network "
                          "(`datum` = 'free') fixes nothing; drop the control points, or "
                          "`datum` = 'free'")
    if inputs.control and config.reference_station is not None:
        raise ConfigError("control points (`control_path`) are the datum and fix no station: "
                          "drop `reference_station`, or the control points")
    if problem is None:
        problem, cand, vis, timings = build_problem(inputs, config, error_model, progress,
                                                    map_groups, detection_model)
    t = time.perf_counter()
    result = plan_sites(problem, config)
    timings["program"] = time.perf_counter() - t
    t = time.perf_counter()
    if config.network:
        baselines = [result.greedy or network_baseline(problem, config)]
    else:
        baselines = [greedy_cover(problem, config)]
        x0, y0, x1, y1 = plan_bounds(inputs, problem)
        baselines.append(regular_grid(problem, config, (x0, y0, x1, y1)))
    timings["baselines"] = time.perf_counter() - t
    detection = chance = sampled = baseline_chances = whole = None
    if problem.pair_detection_p is not None:
        from planner.problem.detection_odds import detection_record

        t = time.perf_counter()
        detection = detection_record(detection_model, detection_name) \
            if detection_model is not None else {"name": "given with the problem"}
        odds = station_odds(problem, station_infos(problem, config), config)
        chance = plan_chance(problem, result.selected, config, odds)

        def certified(selected: np.ndarray) -> float:
            if config.network:
                return network_chance(problem, selected, config).pass_low
            return plan_chance(problem, selected, config, odds).pass_low

        if config.network:
            whole = network_chance(problem, result.selected, config)
        baseline_chances = {b.name: certified(np.asarray(b.selected, bool))
                            for b in baselines if b.selected is not None}
        samples = config.pass_rate_samples if samples is None else samples
        if samples:
            sampled = sampled_chance(problem, result.selected, config, samples)
        timings["chance"] = time.perf_counter() - t
    as_built = None
    if vis is not None and len(inputs.as_built_ids):
        pab = sight_problem(inputs, inputs.as_built_ids, inputs.as_built_xyz, config,
                            error_model, progress=False, map_groups=map_groups).problem
        as_built = evaluate_layout(pab, np.ones(len(inputs.as_built_ids), bool),
                                   config.replace(existing=(), forbidden=()))
    return PlanOutcome(inputs=inputs, config=config, model_name=model_name, problem=problem,
                       candidates=cand, visibility=vis, result=result, baselines=baselines,
                       as_built=as_built, timings_s=timings, detection=detection,
                       chance=chance, sampled=sampled, baseline_chances=baseline_chances,
                       network_chance=whole)


def plan_bounds(inputs: PlanInputs, problem: PlanProblem) -> tuple[float, float, float, float]:
    """(xmin, ymin, xmax, ymax) the regular-grid baseline covers, site frame, m: the site's
    boundary when it has one, else the candidate sites' extent."""
    if inputs.boundary_xy is not None:
        b = np.asarray(inputs.boundary_xy)
        return float(b[:, 0].min()), float(b[:, 1].min()), float(b[:, 0].max()), \
            float(b[:, 1].max())
    xy = problem.site_xyz[:, :2]
    return float(xy[:, 0].min()), float(xy[:, 1].min()), float(xy[:, 0].max()), \
        float(xy[:, 1].max())
