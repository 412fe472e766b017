"""What a network adjustment is given: the stations' marker observations and the datum.

The observations are marker centres each station measured in its levelled station frame
(origin at the LiDAR centre, z up, x along the station's nominal heading), with the error
model's isotropic 1-sigma 3D centre error; their model is :mod:`pipeline.network.design`. A
station's pose is ``POSE_PARAMETERS`` in the site frame; :class:`NominalPoses` (odometry or the
plan) gives initial values and the centre of a heading prior.

Datum
-----
The observations are invariant to translating the whole network and rotating it about the
vertical (gravity, through the inclinometers, fixes the tilt): a defect of 4.

``"station"``
    the reference station's x, y, z and heading are fixed (at ``Datum.reference_pose``, else its
    nominal pose, else the origin with heading 0); its roll and pitch keep their priors.
``"control"``
    markers with known coordinates and per-axis sigmas (a lander's fiducials) are weighted
    observations; they must fix all four defects: any point fixes the translation, and the
    heading needs control points spread horizontally beyond their sigma (a heading 1-sigma of at
    most :data:`MAX_CONTROL_HEADING_SIGMA_RAD` from them alone) or a heading prior
    (:meth:`Datum.constrained_defects` refuses anything less).
``"free"``
    minimal constraints on the stations: their centroid and their mean rotation about the
    vertical stay at the initial values (inner constraints over the stations' x, y, z and
    heading); covariances are then relative to the stations' centroid. With a heading prior the
    rotation is observed, and only the translation is constrained.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass

import numpy as np

from markerplan.errors import ConfigError, InputFileError

#: Order of a station's pose parameters (site frame; m and rad).
POSE_PARAMETERS = ("x_m", "y_m", "z_m", "heading_rad", "roll_rad", "pitch_rad")

#: The datum options of :class:`Datum`.
DATUM_KINDS = ("station", "control", "free")

#: The datum defects, in the order of :meth:`Datum.constrained_defects`' indices.
DATUM_DEFECTS = ("translation x", "translation y", "translation z",
                 "heading (rotation about the vertical)")

#: Largest 1-sigma heading, rad, that control points alone may leave and still fix the heading.
#: Beyond it their horizontal spread is within their sigma (two points at one x, y, or stacked
#: vertically): the heading is unknown, and the linearised model means nothing.
MAX_CONTROL_HEADING_SIGMA_RAD = 1.0

#: Smallest 1-sigma, m or rad, of an observation or a prior (inclinometer, heading prior,
#: control point): its weight 1/sigma^2 then stays below sqrt(float max), so the normal
#: equations (sums of weights times squared lever arms) and products of weights cannot overflow.
MIN_SIGMA = sys.float_info.max ** -0.25

#: The rule :data:`MIN_SIGMA` sets, for messages.
SIGMA_RULE = f"> 0 (at least {MIN_SIGMA:.2g}: a smaller sigma's weight 1/sigma^2 overflows)"


def usable_sigma(sigma) -> np.ndarray:
    """True where ``sigma`` (any shape) is finite and at least :data:`MIN_SIGMA`.

    >>> usable_sigma([0.01, 0.0, 1e-300, np.inf]).tolist()
    [True, False, False, False]
    """
    sigma = np.asarray(sigma, dtype=float)
    return np.isfinite(sigma) & (sigma >= MIN_SIGMA)


def _ids(values, name: str) -> tuple[str, ...]:
    ids = tuple(str(v) for v in values)
    if len(set(ids)) != len(ids):
        seen: set[str] = set()
        twice = sorted({i for i in ids if i in seen or seen.add(i)})
        raise InputFileError(f"`{name}` must be unique, got {', '.join(twice)} more than once")
    return ids


@dataclass(frozen=True)
class NetworkObservations:
    """Marker centres measured by the stations of a network.

    Attributes
    ----------
    station_ids : tuple of str, (s,)
    marker_ids : tuple of str, (k,)
        Every marker must be observed at least once.
    station : (n,) int
        Index into ``station_ids`` of each observation.
    marker : (n,) int
        Index into ``marker_ids`` of each observation.
    xyz_m : (n, 3) float
        Marker centre in the observing station's levelled frame, m.
    sigma_m : (n,) float
        1-sigma 3D centre error (per-axis variance ``sigma**2 / 3``), m.

    Raises
    ------
    InputFileError
        Repeated ids, wrong shapes, indices out of range, coordinates or sigmas that are not
        finite, sigmas <= 0, or a marker id with no observation.
    """

    station_ids: tuple[str, ...]
    marker_ids: tuple[str, ...]
    station: np.ndarray
    marker: np.ndarray
    xyz_m: np.ndarray
    sigma_m: np.ndarray

    def __post_init__(self):
        set_ = object.__setattr__
        set_(self, "station_ids", _ids(self.station_ids, "station_ids"))
        set_(self, "marker_ids", _ids(self.marker_ids, "marker_ids"))
        for name, dtype in (("station", int), ("marker", int), ("xyz_m", float),
                            ("sigma_m", float)):
            try:
                set_(self, name, np.asarray(getattr(self, name), dtype=dtype))
            except (TypeError, ValueError) as exc:
                raise InputFileError(f"`{name}` must be numeric: {exc}") from None
        if self.station.ndim != 1:
            raise InputFileError(f"`station` must have shape (n,), got {self.station.shape}")
        n = self.station.shape[0]
        expected = {"station": (n,), "marker": (n,), "xyz_m": (n, 3), "sigma_m": (n,)}
        for name, shape in expected.items():
            if getattr(self, name).shape != shape:
                raise InputFileError(f"`{name}` must have shape {shape} (n observations), "
                                     f"got {getattr(self, name).shape}")
        for name, ids in (("station", self.station_ids), ("marker", self.marker_ids)):
            idx = getattr(self, name)
            if idx.size and (idx.min() < 0 or idx.max() >= len(ids)):
                raise InputFileError(f"`{name}` indices must lie in [0, {len(ids)}), got "
                                     f"{idx.min()}..{idx.max()}")
        bad = ~np.isfinite(self.xyz_m).all(axis=1)
        if bad.any():
            raise InputFileError(f"`xyz_m` must be finite, got {self.xyz_m[bad][0].tolist()} "
                                 f"({self._name(int(np.flatnonzero(bad)[0]))})")
        bad = ~usable_sigma(self.sigma_m)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise InputFileError(f"`sigma_m` must be finite and {SIGMA_RULE}, got "
                                 f"{self.sigma_m[i]} ({self._name(i)})")
        unseen = np.setdiff1d(np.arange(len(self.marker_ids)), self.marker)
        if unseen.size:
            raise InputFileError("every marker needs an observation; none of "
                                 + ", ".join(self.marker_ids[j] for j in unseen[:10]))

    def _name(self, i: int) -> str:
        return (f"station {self.station_ids[self.station[i]]}, "
                f"marker {self.marker_ids[self.marker[i]]}")

    @property
    def n(self) -> int:
        """Number of point observations."""
        return int(self.station.shape[0])

    def subset(self, keep: np.ndarray) -> NetworkObservations:
        """The observations where ``keep`` ((n,) bool) is True, with the same id tuples."""
        return NetworkObservations(self.station_ids, self.marker_ids, self.station[keep],
                                   self.marker[keep], self.xyz_m[keep], self.sigma_m[keep])


@dataclass(frozen=True)
class ControlPoint:
    """A marker with known site coordinates (e.g. a lander's fiducial).

    Attributes
    ----------
    marker_id : str
    xyz_m : (3,) float
        Site-frame coordinates, m.
    sigma_m : (3,) float
        Per-axis 1-sigma of ``xyz_m``, m (at least :data:`MIN_SIGMA`).
    """

    marker_id: str
    xyz_m: np.ndarray
    sigma_m: np.ndarray

    def __post_init__(self):
        object.__setattr__(self, "marker_id", str(self.marker_id))
        for name in ("xyz_m", "sigma_m"):
            value = np.asarray(getattr(self, name), dtype=float)
            if value.shape != (3,) or not np.isfinite(value).all():
                raise ConfigError(f"control point {self.marker_id}: `{name}` must be 3 finite "
                                  f"numbers, got {value.tolist()}")
            object.__setattr__(self, name, value)
        if not usable_sigma(self.sigma_m).all():
            raise ConfigError(f"control point {self.marker_id}: `sigma_m` must be {SIGMA_RULE}, "
                              f"got {self.sigma_m.tolist()}")


@dataclass(frozen=True)
class Datum:
    """What fixes the network's 4-DoF datum defect (see the module doc).

    Attributes
    ----------
    kind : {"station", "control", "free"}
    reference_station : str or None
        The station the network is chained from and, for ``"station"``, whose x, y, z, heading
        are fixed; None means the first station.
    control : tuple of ControlPoint
        The control points of ``"control"`` (and only there).
    reference_pose : (4,) float or None
        ``(x_m, y_m, z_m, heading_rad)`` of the reference station for ``"station"``; None
        means its nominal pose, or the origin with heading 0 without nominal poses.
    """

    kind: str = "station"
    reference_station: str | None = None
    control: tuple[ControlPoint, ...] = ()
    reference_pose: tuple[float, float, float, float] | None = None

    def __post_init__(self):
        if self.kind not in DATUM_KINDS:
            raise ConfigError(f"datum kind must be one of {', '.join(DATUM_KINDS)}, "
                              f"got {self.kind!r}")
        object.__setattr__(self, "control", tuple(self.control))
        if (self.kind == "control") != bool(self.control):
            raise ConfigError("control points are needed by, and only used with, the 'control' "
                              f"datum; got kind {self.kind!r} with {len(self.control)} points")
        _ids([c.marker_id for c in self.control], "control marker ids")
        if self.reference_pose is not None:
            pose = tuple(float(v) for v in self.reference_pose)
            if self.kind != "station" or len(pose) != 4 or not np.isfinite(pose).all():
                raise ConfigError("`reference_pose` must be 4 finite numbers (x, y, z, heading) "
                                  f"of the 'station' datum, got {self.reference_pose!r} with "
                                  f"kind {self.kind!r}")
            object.__setattr__(self, "reference_pose", pose)

    def resolve(self, station_ids) -> int:
        """Index of the reference station in ``station_ids``: ``reference_station``, else the
        first station. The one rule of the default datum, for the planner and the adjustment.

        Parameters
        ----------
        station_ids : sequence of str
            The network's (or the plan's) station ids, in order; not empty.

        Returns
        -------
        index : int

        Raises
        ------
        ConfigError
            ``reference_station`` is not one of ``station_ids``.

        Examples
        --------
        >>> Datum().resolve(("S1", "S2"))
        0
        >>> Datum(reference_station="S2").resolve(("S1", "S2"))
        1
        >>> Datum(reference_station="S9").resolve(("S1", "S2"))
        Traceback (most recent call last):
        ...
        markerplan.errors.ConfigError: `reference_station` 'S9' is not a station of the network; \
valid ids are S1, S2
        """
        ids = list(station_ids)
        reference = self.reference_station or ids[0]
        if reference not in ids:
            shown = ", ".join(ids[:20]) + (", ..." if len(ids) > 20 else "")
            raise ConfigError(f"`reference_station` {reference!r} is not a station of the "
                              f"network; valid ids are {shown}")
        return ids.index(reference)

    def reference_id(self, station_ids) -> str:
        """Id of the reference station among ``station_ids`` (:meth:`resolve`'s station).

        >>> Datum(reference_station="S2").reference_id(("S1", "S2"))
        'S2'
        """
        return station_ids[self.resolve(station_ids)]

    def control_heading_sigma_rad(self) -> float:
        """1-sigma of the heading the control points alone fix, rad (inf when they stand at one
        horizontal position): ``1 / sqrt(sum_i w_i |r_i - r_w|^2)`` over their horizontal
        positions ``r_i`` (m) with weights ``w_i = 2 / (sigma_x^2 + sigma_y^2)`` (1/m^2) about
        their weighted centroid ``r_w``.

        Examples
        --------
        >>> a = ControlPoint("A", [0.0, 0.0, 0.0], [0.01] * 3)
        >>> b = ControlPoint("B", [2.0, 0.0, 0.0], [0.01] * 3)
        >>> round(Datum("control", control=(a, b)).control_heading_sigma_rad(), 6)
        0.007071
        >>> Datum("control", control=(a, ControlPoint("B", [0.0, 0.0, 5.0], [0.01] * 3))
        ...       ).control_heading_sigma_rad()
        inf
        """
        xy = np.array([c.xyz_m[:2] for c in self.control]).reshape(-1, 2)
        weight = np.array([2.0 / np.sum(c.sigma_m[:2] ** 2) for c in self.control])
        if not weight.size:
            return math.inf
        centroid = weight @ xy / weight.sum()
        information = float(weight @ np.sum((xy - centroid) ** 2, axis=1))
        return 1.0 / math.sqrt(information) if information > 0.0 else math.inf

    def constrained_defects(self, heading_observed: bool) -> tuple[int, ...]:
        """The datum defects (indices into :data:`DATUM_DEFECTS`) that minimal constraints must
        fix; the one check that a datum fixes position and heading.

        ``"station"`` fixes all four by fixing the reference station's x, y, z and heading;
        ``"control"`` by its points, which must fix the translation and, without a heading
        prior, the heading too (see :meth:`control_heading_sigma_rad`); ``"free"`` leaves the
        translation and, without a heading prior, the heading to minimal constraints.

        Parameters
        ----------
        heading_observed : bool
            Whether a heading prior (sun sensor) observes every station's heading.

        Returns
        -------
        defects : tuple of int
            Empty for ``"station"`` and ``"control"``.

        Raises
        ------
        ConfigError
            Control points that leave the heading free (named, with their heading sigma).

        Examples
        --------
        >>> Datum("free").constrained_defects(heading_observed=False)
        (0, 1, 2, 3)
        >>> Datum("free").constrained_defects(heading_observed=True)
        (0, 1, 2)
        >>> one = Datum("control", control=(ControlPoint("A", [0, 0, 0], [0.01] * 3),))
        >>> one.constrained_defects(heading_observed=True)
        ()
        >>> one.constrained_defects(heading_observed=False)
        Traceback (most recent call last):
        ...
        markerplan.errors.ConfigError: the control points (A) leave heading (rotation about \
the vertical) free: they stand at one horizontal position within their sigma (heading \
1-sigma inf deg from them, above 57.3 deg); give control points at >= 2 horizontal positions \
farther apart than their sigma (or a heading prior)
        """
        heading_free = not heading_observed
        if self.kind == "station":
            return ()
        if self.kind == "free":
            return (0, 1, 2, 3) if heading_free else (0, 1, 2)
        heading_sigma = self.control_heading_sigma_rad()
        if heading_free and not heading_sigma <= MAX_CONTROL_HEADING_SIGMA_RAD:
            raise ConfigError(
                f"the control points ({', '.join(c.marker_id for c in self.control)}) leave "
                f"{DATUM_DEFECTS[3]} free: they stand at one horizontal position within their "
                f"sigma (heading 1-sigma {math.degrees(heading_sigma):.3g} deg from them, above "
                f"{math.degrees(MAX_CONTROL_HEADING_SIGMA_RAD):.3g} deg); give control points at "
                ">= 2 horizontal positions farther apart than their sigma (or a heading prior)")
        return ()

    def describe(self, station_ids: tuple[str, ...]) -> str:
        """One line naming the datum, for reports, e.g. ``"reference station S1 (x, y, z,
        heading fixed)"``.

        Examples
        --------
        >>> Datum().describe(("S1", "S2"))
        'reference station S1 (x, y, z, heading fixed)'
        """
        if self.kind == "station":
            return (f"reference station {self.reference_id(station_ids)} "
                    "(x, y, z, heading fixed)")
        if self.kind == "control":
            return "control points " + ", ".join(c.marker_id for c in self.control)
        return "free network (minimal constraints on the stations' centroid and mean heading)"


@dataclass(frozen=True)
class NominalPoses:
    """Nominal station poses (odometry or the plan): initial values and heading-prior centre.

    Attributes
    ----------
    position_m : (s, 3) float
        Site frame, m.
    heading_rad : (s,) float
        Rotation about the vertical from the levelled station frame to the site frame, rad.
    """

    position_m: np.ndarray
    heading_rad: np.ndarray

    def __post_init__(self):
        position = np.asarray(self.position_m, dtype=float)
        heading = np.asarray(self.heading_rad, dtype=float)
        if (position.ndim != 2 or position.shape[1] != 3 or heading.shape != position.shape[:1]
                or not (np.isfinite(position).all() and np.isfinite(heading).all())):
            raise ConfigError("nominal poses must be finite `position_m` (s, 3) and "
                              f"`heading_rad` (s,), got {position.shape} and {heading.shape}")
        object.__setattr__(self, "position_m", position)
        object.__setattr__(self, "heading_rad", heading)
