"""Verify a plan in network mode: simulate and process every station, identify the markers
without the simulator's truth, adjust the whole network, and compare the achieved station and
marker errors with the predicted ones.

The closed loop of ``markerplan verify --network``, in two steps:

1. :func:`scan_plan` — every chosen station is simulated at its planned pose (levelled to the
   local vertical of a curved ``body``, :mod:`planner.verify.levelling`) with only the
   planned markers (:func:`planner.verify.known_control.map_stations`: the sensor profile and the
   mis-mounted rig of known-control ``verify``) and processed by the published chain
   (:func:`pipeline.chain.process.process_station`) *without* a reference, so the marker table's
   ``marker_id`` column is empty until the association of step 2 fills it
   (:func:`~planner.verify.network_identify.identified_rows`). The truth of every station (its
   pose and the markers' true centres) is kept apart, for the comparison only, and so are the
   fates of its planned markers (:func:`planner.verify.fates.station_fates`: the stage that
   lost each, against the true centres; ``fates.csv`` names them by their true ids).
2. :func:`adjust_and_compare` — the marker table goes through the steps of ``markerplan adjust``
   (:func:`pipeline.network.run.adjust_tables`): detections weighted by the error model;
   identified by gated association with the plan's markers from each station's planned pose
   taken as rover odometry with its sigma; a network adjustment tied to the plan's
   reference station (default the first; its planned pose is the datum), data snooping on. Then,
   against the truth:

   - achieved station error: the largest 3D difference over the station and its working-radius
     rim (at its height) between the adjusted and the true mapping of the levelled station frame
     into the site frame, all six pose parameters
     (:func:`planner.accuracy.known_control.pose_difference_m`);
   - achieved marker error: the adjusted minus the true centre, its length.

   - identification: the association's id of every accepted planned marker's detection
     against its true id (:func:`~planner.verify.network_identify.misidentified`), when the
     fates are given.

   Each is set beside the plan's prediction (the station's ``predicted_error_m``; a marker's
   ``predicted_error_m`` where the plan gives one, as a network plan may) and beside the
   adjustment's own 95 % figure from its covariance (what ``adjust`` would state for these
   scans).

The plan passes when every chosen station took part in the adjustment and its achieved error
is within the requirement (markers are reported, not judged: the requirement is the stations').
Because the plan's markers are simulated at their planned centres and the stations at their
planned poses, the truth is the plan; the pipeline and the adjustment never see it. Two
consequences: the odometry error of the association only widens its gate (the rover is
exactly where it was planned to be), and the plan's pose aids are simulated from the truth with
the plan's sigmas (:mod:`planner.verify.network_aids`): a heading reference reads the true
heading plus one common boresight bias plus per-station noise, and odometry between
consecutive stations (plan order) reads their true relative pose plus noise growing with the
distance; both are seeded from verify's seed and go to the adjustment with the plan's sigmas.
A station that identifies no planned marker, or shares fewer than two identified markers with
the part of the network holding the reference, fails with that reason and is left out of the
adjustment (:func:`~planner.verify.network_identify.tied_network`); the others are still
adjusted and compared.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from markerplan.errors import ConfigError
from pipeline.chain.stages import ProcessConfig
from pipeline.network.body import Body
from pipeline.network.detections import Identified, StationDetections
from pipeline.scans.rig import MountingOffsets
from pipeline.tables.marker_table import MarkerRow
from planner.accuracy import known_control
from planner.accuracy.requirement import NetworkRequirement, datum_distances
from planner.distributed import Executor
from planner.outputs.plan_file import SurveyPlan
from planner.verify.fates import (
    StationFates,
    losses_text,
    unmatched_text,
)
from planner.verify.local_pairs import PairOutcome, marker_pair_outcomes, pair_outcomes
from planner.verify.network_identify import (
    datum_station,
    identified_rows,
    misidentified,
    tied_network,
)
from visibility.sensor_profile import SensorProfile


@dataclass(frozen=True)
class TrueStation:
    """The simulator's truth of one station, kept apart from the pipeline for the comparison.

    Attributes
    ----------
    station_id : str
    pose : (6,) float
        ``POSE_PARAMETERS`` (x, y, z, heading, roll, pitch), site frame, m and rad.
    marker_xyz_m : dict of str to (3,) float
        True centre of every simulated marker, site frame, m.
    """

    station_id: str
    pose: np.ndarray
    marker_xyz_m: dict[str, np.ndarray]

    @classmethod
    def from_truth(cls, truth: dict) -> TrueStation:
        """From a truth record (:func:`visibility.simulate.simulate_markers`' second value)."""
        p = truth["station_pose"]
        pose = np.array([*p["position_m"], p["heading_rad"], p.get("roll_rad", 0.0),
                         p.get("pitch_rad", 0.0)], dtype=float)
        return cls(truth["station_id"], pose,
                   {m["id"]: np.array(m["centre_site_m"], dtype=float) for m in truth["markers"]})


@dataclass(frozen=True)
class NetworkVerifySettings:
    """Options of the identification and the adjustment (``markerplan adjust``'s meaning).

    Attributes
    ----------
    odometry_sigma_m : float
        1-sigma error of a station's planned position as rover odometry, m (the gate).
    odometry_heading_sigma_deg : float
        1-sigma error of a station's planned heading, degrees.
    snooping : bool
        Remove blunders by data snooping (else only flag them).
    alpha0, beta0 : float
        Significance level and power of the w-test.
    body : Body
        The body whose local vertical the simulated stations level to and the adjustment
        centres its tilt priors on (``adjust --body``; :mod:`planner.verify.levelling`);
        default the plane: every station level in the site frame.
    """

    odometry_sigma_m: float = 0.5
    odometry_heading_sigma_deg: float = 2.0
    snooping: bool = True
    alpha0: float = 0.001
    beta0: float = 0.80
    body: Body = Body()

    def __post_init__(self):
        for name, high in (("odometry_sigma_m", 50.0), ("odometry_heading_sigma_deg", 90.0)):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and 0.0 < v <= high):
                raise ConfigError(f"`{name}` must be in (0, {high:g}], got {v!r:.40}")
        for name in ("alpha0", "beta0"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and 0.0 < v < 1.0):
                raise ConfigError(f"`{name}` must be in (0, 1), got {v!r:.40}")
        if not isinstance(self.body, Body):
            raise ConfigError(f"`body` must be a Body (Body.named('moon'|'earth'|'plane')), got "
                              f"{self.body!r:.40}")

    def record(self) -> dict:
        """The settings for the outputs; the body only when it is not the plane (the record of
        earlier versions, which had none)."""
        rec = dataclasses.asdict(self)
        body = rec.pop("body")
        return rec if self.body.radius_m is None else {**rec, "body": body}


@dataclass
class StationOutcome:
    """Predicted against achieved for one station (errors in m; ``None`` where there is none)."""

    station_id: str
    predicted_error_m: float | None
    stated_error_m: float | None
    """The adjustment's 95 % station error from its covariance."""
    achieved_error_m: float | None
    n_accepted: int
    """Accepted detections in the station's marker table."""
    n_identified: int
    """Detections the association gave a planned marker's id."""
    n_used: int
    """Observations the adjustment kept (after data snooping)."""
    passed: bool
    reason: str


@dataclass
class MarkerOutcome:
    """Predicted against achieved for one marker (errors in m)."""

    marker_id: str
    predicted_error_m: float | None
    stated_error_m: float
    """Largest semi-axis of the adjustment's 95 % error ellipsoid."""
    achieved_error_m: float
    """Length of the adjusted minus the true centre."""
    achieved_xyz_m: tuple[float, float, float]
    """Adjusted minus true centre per axis, site frame."""
    stations: tuple[str, ...]


@dataclass
class NetworkVerification:
    """Result of :func:`adjust_and_compare`."""

    stations: list[StationOutcome]
    markers: list[MarkerOutcome]
    reference_station: str
    config: dict
    """The resolved configuration of the identification and adjustment (``adjust``'s)."""
    rejected: list[dict] = field(default_factory=list)
    """Observations removed by data snooping: station, marker (the association's id), w."""
    unidentified: int = 0
    """Accepted detections the association left without an id."""
    sigma0_squared: float | None = None
    dof: int = 0
    fates: dict[str, StationFates] | None = None
    """Per station, its planned markers' fates (the simulator's truth), when known."""
    misidentified: list[dict] = field(default_factory=list)
    """Accepted planned markers of adjusted stations whose detection the association named
    otherwise: station, true marker id, ``identified_as`` (``None``: left unidentified)."""
    detection_ids: dict[str, tuple[str | None, ...]] = field(default_factory=dict)
    """Per station the association reached, the id it gave each accepted detection (in the
    table's order; ``None``: left unidentified), whether or not the station was adjusted."""
    requirement: NetworkRequirement = field(default_factory=NetworkRequirement)
    """The plan's requirement (constant, or growing with the distance from the datum)."""
    allowed_m: dict[str, float] = field(default_factory=dict)
    """Per verified station, the error its requirement allows at its distance from the
    datum, m."""
    local: dict | None = None
    """The plan's ``local`` section (its local requirement), if it has one."""
    pairs: list[PairOutcome] = field(default_factory=list)
    """With a local requirement: each judged station pair, predicted against achieved."""
    marker_pairs: list[PairOutcome] = field(default_factory=list)
    """With ``local_markers``: each judged marker pair, predicted against achieved."""

    @property
    def passed(self) -> bool:
        return all(s.passed for s in self.stations) \
            and all(p.passed for p in self.pairs + self.marker_pairs)


#: :func:`scan_plan`'s result: the marker-table rows, the truth and the fates of one scan.
Scanned = tuple[list[MarkerRow], dict[str, TrueStation], dict[str, StationFates]]


def scan_plan(plan: SurveyPlan, seed: int = 0, progress: bool = True,
              offsets: MountingOffsets | None = None, station_ids: list[str] | None = None,
              profile: SensorProfile | None = None, executor: Executor | None = None,
              body: Body = Body(), reference: str | None = None) -> Scanned:  # noqa: B008
    """Simulate and process the chosen stations of a plan (step 1 of the module docstring).

    Parameters are those of :func:`planner.verify.known_control.verify_plan`, and ``body``,
    ``reference`` those of :func:`scan_plans`.

    Returns
    -------
    rows : list of MarkerRow
        Every candidate of every station (accepted or not), ``marker_id`` empty, in the plan's
        station order: a ``markers.csv`` as ``markerplan process`` writes it.
    truth : dict of str to TrueStation
        Per station id.
    fates : dict of str to StationFates
        Per station id, its planned markers' fates (``candidate``: the row among the
        station's ``rows``).
    """
    return scan_plans(plan, [seed], progress, offsets, station_ids, profile, executor,
                      body=body, reference=reference)[0]


def scan_plans(plan: SurveyPlan, seeds: list[int], progress: bool = True,
               offsets: MountingOffsets | list[MountingOffsets] | None = None,
               station_ids: list[str] | None = None, profile: SensorProfile | None = None,
               executor: Executor | None = None, names: list[str] | None = None,
               body: Body = Body(), reference: str | None = None  # noqa: B008 (frozen)
               ) -> list[Scanned]:
    """:func:`scan_plan` once per seed (the trials of ``verify --network --trials N``), every
    scan x station one task of one map
    (:func:`planner.verify.known_control.map_plan_stations`).

    Parameters
    ----------
    plan : SurveyPlan
    seeds : list of int
        One simulation seed per scan.
    offsets : MountingOffsets or list of MountingOffsets, optional
        The rig's true mounting offsets, for all scans or one per scan.
    progress, station_ids, profile, executor
        As :func:`planner.verify.known_control.verify_plan`.
    names : list of str, optional
        A name per scan for the task errors (``trial 3``).
    body : Body
        The stations level to its local vertical (:mod:`planner.verify.levelling`).
    reference : str, optional
        The datum station, the tangent point of its vertical (default the plan's).

    Returns
    -------
    scans : list of Scanned
        Per seed, :func:`scan_plan`'s three values.
    """
    from pipeline.surveys.survey import ProcessingSettings, processing_config
    from planner.verify.known_control import map_plan_stations
    from planner.verify.levelling import levelled_tilts

    cfg = processing_config(ProcessingSettings(marker_radius_m=plan.marker_radius_m))
    done = map_plan_stations([plan] * len(seeds),
                             [functools.partial(station_rows, cfg, s) for s in seeds], seeds,
                             progress, offsets, station_ids, profile, executor, names,
                             levelled_tilts(plan, body, reference, station_ids))
    return [([r for station, _, _ in scan for r in station],
             {true.station_id: true for _, true, _ in scan},
             {true.station_id: fates for _, true, fates in scan}) for scan in done]


def station_rows(cfg: ProcessConfig, seed: int, st, scan, truth: dict
                 ) -> tuple[list[MarkerRow], TrueStation, StationFates]:
    """One simulated station's marker-table rows (no reference: identification comes later),
    its truth and its planned markers' fates; ``cfg``
    (:func:`pipeline.surveys.survey.processing_config`) and ``seed`` are the pipeline's (a
    :func:`planner.verify.known_control.station_task` ``process``)."""
    from pipeline.chain.process import process_station
    from planner.verify.fates import station_fates

    result = process_station(scan, cfg, None, seed=seed)
    return (result.rows, TrueStation.from_truth(truth),
            station_fates(result, truth, st.marker_ids, cfg))


def adjust_and_compare(tables: list[Path], plan_path: Path, error_model,
                       truth: dict[str, TrueStation], predicted_station: dict[str, float | None],
                       predicted_marker: dict[str, float | None] | None = None,
                       settings: NetworkVerifySettings = NetworkVerifySettings(),
                       error_model_name: str = "",
                       planned_markers: dict[str, tuple[str, ...]] | None = None,
                       reference: str | None = None,
                       fates: dict[str, StationFates] | None = None,
                       seed: int = 0) -> NetworkVerification:
    """Identify, adjust and compare (step 2 of the module docstring): a station passes when
    its identified markers meet the plan's rule (:mod:`planner.verify.station_rule`) and its
    achieved error the requirement.

    Parameters
    ----------
    tables : list of Path
        ``markers.csv`` of the stations (:func:`scan_plan`'s rows, written).
    plan_path : Path
        The ``plan.json``: planned markers and poses (association, initial values, datum), its
        reference station, inclinometer, heading prior, working radius and requirement.
    error_model : error_model.model.ErrorModel
        Weights of the detections.
    truth : dict of str to TrueStation
        The stations to judge (their ids); the truth is used only for the comparison.
    predicted_station, predicted_marker : dict of str to (float or None)
        The plan's predicted 95 % errors, m (markers: where the plan has them).
    settings : NetworkVerifySettings
    error_model_name : str
        Recorded in the configuration.
    planned_markers : dict of str to tuple of str, optional
        The markers the plan gives each station: those the association did not identify are
        named in its ``reason``.
    reference : str, optional
        The datum station (``verify --reference-station``); default the plan's.
    fates : dict of str to StationFates, optional
        :func:`scan_plan`'s: each station's reason names its losses, and the association's
        ids are checked against the true ones (:func:`~planner.verify.network_identify.
        misidentified`).
    seed : int
        Seed of the pose aids' readings (:mod:`planner.verify.network_aids`).

    Returns
    -------
    NetworkVerification

    Raises
    ------
    ConfigError
        The reference station is not among the stations in ``truth``.
    InputFileError
        As ``markerplan adjust``: no accepted detection, stations the association cannot tie
        to the network (named), a plan that is not one.
    """
    from pipeline.network.adjustment import AdjustmentSettings
    from pipeline.network.run import adjust_tables
    from planner.network.plan_geometry import (
        body_configuration,
        plan_geometry,
        resolved_configuration,
    )
    from planner.network.record import station_errors
    from planner.outputs.plan_file import read_plan
    from planner.verify.network_aids import plan_aids
    from planner.verify.network_datum import free_alignment, verify_datum
    from planner.verify.station_rule import StationRule

    doc = read_plan(plan_path, "`plan_path`", full=True)
    plan, rule = plan_geometry(doc, plan_path), StationRule.of(doc["requirement"])
    datum = verify_datum(doc, plan, reference, list(truth), seed)
    reference = datum.reference
    config = resolved_configuration(
        tables=[str(t) for t in tables], plan=str(plan_path), control=None,
        error_model=error_model_name, marker_ids="plan", datum=datum.kind,
        reference_station=reference,
        odometry_sigma_m=settings.odometry_sigma_m,
        odometry_heading_sigma_deg=settings.odometry_heading_sigma_deg,
        heading_prior_sigma_deg=None, inclinometer_sigma_deg=None, working_radius_m=None,
        requirement_m=None, error_figure=None, snooping=settings.snooping, alpha0=settings.alpha0,
        beta0=settings.beta0, plan_geometry=plan)
    # the scan simulator levels every station to settings.body's vertical (scan_plans)
    config["body"] = body_configuration(settings.body, reference)
    aids = plan_aids(doc, plan_path, config["heading_prior_sigma_deg"])
    config.update(aids.record(), aids_seed=int(seed))
    if datum.control:
        config["control_points"] = datum.record()["control"]
    adjustment = AdjustmentSettings(
        body=settings.body,
        inclinometer_sigma_rad=math.radians(config["inclinometer_sigma_deg"]), **aids.settings(),
        alpha0=settings.alpha0, beta0=settings.beta0, snooping=settings.snooping)
    verified = [sid for sid in plan.station_ids if sid in truth]
    left_out: dict[str, str] = {}
    detection_ids: dict[str, tuple[str | None, ...]] = {}

    def identify(stations: list[StationDetections]) -> Identified:
        identified, out, ids = tied_network(stations, plan, reference, settings)
        left_out.update(out)
        detection_ids.update(ids)
        return identified

    adjusted = adjust_tables(tables, error_model, functools.partial(datum_station, reference),
                             identify, adjustment, datum_kind=datum.kind,
                             control=datum.control, plan=plan,
                             aids=aids.readings(verified, np.stack(
                                 [truth[sid].pose for sid in verified]), seed))
    stations, identified, result = adjusted.stations, adjusted.identified, adjusted.result
    if datum.kind == "free":  # compared with the truth datum-free
        result = free_alignment(result, np.stack([truth[sid].pose for sid in
                                                  result.observations.station_ids]),
                                adjustment.heading_prior_sigma_rad is not None)
    radius = config["working_radius_m"]
    need = NetworkRequirement(config["requirement_m"],
                              float(doc["requirement"].get("requirement_ppm", 0.0)),
                              bool(doc["requirement"].get("datum_requirement", True)))
    allowed = {sid: float(need.allowed_m(datum_distances(
        plan.station_xyz_m[[plan.station_ids.index(sid)]], datum.datum_xyz)[0]))
        for sid in truth}

    kept = result.observations
    s_ids = kept.station_ids
    stated = station_errors(np.stack([result.station_covariance(i) for i in range(len(s_ids))]),
                            result.pose[:, 3], radius, config["error_figure"])
    accepted = {s.station_id: len(s.xyz_m) for s in stations}
    named = {s.station_id: {i for i in ids if i is not None}
             for s, ids in zip(identified.stations, identified.ids, strict=True)}
    named_count = {**{sid: sum(i is not None for i in ids)
                      for sid, ids in detection_ids.items()},
                   **{sid: len(ids) for sid, ids in named.items()}}
    outcomes = []
    for sid in truth:
        pred = predicted_station.get(sid)
        if sid not in s_ids:
            why = left_out.get(sid, "no accepted detection")
            lost = losses_text(fates[sid].rows) if fates and sid in fates else ""
            outcomes.append(StationOutcome(sid, pred, None, None, accepted.get(sid, 0),
                                           named_count.get(sid, 0), 0, False,
                                           f"not in the adjustment: {why}"
                                           + (f"; {lost}" if lost else "")))
            continue
        i = s_ids.index(sid)
        achieved = known_control.pose_difference_m(result.pose[i], truth[sid].pose, radius)
        ok, reason = rule.verdict(
            plan.station_xyz_m[plan.station_ids.index(sid)],
            plan.marker_xyz_m[[plan.marker_ids.index(m) for m in sorted(named[sid])
                               if m in plan.marker_ids]], achieved, allowed[sid])
        missing = sorted(set((planned_markers or {}).get(sid, ())) - named[sid])
        if missing and fates and sid in fates:
            reason += f" ({unmatched_text(fates[sid], named[sid], 'identified')})"
        elif missing:
            reason += f" (planned markers not identified: {', '.join(missing)})"
        outcomes.append(StationOutcome(sid, pred, float(stated[i]), achieved, accepted[sid],
                                       len(named[sid]), int(np.sum(kept.station == i)), ok,
                                       reason))

    pairs = [] if "local" not in doc else pair_outcomes(
        doc["local"], dict(zip(plan.station_ids, plan.station_xyz_m, strict=True)),
        {sid: result.pose[i] for i, sid in enumerate(s_ids)},
        {sid: t.pose for sid, t in truth.items()}, radius)
    markers = _marker_outcomes(result, plan.marker_ids, truth, predicted_marker or {})
    marker_pairs = marker_pair_outcomes(
        doc.get("local"), dict(zip(plan.marker_ids, plan.marker_xyz_m, strict=True)), markers)
    rejected = [{"station_id": r.station_id, "marker_id": r.marker_id, "w": float(r.w)}
                for r in result.rejected]
    sigma0 = None if not np.isfinite(result.sigma0_squared) else float(result.sigma0_squared)
    wrong = misidentified(tables, identified, fates) if fates else []
    return NetworkVerification(outcomes, markers, reference, config, rejected,
                               len(identified.unidentified), sigma0, int(result.dof), fates,
                               wrong, detection_ids, need, allowed, doc.get("local"), pairs,
                               marker_pairs)


def verify_scan(scanned: Scanned, table: Path, plan_path: Path, doc: dict, error_model,
                error_model_name: str, settings: NetworkVerifySettings,
                reference: str | None = None, seed: int = 0) -> NetworkVerification:
    """Step 2 of the module docstring for one scan of a plan: its marker table written to
    ``table`` (``marker_id`` filled by the association, :func:`identified_rows`), identified,
    adjusted and compared with the plan's predictions.

    Parameters
    ----------
    scanned : Scanned
        :func:`scan_plan`'s rows, truth and fates.
    table : Path
        The ``markers.csv`` to write.
    plan_path : Path
    doc : dict
        The ``plan.json`` (:func:`planner.outputs.plan_file.read_plan`, full): the stations'
        and markers' predicted errors and each station's planned markers.
    error_model, error_model_name, settings, reference, seed
        As :func:`adjust_and_compare` (``seed``: the scan's).

    Returns
    -------
    NetworkVerification
    """
    from pipeline.tables.marker_table import write_marker_table

    rows, truth, fates = scanned
    write_marker_table(table, rows)
    check = adjust_and_compare(
        [table], plan_path, error_model, truth,
        {s["id"]: s.get("predicted_error_m") for s in doc["stations"]},
        {m["id"]: m.get("predicted_error_m") for m in doc["markers"]}, settings,
        error_model_name, {s["id"]: tuple(s.get("markers", ())) for s in doc["stations"]},
        reference=reference, fates=fates, seed=seed)
    write_marker_table(table, identified_rows(rows, check))
    return check


def _marker_outcomes(result, plan_marker_ids: tuple[str, ...], truth: dict[str, TrueStation],
                     predicted: dict[str, float | None]) -> list[MarkerOutcome]:
    """Every adjusted marker against its true centre and its prediction, in the plan's order."""
    from planner.network.record import ellipsoid_axes

    kept = result.observations
    true_centres = {m: c for t in truth.values() for m, c in t.marker_xyz_m.items()}
    axes = ellipsoid_axes(np.stack([result.marker_covariance(j)
                                    for j in range(len(kept.marker_ids))]))
    out = []
    for j in sorted(range(len(kept.marker_ids)),
                    key=lambda j: plan_marker_ids.index(kept.marker_ids[j])):
        mid = kept.marker_ids[j]
        diff = result.marker_xyz_m[j] - true_centres[mid]
        seen = tuple(kept.station_ids[i] for i in np.unique(kept.station[kept.marker == j]))
        out.append(MarkerOutcome(mid, predicted.get(mid), float(axes[j, 0]),
                                 float(np.linalg.norm(diff)), tuple(float(v) for v in diff),
                                 seen))
    return out
