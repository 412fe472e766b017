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
    observations; they must fix all four defects (two control points at different horizontal
    positions, or one with a heading prior).
``"free"``
    minimal constraints on the stations: their centroid and their mean rotation about the
    vertical stay at the initial values (inner constraints over the stations' x, y, z and
    heading); covariances are then relative to the stations' centroid. With a heading prior the
    rotation is observed, and only the translation is constrained.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from markerplan.errors import ConfigError, InputFileError

#: Order of a station's pose parameters (site frame; m and rad).
POSE_PARAMETERS = ("x_m", "y_m", "z_m", "heading_rad", "roll_rad", "pitch_rad")

#: The datum options of :class:`Datum`.
DATUM_KINDS = ("station", "control", "free")


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
        bad = ~(np.isfinite(self.sigma_m) & (self.sigma_m > 0))
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise InputFileError(f"`sigma_m` must be finite and > 0, got {self.sigma_m[i]} "
                                 f"({self._name(i)})")
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
        Per-axis 1-sigma of ``xyz_m``, m (> 0).
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
        if (self.sigma_m <= 0).any():
            raise ConfigError(f"control point {self.marker_id}: `sigma_m` must be > 0, got "
                              f"{self.sigma_m.tolist()}")


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
