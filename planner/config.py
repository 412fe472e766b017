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


@dataclass(frozen=True)
class PlanConfig:
    """Everything that decides a plan besides the site and the error model.

    Attributes
    ----------
    requirement_m : float
        Required 95 % bound of a station's registered position error over its working radius, m.
    n_sectors : int
        Number of equal bearing sectors around each station (site frame), default 6 x 60 deg.
    min_sectors : int
        Least number of distinct sectors that must hold a selected usable marker.
    min_markers : int
        Least number of selected usable markers per station.
    grid_spacing_m : float
        Spacing of the candidate-site grid, m.
    max_slope_deg : float
        Candidate sites on ground steeper than this are dropped, degrees.
    min_station_distance_m : float
        Candidate sites closer than this to any station are dropped (the rover needs room), m.
    exclude_crater_interiors : bool
        Drop candidate sites inside crater rims.
    max_range_m : float
        Station-site pairs farther apart than this are not considered, m.
    min_visible_fraction : float
        A pair is usable only if at least this fraction of the marker's sensor-facing
        hemisphere is unoccluded (terrain and burial counted).
    allow_out_of_domain : bool
        Accept pairs outside the error model's fitted domain (default: they are unusable).
    working_radius_m : float
        Radius around a station over which its registered cloud must meet the requirement, m.
    inclinometer_sigma_deg : float
        1-sigma roll/pitch error of the rover's inclinometer, degrees; roll and pitch are taken
        from it, not estimated from markers.
    rays_per_marker : int
        Size of the ray bundle that samples each marker's visible hemisphere.
    redundant : bool
        Every station must still meet directions and accuracy after losing any one marker.
    budget : int or None
        Largest number of markers allowed (``None``: no budget).
    time_limit_s : float
        Wall-clock limit for the whole integer-programming loop, s.
    mip_gap : float
        Target relative gap; 0 asks for proven optimality.
    existing : tuple of str
        Ids of markers that already exist (fixed in the plan).
    forbidden : tuple of str
        Ids of candidate sites that must not be used.
    """

    requirement_m: float = 0.10
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

    def __post_init__(self) -> None:
        _plan_config_iv(self)

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

    @property
    def max_slope_rad(self) -> float:
        return math.radians(self.max_slope_deg)

    @property
    def inclinometer_sigma_rad(self) -> float:
        return math.radians(self.inclinometer_sigma_deg)


def _field_names() -> list[str]:
    return [f.name for f in dataclasses.fields(PlanConfig)]


def _reject_unknown(values: dict[str, Any], where: str) -> None:
    unknown = sorted(set(values) - set(_field_names()))
    if unknown:
        raise ConfigError(f"{where}: unknown key(s) {', '.join(unknown)}; "
                          f"known keys are {', '.join(_field_names())}")


def _plan_config_iv(c: PlanConfig) -> None:
    positive = ["requirement_m", "grid_spacing_m", "max_range_m", "working_radius_m",
                "time_limit_s"]
    for name in positive:
        v = getattr(c, name)
        if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v) \
                or v <= 0:
            raise ConfigError(f"`{name}` must be a finite number > 0, got {v!r}")
    non_negative = ["min_station_distance_m", "inclinometer_sigma_deg", "mip_gap"]
    for name in non_negative:
        v = getattr(c, name)
        if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v) or v < 0:
            raise ConfigError(f"`{name}` must be a finite number >= 0, got {v!r}")
    for name in ["n_sectors", "min_sectors", "min_markers", "rays_per_marker"]:
        v = getattr(c, name)
        if not isinstance(v, int) or isinstance(v, bool) or v < 1:
            raise ConfigError(f"`{name}` must be an integer >= 1, got {v!r}")
    if c.min_sectors > c.n_sectors:
        raise ConfigError(f"`min_sectors` must be <= `n_sectors` ({c.n_sectors}), "
                          f"got {c.min_sectors}")
    if not 0.0 < c.max_slope_deg <= 90.0:
        raise ConfigError(f"`max_slope_deg` must be in (0, 90], got {c.max_slope_deg!r}")
    if not 0.0 <= c.min_visible_fraction <= 1.0:
        raise ConfigError(f"`min_visible_fraction` must be in [0, 1], "
                          f"got {c.min_visible_fraction!r}")
    if c.budget is not None and (not isinstance(c.budget, int) or isinstance(c.budget, bool)
                                 or c.budget < 1):
        raise ConfigError(f"`budget` must be an integer >= 1 or None, got {c.budget!r}")
    for name in ["existing", "forbidden"]:
        v = getattr(c, name)
        if not isinstance(v, tuple) or not all(isinstance(s, str) for s in v):
            raise ConfigError(f"`{name}` must be a list of site ids (strings), got {v!r}")
    overlap = sorted(set(c.existing) & set(c.forbidden))
    if overlap:
        raise ConfigError(f"sites {', '.join(overlap)} are both `existing` and `forbidden`; "
                          "remove them from one list")
    for name in ["exclude_crater_interiors", "allow_out_of_domain", "redundant"]:
        if not isinstance(getattr(c, name), bool):
            raise ConfigError(f"`{name}` must be true or false, got {getattr(c, name)!r}")


def config_from_dict(values: dict[str, Any], base: PlanConfig | None = None,
                     where: str = "config") -> PlanConfig:
    """Build a :class:`PlanConfig` from a mapping, refusing unknown keys by name.

    Parameters
    ----------
    values : dict
        Field name -> value. Lists for ``existing`` / ``forbidden`` are accepted.
    base : PlanConfig, optional
        Defaults for fields not given (default: ``PlanConfig()``).
    where : str
        Name of the source, for error messages.

    Examples
    --------
    >>> config_from_dict({"requirement_m": 0.05}).requirement_m
    0.05
    """
    _reject_unknown(values, where)
    v = dict(values)
    for name in ("existing", "forbidden"):
        if name in v and isinstance(v[name], list):
            v[name] = tuple(v[name])
    try:
        return dataclasses.replace(base or PlanConfig(), **v)
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
    """
    path = Path(path)
    try:
        with path.open("rb") as fh:
            values = tomllib.load(fh)
    except FileNotFoundError as exc:
        raise InputFileError(f"--config {path}: file not found; give an existing .toml file") \
            from exc
    except tomllib.TOMLDecodeError as exc:
        raise InputFileError(f"--config {path}: not valid TOML ({exc}); fix the syntax") from exc
    return config_from_dict(values, base=base, where=f"--config {path}")
