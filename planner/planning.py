"""One planning run, end to end: inputs -> candidates -> visibility -> program -> baselines.

The CLI (``markerplan plan``), the benchmark and notebooks call :func:`load_inputs` and
:func:`make_plan`; writing files is :mod:`planner.report` and :mod:`planner.plan_map`.
"""

from __future__ import annotations

import csv
import json
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from markerplan.errors import DataError, InputFileError
from planner.baselines import Baseline, greedy_cover, regular_grid
from planner.candidates import Candidates, candidate_sites, load_polygons
from planner.program import LayoutCheck, PlanResult, evaluate_layout, plan_sites
from planner.usability import PlanProblem, problem_from_visibility


@dataclass
class PlanInputs:
    """Everything a plan is made for, site frame (metres).

    Attributes
    ----------
    site_name : str
    seed : int or None
    dem : visibility.dem.DEM
    station_ids : list of str
    station_xyz : (s, 3) float
        LiDAR centres, m.
    station_heading_rad : (s,) float
    boundary_xy : (k, 2) float or None
        Where markers may go (None: the whole DEM).
    exclusions : list of shapely Polygon
    craters : list
        Objects with ``centre_xy_m`` and ``diameter_m`` (for the map and crater exclusion).
    as_built_ids : list of str
    as_built_xyz : (m, 3) float
        The site's as-built marker layout (empty when not known), m.
    existing_ids : list of str
    existing_xyz : (e, 3) float
        Markers already in the field, fixed in the plan, m.
    marker_radius_m : float
    sources : dict
        Where each input came from (for provenance).
    """

    site_name: str
    seed: int | None
    dem: object
    station_ids: list[str]
    station_xyz: np.ndarray
    station_heading_rad: np.ndarray
    boundary_xy: np.ndarray | None
    exclusions: list
    craters: list
    as_built_ids: list[str]
    as_built_xyz: np.ndarray
    existing_ids: list[str] = field(default_factory=list)
    existing_xyz: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    marker_radius_m: float = 0.10
    lidar_height_m: float = 1.0
    sources: dict = field(default_factory=dict)


def load_inputs(site: str = "default", seed: int | None = None, dem_path=None,
                stations_path=None, boundary_path=None, exclude_paths=(),
                existing: str | None = None) -> PlanInputs:
    """Assemble the inputs of a plan from a site preset and optional files.

    Parameters
    ----------
    site : str
        Preset name (``visibility.sites``); supplies what no file replaces.
    seed : int, optional
        Preset seed.
    dem_path : path, optional
        GeoTIFF / npz DEM in the site frame (replaces the preset terrain; the preset's craters
        and as-built layout are then dropped).
    stations_path : path, optional
        Stations CSV (``id, x_m, y_m[, z_m][, heading_deg]``; ``z_m`` is the LiDAR centre, default
        ground + rig height) or GeoJSON Points with an ``id`` property.
    boundary_path : path, optional
        GeoJSON polygon: where markers may go.
    exclude_paths : sequence of path
        GeoJSON polygons where no marker may go.
    existing : str, optional
        ``"as-built"`` (the preset's layout) or a markers CSV (``id, x_m, y_m[, z_m]``): markers
        already in the field, fixed in the plan.
    """
    from visibility.dem import read_dem
    from visibility.sites import load_site

    preset = load_site(site, seed)
    sources = {"site": site, "seed": preset.seed}
    dem = preset.dem
    craters = list(preset.craters)
    as_built_ids, as_built_xyz = list(preset.marker_ids), np.asarray(preset.marker_centres_m)
    boundary = np.asarray(preset.boundary_xy_m, float) if len(preset.boundary_xy_m) else None
    if dem_path is not None:
        dem = read_dem(dem_path)
        sources["dem"] = str(dem_path)
        craters, boundary = [], None
        as_built_ids, as_built_xyz = [], np.zeros((0, 3))
    lidar_h = float(preset.lidar_height_m)
    if stations_path is not None:
        ids, xyz, heading = read_stations(stations_path, dem, lidar_h)
        sources["stations"] = str(stations_path)
        as_built_ids, as_built_xyz = [], np.zeros((0, 3))
    else:
        ids = list(preset.station_ids)
        _check_inside(dem, np.asarray(preset.station_xy_m), ids, "station")
        xyz = np.column_stack([preset.station_xy_m,
                               dem.height_at(preset.station_xy_m) + lidar_h])
        heading = np.asarray(preset.station_heading_rad, float)
    if boundary_path is not None:
        boundary = np.asarray(load_polygons(boundary_path, "--boundary")[0].exterior.coords)
        sources["boundary"] = str(boundary_path)
    exclusions = []
    for p in exclude_paths:
        exclusions += load_polygons(p, "--exclude")
    if exclude_paths:
        sources["exclude"] = [str(p) for p in exclude_paths]
    ex_ids, ex_xyz = [], np.zeros((0, 3))
    if existing == "as-built":
        if not as_built_ids:
            raise InputFileError("--existing as-built: this input has no as-built layout (it is "
                                 "dropped with --dem/--stations); give a markers CSV instead")
        ex_ids, ex_xyz = list(as_built_ids), as_built_xyz.copy()
    elif existing is not None:
        ex_ids, ex_xyz = read_markers(existing, dem, float(preset.marker_radius_m))
    if existing is not None:
        sources["existing"] = existing
    return PlanInputs(site_name=site, seed=preset.seed, dem=dem, station_ids=ids,
                      station_xyz=xyz, station_heading_rad=heading, boundary_xy=boundary,
                      exclusions=exclusions, craters=craters, as_built_ids=as_built_ids,
                      as_built_xyz=as_built_xyz, existing_ids=ex_ids, existing_xyz=ex_xyz,
                      marker_radius_m=float(preset.marker_radius_m), lidar_height_m=lidar_h,
                      sources=sources)


def _check_inside(dem, xy: np.ndarray, ids, label: str) -> None:
    inside = dem.contains(xy)
    if not inside.all():
        k = int(np.flatnonzero(~inside)[0])
        xmin, xmax, ymin, ymax = dem.extent()
        raise DataError(f"{label} {ids[k]} at ({xy[k, 0]:.2f}, {xy[k, 1]:.2f}) m lies outside the "
                        f"DEM [{xmin:.1f}, {xmax:.1f}] x [{ymin:.1f}, {ymax:.1f}] m; move it "
                        "inside or use a DEM covering it")


def _read_points(path, option: str) -> list[dict]:
    path = Path(path)
    if not path.is_file():
        raise InputFileError(f"{option} {path}: file not found; give an existing CSV or GeoJSON")
    try:
        if path.suffix.lower() in (".geojson", ".json"):
            data = json.loads(path.read_text())
            feats = data.get("features", []) if isinstance(data, dict) else []
            rows = []
            for k, f in enumerate(feats):
                g = f.get("geometry") or {}
                if g.get("type") != "Point":
                    raise InputFileError(f"{option} {path}: feature {k} must be a Point, got "
                                         f"{g.get('type')}")
                c = g["coordinates"]
                props = f.get("properties") or {}
                row = {"id": str(props.get("id", f"P{k + 1}")), "x_m": c[0], "y_m": c[1]}
                if "heading_deg" in props:
                    row["heading_deg"] = props["heading_deg"]
                if len(c) > 2:
                    row["z_m"] = c[2]
                rows.append(row)
        else:
            with path.open(newline="") as fh:
                rows = list(csv.DictReader(fh))
    except (json.JSONDecodeError, UnicodeDecodeError, csv.Error, KeyError, TypeError,
            AttributeError) as exc:
        raise InputFileError(f"{option} {path}: unreadable ({exc}); give a CSV with columns "
                             "id, x_m, y_m or a GeoJSON FeatureCollection of Points") from exc
    if not rows:
        raise InputFileError(f"{option} {path}: no points found")
    for c in ("id", "x_m", "y_m"):
        if c not in rows[0]:
            raise InputFileError(f"{option} {path}: missing column {c!r}; need id, x_m, y_m")
    return rows


def _float(row: dict, key: str, option: str, default=None):
    v = row.get(key)
    if v in (None, ""):
        return default
    try:
        out = float(v)
    except (TypeError, ValueError) as exc:
        raise InputFileError(f"{option}: {key} of {row.get('id')!r} is not a number: {v!r}") \
            from exc
    if not np.isfinite(out):
        raise InputFileError(f"{option}: {key} of {row.get('id')!r} must be finite, got {v!r}")
    return out


def read_stations(path, dem, lidar_height_m: float) -> tuple[list[str], np.ndarray, np.ndarray]:
    """Stations from CSV/GeoJSON -> ids, LiDAR centres (s, 3) m, headings (s,) rad.

    Raises
    ------
    InputFileError, DataError
        Unreadable file, duplicate ids, or a station outside the DEM.
    """
    rows = _read_points(path, "--stations")
    ids = [str(r["id"]).strip() for r in rows]
    if len(set(ids)) != len(ids):
        raise InputFileError(f"--stations {path}: station ids must be unique")
    xy = np.array([[_float(r, "x_m", "--stations"), _float(r, "y_m", "--stations")]
                   for r in rows])
    _check_inside(dem, xy, ids, "station")
    ground = dem.height_at(xy)
    z = np.array([_float(r, "z_m", "--stations", g + lidar_height_m)
                  for r, g in zip(rows, ground, strict=True)])
    heading = np.radians([_float(r, "heading_deg", "--stations", 0.0) for r in rows])
    return ids, np.column_stack([xy, z]), heading


def read_markers(path, dem, marker_radius_m: float, option: str = "--existing"
                 ) -> tuple[list[str], np.ndarray]:
    """Markers CSV/GeoJSON (``id, x_m, y_m[, z_m]``) -> ids and centres (m, 3) m (default
    ``z``: ground + radius). ``option`` names the argument in error messages."""
    rows = _read_points(path, option)
    ids = [str(r["id"]).strip() for r in rows]
    if len(set(ids)) != len(ids):
        raise InputFileError(f"{option} {path}: marker ids must be unique")
    xy = np.array([[_float(r, "x_m", option), _float(r, "y_m", option)]
                   for r in rows])
    _check_inside(dem, xy, ids, "marker")
    ground = dem.height_at(xy)
    z = np.array([_float(r, "z_m", option, g + marker_radius_m)
                  for r, g in zip(rows, ground, strict=True)])
    return ids, np.column_stack([xy, z])


@dataclass
class PlanOutcome:
    """A finished planning run (inputs, intermediate products, the plan and the baselines)."""

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

    @property
    def selected_ids(self) -> list[str]:
        return [self.problem.site_ids[j] for j in np.flatnonzero(self.result.selected)]


def angular_sampling():
    """The default rig's angular sampling (:mod:`visibility.sensor`) for point counts."""
    from visibility.sensor import RigConfig, SensorConfig
    from visibility.visibility_matrix import AngularSampling

    return AngularSampling(azimuth_step_rad=SensorConfig().azimuth_step_rad,
                           frames_per_turn=RigConfig().frames_per_turn)


def build_problem(inputs: PlanInputs, config, error_model, progress: bool = True
                  ) -> tuple[PlanProblem, Candidates, object, object, dict]:
    """Candidates + visibility matrix + usability -> the program's input.

    Returns ``(problem, candidates, visibility, scene, timings_s)``; existing markers are
    appended to the candidate sites (ids as given) and fixed.
    """
    from visibility.scene import RayScene
    from visibility.visibility_matrix import visibility_matrix

    timings = {}
    t = time.perf_counter()
    cand = candidate_sites(inputs.dem, config, boundary=inputs.boundary_xy,
                           exclusions=inputs.exclusions, station_xy=inputs.station_xyz,
                           craters=inputs.craters, marker_radius_m=inputs.marker_radius_m)
    timings["candidates"] = time.perf_counter() - t
    site_ids = list(cand.ids) + list(inputs.existing_ids)
    if len(set(site_ids)) != len(site_ids):
        raise InputFileError("existing marker ids clash with candidate ids (C00000...); "
                             "rename the existing markers")
    site_xyz = np.vstack([cand.centre_m, inputs.existing_xyz])
    existing = np.r_[np.zeros(len(cand), bool), np.ones(len(inputs.existing_ids), bool)]
    t = time.perf_counter()
    scene = RayScene(inputs.dem)
    timings["scene"] = time.perf_counter() - t
    vis = visibility_matrix(scene, inputs.station_xyz, site_xyz, inputs.marker_radius_m,
                            config.max_range_m, config.rays_per_marker, angular_sampling(),
                            progress=progress)
    timings["visibility"] = vis.elapsed_s
    problem = problem_from_visibility(vis, error_model, config, inputs.station_ids,
                                      inputs.station_xyz, site_ids, site_xyz,
                                      site_existing=existing)
    return problem, cand, vis, scene, timings


def make_plan(inputs: PlanInputs, config, error_model, model_name: str = "default",
              problem: PlanProblem | None = None, progress: bool = True) -> PlanOutcome:
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
    """
    timings: dict = {}
    cand = vis = scene = None
    if problem is None:
        problem, cand, vis, scene, timings = build_problem(inputs, config, error_model, progress)
    t = time.perf_counter()
    result = plan_sites(problem, config)
    timings["program"] = time.perf_counter() - t
    t = time.perf_counter()
    baselines = [greedy_cover(problem, config)]
    x0, y0, x1, y1 = _plan_bounds(inputs, problem)
    baselines.append(regular_grid(problem, config, (x0, y0, x1, y1)))
    timings["baselines"] = time.perf_counter() - t
    as_built = None
    if scene is not None and len(inputs.as_built_ids):
        from visibility.visibility_matrix import visibility_matrix

        vab = visibility_matrix(scene, inputs.station_xyz, inputs.as_built_xyz,
                                inputs.marker_radius_m, config.max_range_m,
                                config.rays_per_marker, angular_sampling(), progress=False)
        pab = problem_from_visibility(vab, error_model, config, inputs.station_ids,
                                      inputs.station_xyz, inputs.as_built_ids,
                                      inputs.as_built_xyz)
        as_built = evaluate_layout(pab, np.ones(len(inputs.as_built_ids), bool),
                                   config.replace(existing=(), forbidden=()))
    return PlanOutcome(inputs=inputs, config=config, model_name=model_name, problem=problem,
                       candidates=cand, visibility=vis, result=result, baselines=baselines,
                       as_built=as_built, timings_s=timings)


def _plan_bounds(inputs: PlanInputs, problem: PlanProblem) -> tuple[float, float, float, float]:
    if inputs.boundary_xy is not None:
        b = np.asarray(inputs.boundary_xy)
        return float(b[:, 0].min()), float(b[:, 1].min()), float(b[:, 0].max()), \
            float(b[:, 1].max())
    xy = problem.site_xyz[:, :2]
    return float(xy[:, 0].min()), float(xy[:, 1].min()), float(xy[:, 0].max()), \
        float(xy[:, 1].max())
