"""Network accuracy as surveyors state it: a constant plus parts per million of the distance
from the datum.

A network's errors grow from its datum outward, and survey standards let the allowance grow
with them: ALTA/NSPS relative positional precision is 2 cm + 50 ppm at 95 %, FGDC-STD-007.2
reports network accuracy against the distance to the datum. :class:`NetworkRequirement` is
that allowance, ``a + b * 1e-6 * d`` metres at 95 % (the configured
:class:`~planner.accuracy.figure.ErrorFigure`), with ``d`` the horizontal distance (site-frame
x, y) from the datum point: the reference station's position. A station is judged at its own
position (its whole working disc against the allowance there), a marker at its site. With
``b = 0`` (the default) it is the constant requirement of every earlier plan.

The allowance is fixed per station and per site, so every station's requirement stays the
convex ``h(J) <= allowance^2 / k`` of :mod:`planner.accuracy.network`: the tangent cuts, the
monotonicity and the no-good rows hold station by station, each with its own right-hand side.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from markerplan.errors import ConfigError

#: Parts per million.
PPM = 1e-6


@dataclass(frozen=True)
class NetworkRequirement:
    """The 95 % error a network allows a point ``d`` metres from its datum: ``a + b ppm d``.

    Parameters
    ----------
    constant_m : float
        ``a``, m (> 0).
    ppm : float
        ``b``, parts per million of the distance from the datum (>= 0).
    judged : bool
        False: no requirement relative to the datum (a plan judged by its local requirement
        alone): every allowance is infinite.

    Examples
    --------
    10 cm + 200 ppm allows 10.2 cm at 10 m and 12 cm at 100 m from the datum:

    >>> req = NetworkRequirement(0.10, 200.0)
    >>> req.allowed_m(np.array([0.0, 10.0, 100.0])).round(4).tolist()
    [0.1, 0.102, 0.12]
    >>> req.describe()
    '0.1 m + 200 ppm of the distance from the datum'
    """

    constant_m: float = 0.10
    ppm: float = 0.0
    judged: bool = True

    def __post_init__(self) -> None:
        for name, low_open in (("constant_m", True), ("ppm", False)):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and np.isfinite(v) and (v > 0 if low_open
                                                                         else v >= 0)):
                raise ConfigError(f"`{name}` must be a finite number "
                                  f"{'> 0' if low_open else '>= 0'}, got {v!r:.40}")

    @classmethod
    def of(cls, config) -> NetworkRequirement:
        """The requirement of a :class:`~planner.config.PlanConfig` (``requirement_m``,
        ``requirement_ppm``)."""
        return cls(float(config.requirement_m), float(config.requirement_ppm),
                   bool(config.datum_requirement))

    @property
    def grows(self) -> bool:
        """Whether the allowance depends on the distance (a ppm term)."""
        return self.ppm > 0

    def allowed_m(self, distance_m) -> np.ndarray:
        """Allowed 95 % error at horizontal distances ``distance_m`` (any shape, m) from the
        datum, m (same shape; ``inf`` when not ``judged``)."""
        if not self.judged:
            return np.full(np.shape(distance_m), np.inf)
        return self.constant_m + self.ppm * PPM * np.asarray(distance_m, dtype=float)

    def describe(self) -> str:
        """One line for reports and messages."""
        if not self.judged:
            return "none relative to the datum"
        if not self.grows:
            return f"{self.constant_m:g} m"
        return f"{self.constant_m:g} m + {self.ppm:g} ppm of the distance from the datum"


def datum_distances(xyz: np.ndarray, datum_xyz: np.ndarray) -> np.ndarray:
    """(k,) horizontal (site-frame x, y) distances of points ``xyz`` (k, 3) or (k, 2) from the
    datum point ``datum_xyz`` (3,) or (2,), m."""
    xyz = np.asarray(xyz, dtype=float)
    return np.linalg.norm(xyz[:, :2] - np.asarray(datum_xyz, dtype=float)[:2], axis=1)


#: How reports name a free network's datum (:meth:`planner.accuracy.network.NetworkModel.
#: datum_record`).
FREE_NETWORK = "free network (datum-free)"


def datum_text(datum: dict) -> str:
    """The datum of a plan's ``network.datum`` record in words: its ``description`` (for a free
    network its first clause), or for a record written before control datums its reference
    station.

    >>> datum_text({"reference_station": "S1"})
    'station S1'
    >>> datum_text({"kind": "free", "description": "free network (datum-free): nothing fixed"})
    'free network (datum-free)'
    """
    if datum.get("kind") == "free":
        return FREE_NETWORK
    return datum.get("description") or f"station {datum['reference_station']}"


def datum_clause(datum: dict) -> str:
    """The reports' clause naming a ``network.datum`` record and what it fixes (Markdown).

    >>> datum_clause({"kind": "station", "reference_station": "S1"})
    'station **S1** (x, y, z and heading fixed)'
    """
    if datum.get("kind", "station") == "station":
        return f"station **{datum['reference_station']}** (x, y, z and heading fixed)"
    if datum["kind"] == "free":
        return f"a **{FREE_NETWORK}**: {datum['description'].split(': ', 1)[-1]}"
    points = ", ".join(f"{c['marker_id']} (+-{c['sigma_m']:g} m)" for c in datum["control"])
    return (f"the **control points** {points}, no station fixed; distances from their centroid "
            f"({datum['datum_xyz_m'][0]:.2f}, {datum['datum_xyz_m'][1]:.2f}) m")


def requirement_text(section: dict) -> str:
    """The requirement of a plan's (or a verification's) record in words: its
    ``requirement_text``, or for a record written before it existed its constant
    ``requirement_m``.

    >>> requirement_text({"requirement_m": 0.1})
    '0.1 m'
    """
    return section.get("requirement_text", f"{section['requirement_m']:g} m")


def requirement_record(config, redundant: bool = True) -> dict:
    """The ``requirement`` section ``plan.json`` and ``reduce.json`` record of a
    :class:`~planner.config.PlanConfig`: every kind judged (the allowance relative to the datum
    and its text, the local requirement), the direction rule and the 95 % figure (and, with
    ``redundant``, the redundant rule)."""
    from planner.accuracy.figure import error_figure

    return {"requirement_m": config.requirement_m, "requirement_ppm": config.requirement_ppm,
            "requirement_text": NetworkRequirement.of(config).describe(),
            "datum_requirement": config.datum_requirement,
            "local_requirement_m": config.local_requirement_m,
            "local_requirement_ppm": config.local_requirement_ppm,
            "local_within_m": config.local_within_m, "local_kind": config.local_kind,
            "n_sectors": config.n_sectors, "min_sectors": config.min_sectors,
            "min_markers": config.min_markers, "working_radius_m": config.working_radius_m,
            **({"redundant": config.redundant} if redundant else {}),
            "error_figure": config.error_figure,
            "error_figure_text": error_figure(config).describe()}
