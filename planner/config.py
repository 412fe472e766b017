"""Planning configuration: one frozen dataclass, loaded from TOML with unknown keys rejected.

Degrees appear only here, at the configuration edge, with the unit in the name
(``max_slope_deg``); the planner converts them to radians where it uses them.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from markerplan.errors import ConfigError, InputFileError
from markerplan.reading import read_text
from planner.accuracy.aids import Odometry, heading_aid_sigmas_deg

#: Most stations a site may hold: a ``--stations`` file or a plan (each station ray casts every
#: candidate site).
MAX_STATIONS = 1_000
#: Most markers a layout may hold: a markers file (``--existing``, ``reduce INPUT``) or a plan.
MAX_MARKERS = 100_000
#: The 95 % figures a requirement may be judged by (:mod:`planner.accuracy.figure`).
ERROR_FIGURES = ("quantile", "ellipsoid")
#: The default figure: the ellipsoid, until the integer program has cuts as tight for the
#: quantile (with only its one-direction cut a 3-station network plan spends 90 x the solver
#: time; :mod:`planner.accuracy.figure`).
DEFAULT_ERROR_FIGURE = "ellipsoid"


@dataclass(frozen=True)
class PlanConfig:
    """Everything that decides a plan besides the site and the error model.

    Every numeric setting has documented bounds (:data:`BOUNDS`, repeated below); a value
    outside them, of the wrong type, or not finite raises :class:`ConfigError` naming the
    setting, the bounds and the value received.

    Attributes
    ----------
    requirement_m : float
        Required 95 % figure of a station's registered position error over its working radius
        (and of a network's marker), m; finite, > 0. In network mode the constant part of
        the allowance ``requirement_m + requirement_ppm * 1e-6 * d``.
    requirement_ppm : float
        Network mode: parts per million of a station's (or marker's) horizontal distance ``d``
        from the datum (the reference station) added to ``requirement_m``
        (:class:`planner.accuracy.requirement.NetworkRequirement`, e.g. 10 cm + 200 ppm);
        0 (default): a constant requirement; in [0, 1e6]. Known control has no distance datum
        and refuses a ppm term.
    error_figure : {"ellipsoid", "quantile"}
        How the 95 % figure is computed (:mod:`planner.accuracy.figure`): the semi-major axis of
        the 3-D 95 % error ellipsoid at the worst point (default; usually, not always,
        conservative), or the computed 95 % quantile of the worst error over the working disc.
    datum_requirement : bool
        Network mode: judge every station (and marker) against ``requirement_m`` (+
        ``requirement_ppm``) relative to the datum (default); false: only the local
        requirement (``local_requirement_m`` must be set).
    local_requirement_m : float or None
        Network mode: the 95 % relative error allowed between every pair of stations at most
        ``local_within_m`` apart (:mod:`planner.accuracy.local`), m; ``None``: no local
        requirement; > 0.
    local_requirement_ppm : float
        Parts per million of the pair's separation added to ``local_requirement_m``; in
        [0, 1e6].
    local_within_m : float
        Largest horizontal separation of a pair the local requirement judges, m; in
        (0, 10000].
    local_kind : {"position", "distance"}
        What the local requirement bounds: the relative position of any points of the two
        stations' working discs, or their distance (edge length).
    local_markers : bool
        Also judge every pair of selected markers at most ``local_within_m`` apart by the
        local requirement (:mod:`planner.accuracy.local_markers`; default false: stations
        only); needs ``local_requirement_m``.
    n_sectors : int
        Number of equal bearing sectors around each station (site frame), default 6 x 60 deg;
        integer in [1, 36].
    min_sectors : int
        Least number of distinct sectors that must hold a selected usable marker; integer in
        [1, n_sectors].
    min_markers : int
        Least number of selected usable markers per station; integer in [1, 100].
    grid_spacing_m : float
        Spacing of the candidate-site grid, m; in [0.1, 100].
    max_slope_deg : float
        Candidate sites on ground steeper than this are dropped, degrees; in (0, 90].
    min_station_distance_m : float
        Candidate sites closer than this to any station are dropped (the rover needs room), m;
        in [0, 100].
    exclude_crater_interiors : bool
        Drop candidate sites inside crater rims.
    max_range_m : float
        Station-site pairs farther apart than this are not considered, m; in (0, 100] (the
        LiDAR's range).
    min_visible_fraction : float
        A pair is usable only if at least this fraction of the marker's sensor-facing
        hemisphere is unoccluded (terrain and burial counted); in [0, 1].
    allow_out_of_domain : bool
        Accept pairs outside the error model's fitted domain (default: they are unusable).
    working_radius_m : float
        Radius around a station over which its registered cloud must meet the requirement, m;
        in (0, 100].
    inclinometer_sigma_deg : float
        1-sigma roll/pitch error of the rover's inclinometer, degrees; roll and pitch are taken
        from it, not estimated from markers; in [0, 10].
    rays_per_marker : int
        Size of the ray bundle that samples each marker's visible hemisphere; integer in
        [1, 1024].
    redundant : bool
        Every station must still meet directions and accuracy after losing any one marker.
    budget : int or None
        Largest number of markers allowed (``None``: no budget); integer in [1, 100000].
    time_limit_s : float
        Wall-clock limit for the whole integer-programming loop, s; in (0, 86400].
    mip_gap : float
        Target relative gap; 0 asks for proven optimality; in [0, 1].
    existing : tuple of str
        Ids of markers that already exist (fixed in the plan).
    forbidden : tuple of str
        Ids of candidate sites that must not be used.
    network : bool
        Network mode: markers are unknowns estimated with every station's pose, tied to the
        reference station (:mod:`planner.accuracy.network`); default known control.
    reference_station : str or None
        Network mode: id of the datum station (x, y, z, heading fixed); ``None``: the first.
    datum : {"station", "free"}
        Network mode: what fixes the datum. ``"station"`` (default): the reference station
        (or control points, when the site has them); ``"free"``: nothing, a free network
        whose figures are datum-free (:mod:`planner.accuracy.network`): only the local
        requirement can be judged (``datum_requirement = false``), and its ``"position"``
        kind needs a heading reference (without one a rotation of the whole network is a
        datum defect: only distances are estimable).
    heading_prior_sigma_deg : float or None
        Network mode: a heading reference on every station (a sun sensor, a star tracker), its
        random 1-sigma, degrees; ``None``: none (or the ``heading_aid`` class's); in (0, 10].
    heading_aid : str or None
        Network mode: a heading reference class (:data:`planner.accuracy.aids.HEADING_AIDS`:
        ``"sun-sensor"``, ``"star-tracker"``) that sets ``heading_prior_sigma_deg`` and
        ``heading_bias_sigma_deg`` where they are not given.
    heading_bias_sigma_deg : float or None
        Network mode: 1-sigma of the heading reference's boresight bias, common to every
        station, degrees; ``None``: 0 (or the class's); in (0, 10].
    odometry_percent : float or None
        Network mode: odometry between consecutive stations (in the stations' order), 1-sigma
        per axis of the relative position in percent of the distance driven; ``None``: no
        odometry; in (0, 100].
    odometry_heading_deg_per_m : float or None
        Network mode: 1-sigma of the odometry's relative heading, degrees per metre driven;
        ``None``: not observed; in (0, 10].
    odometry_loop_m : float or None
        Network mode with odometry: the traverse is closed, and this is the distance the rover
        drives from the last station back through the route start (the lander) to the first,
        m: one more odometry reading, of the first station from the last, with the sigmas
        above over this distance (:mod:`planner.accuracy.aids`); ``None``: an open traverse
        (default). A plan over an area of interest sets it from its route; in (0, 1e6].
    chance_epsilon : float or None
        Largest probability that the plan fails because planned markers are not detected and
        accepted (each station-marker pair with its detection model probability, independent
        outcomes); ``None``: plan as if every planned marker is detected (the naive plan);
        in (0, 0.5].
    max_bias_effect_m : float or None
        Network mode: largest shift of any station that a bias of one observation at its
        minimal detectable size may cause, m; ``None``: not bounded; in (0, 10].
    pass_rate_samples : int
        Sampled detection outcomes the plan's pass rate is estimated from after the solve
        (:func:`planner.accuracy.sampled_chance.sampled_chance`; its Wilson interval widens as
        it shrinks); 0: none. Each sample judges the whole layout, which on a network of
        hundreds of stations with a local requirement takes seconds; in [0, 100000].

    The settings below serve a plan that chooses its stations over an area of interest
    (``markerplan plan --aoi``, :mod:`planner.design`); other plans ignore them.

    aoi_cell_m : float
        Side of a cell of the area of interest, m (rounded to whole DEM cells); in [0.1, 100].
    cover_max_range_m : float
        Largest LiDAR centre to ground distance at which a cell counts as measured, m;
        in (0, 100].
    cover_max_incidence_deg : float
        Largest angle between a ray and the ground's normal at which a cell counts as
        measured, degrees (85 reaches 11.4 m on flat ground from a 1 m high LiDAR); in (0, 90].
    cover_min_density_per_m2 : float
        Smallest predicted point density of one full scan on a measured cell, points per m^2;
        in [0, 1e7].
    cover_min_stations : int
        Stations that must measure every cell (2: each cell from two stations); in [1, 10].
    cover_min_fraction : float
        Smallest fraction of the AOI's cells that must be coverable at all: cells no candidate
        station can measure (behind a rock, deep in a crater) are reported and left out of the
        requirement as long as the rest is at least this fraction; in (0, 1].
    rover_footprint_m : float
        Side of the square over which the rover judges slope and roughness (its wheel base),
        m; in (0, 100].
    rover_max_slope_deg : float
        Steepest ground the rover drives and stops on, degrees; in (0, 90).
    rover_max_roughness_m : float
        Largest RMS residual of the ground about its plane over the footprint, m; in [0, 10].
    rover_hazard_standoff_m : float
        Distance the rover keeps from any ground it cannot drive, m; in [0, 100].
    traffic_grid_m : float
        Node spacing of the trafficability map and of the drives' grid, m (whole DEM cells);
        in [0.05, 100].
    station_spacing_m : float
        Spacing of the candidate stations, m; in [0.1, 1000].
    station_time_s : float
        Mission time of one stop (set-up, the turntable scan, packing up), s; in (0, 1e6].
    marker_time_s : float
        Mission time of placing one marker, s; in (0, 1e6].
    drive_speed_m_s : float
        The rover's mean speed between stops, m/s; in (0, 100].
    """

    requirement_m: float = 0.10
    requirement_ppm: float = 0.0
    datum_requirement: bool = True
    local_requirement_m: float | None = None
    local_requirement_ppm: float = 0.0
    local_within_m: float = 50.0
    local_kind: str = "position"
    local_markers: bool = False
    n_sectors: int = 6
    min_sectors: int = 3
    min_markers: int = 3
    grid_spacing_m: float = 1.0
    max_slope_deg: float = 25.0
    min_station_distance_m: float = 1.5
    exclude_crater_interiors: bool = False
    max_range_m: float = 30.0
    min_visible_fraction: float = 0.5
    allow_out_of_domain: bool = False
    working_radius_m: float = 10.0
    inclinometer_sigma_deg: float = 0.01
    rays_per_marker: int = 24
    redundant: bool = False
    budget: int | None = None
    time_limit_s: float = 60.0
    mip_gap: float = 0.0
    existing: tuple[str, ...] = field(default_factory=tuple)
    forbidden: tuple[str, ...] = field(default_factory=tuple)
    network: bool = False
    reference_station: str | None = None
    datum: str = "station"
    heading_prior_sigma_deg: float | None = None
    heading_aid: str | None = None
    heading_bias_sigma_deg: float | None = None
    odometry_percent: float | None = None
    odometry_heading_deg_per_m: float | None = None
    odometry_loop_m: float | None = None
    chance_epsilon: float | None = 0.05
    max_bias_effect_m: float | None = None
    pass_rate_samples: int = 2000
    error_figure: str = DEFAULT_ERROR_FIGURE
    aoi_cell_m: float = 1.0
    cover_max_range_m: float = 30.0
    cover_max_incidence_deg: float = 85.0
    cover_min_density_per_m2: float = 100.0
    cover_min_stations: int = 1
    cover_min_fraction: float = 0.99
    rover_footprint_m: float = 1.5
    rover_max_slope_deg: float = 15.0
    rover_max_roughness_m: float = 0.03
    rover_hazard_standoff_m: float = 0.5
    traffic_grid_m: float = 0.5
    station_spacing_m: float = 4.0
    station_time_s: float = 300.0
    marker_time_s: float = 180.0
    drive_speed_m_s: float = 0.05

    def __post_init__(self) -> None:
        _plan_config_iv(self)
        _aids_iv(self)

    def to_dict(self) -> dict[str, Any]:
        """JSON-serialisable dict of every field (tuples as lists)."""
        d = dataclasses.asdict(self)
        d["existing"] = list(self.existing)
        d["forbidden"] = list(self.forbidden)
        return d

    def replace(self, **changes: Any) -> PlanConfig:
        """Copy with some fields changed (validated again); unknown names are refused."""
        _reject_unknown(changes, "PlanConfig.replace")
        return dataclasses.replace(self, **changes)

    def as_known_control(self, **changes: Any) -> PlanConfig:
        """This configuration in known-control mode (and ``changes``): the network-only
        requirement kinds (ppm terms, the local requirement, no datum requirement) and pose
        aids (heading reference bias, odometry) dropped."""
        return self.replace(**{"network": False, "datum": "station", "requirement_ppm": 0.0,
                               "datum_requirement": True, "local_requirement_m": None,
                               "local_requirement_ppm": 0.0, "local_markers": False,
                               "heading_aid": None,
                               "heading_bias_sigma_deg": None, "odometry_percent": None,
                               "odometry_heading_deg_per_m": None, "odometry_loop_m": None,
                               **changes})

    @property
    def max_slope_rad(self) -> float:
        return math.radians(self.max_slope_deg)

    @property
    def inclinometer_sigma_rad(self) -> float:
        return math.radians(self.inclinometer_sigma_deg)

    @property
    def heading_sigmas_deg(self) -> tuple[float | None, float]:
        """The heading reference's (random, boresight bias) 1-sigma, degrees, as used: each
        the setting's, else the ``heading_aid`` class's (random ``None``: no heading reference;
        bias 0: none)."""
        aid = heading_aid_sigmas_deg(self.heading_aid) or (None, 0.0)
        random = aid[0] if self.heading_prior_sigma_deg is None else self.heading_prior_sigma_deg
        bias = aid[1] if self.heading_bias_sigma_deg is None else self.heading_bias_sigma_deg
        return random, bias

    @property
    def heading_prior_sigma_rad(self) -> float | None:
        random = self.heading_sigmas_deg[0]
        return None if random is None else math.radians(random)

    @property
    def heading_bias_sigma_rad(self) -> float:
        return math.radians(self.heading_sigmas_deg[1])

    @property
    def odometry(self) -> Odometry:
        """The odometry between consecutive stations, and the closing reading of a closed
        traverse (:class:`planner.accuracy.aids.Odometry`; empty without one)."""
        return Odometry(
            None if self.odometry_percent is None else self.odometry_percent / 100.0,
            None if self.odometry_heading_deg_per_m is None
            else math.radians(self.odometry_heading_deg_per_m), self.odometry_loop_m)

    def aids_record(self) -> dict[str, Any]:
        """The pose aids as used (``plan.json``'s and ``reduce.json``'s ``network.datum``):
        inclinometer, heading reference (class, random and bias sigma) and odometry (with the
        closing legs' distance of a closed traverse, ``None``: open)."""
        random, bias = self.heading_sigmas_deg
        return {"inclinometer_sigma_deg": self.inclinometer_sigma_deg,
                "heading_prior_sigma_deg": random, "heading_aid": self.heading_aid,
                "heading_bias_sigma_deg": bias if random is not None else None,
                "odometry_percent": self.odometry_percent,
                "odometry_heading_deg_per_m": self.odometry_heading_deg_per_m,
                "odometry_loop_m": self.odometry_loop_m}

    @property
    def heading_observed(self) -> bool:
        """Network mode: an aid (a heading reference, or the odometry, whose relative position
        turns the previous station's heading) observes stations' headings, so a station need not
        take its heading from its own markers."""
        return self.network and (self.heading_sigmas_deg[0] is not None
                                 or self.odometry.any)


def _field_names() -> list[str]:
    return [f.name for f in dataclasses.fields(PlanConfig)]


def _reject_unknown(values: dict[str, Any], where: str) -> None:
    unknown = sorted(set(values) - set(_field_names()))
    if unknown:
        raise ConfigError(f"{where}: unknown key(s) {', '.join(unknown)}; "
                          f"known keys are {', '.join(_field_names())}")


#: Documented bounds of every numeric setting: name -> (low, low_inclusive, high, unit). Values
#: outside them are mistakes, or make the work explode (a 1e6 m range or a 1 mm grid would ray
#: cast for hours): ``max_range_m`` stops at the LiDAR's own range (visibility.sensor, 100 m),
#: ``grid_spacing_m`` at 0.1 m (finer than the DEM the markers sit on) and ``n_sectors`` at 36
#: (10 degree sectors). ``requirement_m`` has no upper bound: a loose requirement costs nothing
#: (the planner itself uses 1e9 m for "no requirement").
BOUNDS: dict[str, tuple[float, bool, float, str]] = {
    "requirement_m": (0.0, False, math.inf, " m"),
    "requirement_ppm": (0.0, True, 1e6, " ppm"),
    "local_requirement_m": (0.0, False, math.inf, " m"),
    "local_requirement_ppm": (0.0, True, 1e6, " ppm"),
    "local_within_m": (0.0, False, 10_000.0, " m"),
    "n_sectors": (1, True, 36, ""),
    "min_sectors": (1, True, 36, ""),
    "min_markers": (1, True, 100, ""),
    "grid_spacing_m": (0.1, True, 100.0, " m"),
    "max_slope_deg": (0.0, False, 90.0, " deg"),
    "min_station_distance_m": (0.0, True, 100.0, " m"),
    "max_range_m": (0.0, False, 100.0, " m"),
    "min_visible_fraction": (0.0, True, 1.0, ""),
    "working_radius_m": (0.0, False, 100.0, " m"),
    "inclinometer_sigma_deg": (0.0, True, 10.0, " deg"),
    "rays_per_marker": (1, True, 1024, ""),
    "budget": (1, True, 100_000, ""),
    "time_limit_s": (0.0, False, 86_400.0, " s"),
    "mip_gap": (0.0, True, 1.0, ""),
    "heading_prior_sigma_deg": (0.0, False, 10.0, " deg"),
    "heading_bias_sigma_deg": (0.0, False, 10.0, " deg"),
    "odometry_percent": (0.0, False, 100.0, " %"),
    "odometry_heading_deg_per_m": (0.0, False, 10.0, " deg/m"),
    "odometry_loop_m": (0.0, False, 1e6, " m"),
    "chance_epsilon": (0.0, False, 0.5, ""),
    "max_bias_effect_m": (0.0, False, 10.0, " m"),
    "pass_rate_samples": (0, True, 100_000, ""),
    "aoi_cell_m": (0.1, True, 100.0, " m"),
    "cover_max_range_m": (0.0, False, 100.0, " m"),
    "cover_max_incidence_deg": (0.0, False, 90.0, " deg"),
    "cover_min_density_per_m2": (0.0, True, 1e7, " points/m^2"),
    "cover_min_stations": (1, True, 10, ""),
    "cover_min_fraction": (0.0, False, 1.0, ""),
    "rover_footprint_m": (0.0, False, 100.0, " m"),
    "rover_max_slope_deg": (0.0, False, 89.9, " deg"),
    "rover_max_roughness_m": (0.0, True, 10.0, " m"),
    "rover_hazard_standoff_m": (0.0, True, 100.0, " m"),
    "traffic_grid_m": (0.05, True, 100.0, " m"),
    "station_spacing_m": (0.1, True, 1000.0, " m"),
    "station_time_s": (0.0, False, 1e6, " s"),
    "marker_time_s": (0.0, False, 1e6, " s"),
    "drive_speed_m_s": (0.0, False, 100.0, " m/s"),
}
_INTEGERS = ("n_sectors", "min_sectors", "min_markers", "rays_per_marker", "budget",
             "pass_rate_samples", "cover_min_stations")
_FLAGS = ("exclude_crater_interiors", "allow_out_of_domain", "redundant", "network",
          "datum_requirement", "local_markers")
#: Settings that may be ``None`` (not set).
_OPTIONAL = ("budget", "heading_prior_sigma_deg", "chance_epsilon", "max_bias_effect_m",
             "local_requirement_m", "heading_bias_sigma_deg", "odometry_percent",
             "odometry_heading_deg_per_m", "odometry_loop_m", "heading_aid")
#: What a local requirement bounds (:mod:`planner.accuracy.local`).
LOCAL_KINDS = ("position", "distance")
#: What fixes a network's datum (:mod:`planner.accuracy.network`; control points come with
#: the site's inputs, under ``"station"``).
DATUMS = ("station", "free")
#: Most ids accepted in ``existing`` / ``forbidden``.
MAX_IDS = 100_000


def _bound_text(name: str) -> str:
    lo, lo_in, hi, unit = BOUNDS[name]
    if math.isinf(hi):
        return f"{'>=' if lo_in else '>'} {lo:g}{unit}"
    return f"{'[' if lo_in else '('}{lo:g}, {hi:g}]{unit}"


def _number_iv(name: str, v: Any) -> None:
    """Refuse a setting that is not a (finite) number of the right kind within its bounds."""
    lo, lo_in, hi, _ = BOUNDS[name]
    integer = name in _INTEGERS
    kind = "an integer" if integer else "a finite number"
    ok = (isinstance(v, int) if integer else isinstance(v, int | float)) \
        and not isinstance(v, bool)
    if ok and isinstance(v, float):
        ok = math.isfinite(v)
    if ok:
        ok = (v >= lo if lo_in else v > lo) and v <= hi
    if not ok:
        raise ConfigError(f"`{name}` must be {kind} {'' if math.isinf(BOUNDS[name][2]) else 'in '}"
                          f"{_bound_text(name)}, got {v!r:.40}; "
                          "give a value within these bounds")


def _plan_config_iv(c: PlanConfig) -> None:
    """Check every field against its type and documented bounds (:data:`BOUNDS`)."""
    for name in BOUNDS:
        v = getattr(c, name)
        if name in _OPTIONAL and v is None:
            continue
        _number_iv(name, v)
    if c.min_sectors > c.n_sectors:
        raise ConfigError(f"`min_sectors` must be <= `n_sectors` ({c.n_sectors}), "
                          f"got {c.min_sectors}; lower min_sectors or raise n_sectors")
    for name in ["existing", "forbidden"]:
        v = getattr(c, name)
        if not isinstance(v, tuple) or not all(isinstance(s, str) and s for s in v):
            raise ConfigError(f"`{name}` must be a list of site ids (non-empty strings), "
                              f"got {v!r:.60}")
        if len(v) > MAX_IDS:
            raise ConfigError(f"`{name}` lists {len(v)} ids, more than the {MAX_IDS} accepted; "
                              "list only real marker sites")
    overlap = sorted(set(c.existing) & set(c.forbidden))
    if overlap:
        raise ConfigError(f"sites {', '.join(overlap)} are both `existing` and `forbidden`; "
                          "remove them from one list")
    for name in _FLAGS:
        if not isinstance(getattr(c, name), bool):
            raise ConfigError(f"`{name}` must be true or false, got {getattr(c, name)!r:.40}")
    _requirement_kinds_iv(c)
    _datum_iv(c)
    if c.error_figure not in ERROR_FIGURES:
        raise ConfigError(f"`error_figure` must be one of {', '.join(map(repr, ERROR_FIGURES))}, "
                          f"got {c.error_figure!r:.40}")
    if c.reference_station is not None and not (isinstance(c.reference_station, str)
                                                and c.reference_station):
        raise ConfigError(f"`reference_station` must be a station id (a non-empty string), "
                          f"got {c.reference_station!r:.40}")


def _aids_iv(c: PlanConfig) -> None:
    """The pose aids beyond the inclinometer need network mode; a bias needs its sensor."""
    heading_aid_sigmas_deg(c.heading_aid)  # a known class
    given = [name for name in ("heading_aid", "heading_bias_sigma_deg", "odometry_percent",
                               "odometry_heading_deg_per_m", "odometry_loop_m")
             if getattr(c, name) is not None]
    if given and not c.network:
        raise ConfigError(f"`{given[0]}` is a pose aid of network mode (known control registers "
                          "each station on its own); plan in network mode (network = true) or "
                          f"drop {given[0]}")
    if c.odometry_loop_m is not None and not c.odometry.any:
        raise ConfigError("`odometry_loop_m` is the distance of the odometry's closing reading, "
                          "and no odometry is set; set odometry_percent and/or "
                          "odometry_heading_deg_per_m, or drop odometry_loop_m")
    if c.heading_bias_sigma_deg is not None and c.heading_sigmas_deg[0] is None:
        raise ConfigError("`heading_bias_sigma_deg` is the bias of a heading reference, and none "
                          "is set; set heading_prior_sigma_deg or heading_aid, or drop "
                          "heading_bias_sigma_deg")


def _requirement_kinds_iv(c: PlanConfig) -> None:
    """The network-only requirement kinds need network mode, and a plan needs one kind."""
    if c.local_kind not in LOCAL_KINDS:
        raise ConfigError(f"`local_kind` must be one of {', '.join(map(repr, LOCAL_KINDS))}, "
                          f"got {c.local_kind!r:.40}")
    if c.requirement_ppm > 0 and not c.network:
        raise ConfigError(f"`requirement_ppm` ({c.requirement_ppm:g}) grows the requirement with "
                          "the distance from the datum, which known control does not have; plan "
                          "in network mode (network = true) or set requirement_ppm to 0")
    local = c.local_requirement_m is not None
    if not c.network and (local or not c.datum_requirement):
        raise ConfigError("a local requirement (local_requirement_m) or datum_requirement = "
                          "false is a network-mode requirement: known control judges each "
                          "station against its markers alone; plan in network mode "
                          "(network = true) or drop it")
    if c.local_markers and not local:
        raise ConfigError("`local_markers` judges marker pairs by the local requirement, which "
                          "is not set; set local_requirement_m or drop local_markers")
    if c.local_requirement_ppm > 0 and not local:
        raise ConfigError(f"`local_requirement_ppm` ({c.local_requirement_ppm:g}) is added to "
                          "local_requirement_m, which is not set; set local_requirement_m "
                          "or drop the ppm term")
    if not c.datum_requirement and not local:
        raise ConfigError("datum_requirement = false leaves no requirement: set "
                          "local_requirement_m or judge the datum requirement")


def _datum_iv(c: PlanConfig) -> None:
    """A free network fixes nothing: it needs network mode, no reference station, no
    requirement relative to the datum, and a heading reference to judge relative positions."""
    if c.datum not in DATUMS:
        raise ConfigError(f"`datum` must be one of {', '.join(map(repr, DATUMS))}, "
                          f"got {c.datum!r:.40}")
    if c.datum != "free":
        return
    if not c.network:
        raise ConfigError("`datum` = 'free' is a network-mode datum; plan in network mode "
                          "(network = true) or drop datum")
    if c.reference_station is not None:
        raise ConfigError(f"a free network fixes no station, got `reference_station` "
                          f"{c.reference_station!r:.40}; drop reference_station, or use the "
                          "station datum (datum = 'station')")
    if c.datum_requirement or c.requirement_ppm > 0:
        raise ConfigError("a free network has no datum to be accurate relative to, so "
                          "`datum_requirement` (and `requirement_ppm`) cannot be judged; set "
                          "datum_requirement = false with a local requirement "
                          "(local_requirement_m), or use the station datum (reference_station) "
                          "or control points")
    if c.local_kind == "position" and c.heading_sigmas_deg[0] is None:
        raise ConfigError("a free network without a heading reference can rotate as a whole "
                          "about the vertical (a datum defect), so relative positions "
                          "(`local_kind` = 'position') are not estimable; add a heading aid "
                          "(heading_aid or heading_prior_sigma_deg), or set local_kind = "
                          "'distance'")


def config_from_dict(values: dict[str, Any], base: PlanConfig | None = None,
                     where: str = "config") -> PlanConfig:
    """Build a :class:`PlanConfig` from a mapping, refusing unknown keys by name.

    Parameters
    ----------
    values : dict
        Field name -> value. Lists for ``existing`` / ``forbidden`` are accepted, and the
        string ``"none"`` for a setting that may be unset (``chance_epsilon = "none"``: the
        naive plan).
    base : PlanConfig, optional
        Defaults for fields not given (default: ``PlanConfig()``).
    where : str
        Name of the source, for error messages.

    Examples
    --------
    >>> config_from_dict({"requirement_m": 0.05}).requirement_m
    0.05
    """
    if not isinstance(values, dict):
        raise ConfigError(f"{where}: expected a table of settings, got {type(values).__name__}")
    _reject_unknown(values, where)
    v = dict(values)
    for name in _OPTIONAL:  # TOML has no null: "none" unsets an optional setting
        if isinstance(v.get(name), str) and v[name].strip().lower() == "none":
            v[name] = None
    for name in ("existing", "forbidden"):
        if name in v and isinstance(v[name], list):
            v[name] = tuple(v[name])
    try:
        return dataclasses.replace(base or PlanConfig(), **v)
    except ConfigError as exc:
        raise ConfigError(f"{where}: {exc}") from exc
    except TypeError as exc:  # pragma: no cover - names already checked
        raise ConfigError(f"{where}: {exc}") from exc


def load_config(path: str | Path, base: PlanConfig | None = None) -> PlanConfig:
    """Read a TOML file of :class:`PlanConfig` fields (top level, no tables).

    Parameters
    ----------
    path : str or Path
        The ``.toml`` file.
    base : PlanConfig, optional
        Defaults for keys the file does not set.

    Raises
    ------
    InputFileError
        Missing, unreadable or non-UTF-8 file, or not valid TOML.
    ConfigError
        Unknown key, a value of the wrong type, not finite or outside its bounds
        (:data:`BOUNDS`), each naming the file and the setting.
    """
    path = Path(path)
    where = f"`config_path` {path}"
    text = read_text(path, where)
    try:
        values = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputFileError(f"{where}: not valid TOML ({exc}); fix the syntax") from exc
    return config_from_dict(values, base=base, where=where)
