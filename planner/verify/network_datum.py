"""The datum of a network verification (:func:`verify_datum`): the plan's reference station,
the lander's control points, whose coordinates the simulated survey knows only to their
sigma, or none (a free network, whose adjusted solution :func:`free_alignment` compares with
the truth datum-free)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from markerplan.errors import ConfigError
from pipeline.network.observations import ControlPoint, Datum

#: Mixed into verify's seed for the control points' coordinate errors (one stream of its own).
CONTROL_STREAM = 0xC0


@dataclass(frozen=True)
class VerifyDatum:
    """What ties a verified network to the site frame.

    Attributes
    ----------
    kind : {"station", "control", "free"}
        The plan's datum (``plan.json``'s ``network.datum.kind``).
    reference : str
        The datum station; with control points, the station the network is chained from (the
        first verified station the plan gives a control point); in a free network the first
        verified station (chaining only).
    control : tuple of ControlPoint
        The control points as the survey knows them: the simulated (true) centre plus one draw
        of their stated error, with their sigmas; empty for a station datum.
    datum_xyz : (3,) float
        Where the requirement's distances are measured from, site frame, m.
    """

    kind: str
    reference: str
    control: tuple[ControlPoint, ...]
    datum_xyz: np.ndarray

    def record(self) -> dict:
        """The verification configuration's ``datum`` entry: kind, reference and the control
        coordinates the adjustment was given (m)."""
        return {"kind": self.kind, "reference_station": self.reference,
                "control": [{"marker_id": c.marker_id, "xyz_m": c.xyz_m.tolist(),
                             "sigma_m": float(c.sigma_m[0])} for c in self.control]}


def verify_datum(doc: dict, plan, named: str | None, chosen, seed: int) -> VerifyDatum:
    """The datum of a network verification of the plan ``doc``.

    Parameters
    ----------
    doc : dict
        The ``plan.json`` (full).
    plan : pipeline.network.detections.PlanGeometry
        Its geometry (station ids and positions).
    named : str or None
        ``--reference-station`` (refused for a plan on control points), else the plan's.
    chosen : sequence of str
        The stations verified.
    seed : int
        Verify's seed: the control points' coordinate errors are drawn from it.

    Returns
    -------
    VerifyDatum

    Raises
    ------
    ConfigError
        A reference station named for a plan on control points or a free network, no verified
        station the plan
        gives a control point, or (station datum) the reference not verified
        (:func:`reference_station`).
    """
    datum = (doc.get("network") or {}).get("datum") or {}
    if datum.get("kind") == "free":
        if named is not None:
            raise ConfigError(f"`reference_station` {named}: the plan is a free network (no "
                              "station is fixed); drop `reference_station`")
        first = next(sid for sid in plan.station_ids if sid in chosen)
        return VerifyDatum("free", first, (), np.asarray(datum["datum_xyz_m"], float))
    if datum.get("kind", "station") != "control":
        ref = reference_station(named or plan.reference_station, plan.station_ids, chosen)
        return VerifyDatum("station", ref, (),
                           np.asarray(plan.station_xyz_m[plan.station_ids.index(ref)], float))
    if named is not None:
        raise ConfigError(f"`reference_station` {named}: the plan's datum is its control points "
                          "(no station is fixed); drop `reference_station`")
    ids = {c["marker_id"] for c in datum["control"]}
    seeing = [s["id"] for s in doc["stations"]
              if s["id"] in chosen and ids & set(s.get("markers", ()))]
    if not seeing:
        raise ConfigError("none of the stations verified is planned to see a control point "
                          f"({', '.join(sorted(ids))}), so the network has no datum; verify "
                          "the stations that see them too")
    rng = np.random.default_rng([int(seed), CONTROL_STREAM])
    control = tuple(ControlPoint(c["marker_id"],
                                 np.asarray(c["xyz_m"], float) + rng.normal(0.0, c["sigma_m"], 3),
                                 np.full(3, float(c["sigma_m"]))) for c in datum["control"])
    return VerifyDatum("control", seeing[0], control, np.asarray(datum["datum_xyz_m"], float))


def reference_station(named: str | None, plan_stations, chosen) -> str:
    """The datum station of a network verification: the one named, else the plan's first
    (:meth:`pipeline.network.observations.Datum.resolve`).

    Parameters
    ----------
    named : str or None
        The reference station asked for, or the plan's ``reference_station`` (its
        configuration's), if any.
    plan_stations : sequence of str
        The plan's station ids, in order.
    chosen : sequence of str
        The stations to verify (``station_ids``).

    Raises
    ------
    ConfigError
        ``named`` is not a station of the plan, or the reference is not among ``chosen``.

    Examples
    --------
    >>> reference_station(None, ["S1", "S2"], ["S1", "S2"])
    'S1'
    >>> reference_station("S2", ["S1", "S2"], ["S1"])  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    markerplan.errors.ConfigError: the plan's reference station S2 ... in `station_ids`
    """
    reference = Datum(reference_station=named).reference_id(plan_stations)
    if reference not in chosen:
        raise ConfigError(f"the plan's reference station {reference} (the datum of network "
                          f"mode) is not among the stations verified ({', '.join(chosen)}); "
                          "include it in `station_ids`")
    return reference


def free_alignment(result, true_pose: np.ndarray, heading_observed: bool):
    """A free network's adjusted solution with its datum motion against the truth removed.

    The free datum holds the stations' centroid (and mean heading) at their initial values, not
    the truth's, so the adjusted network differs from the truth by a rigid motion besides its
    errors. The pose errors ``d`` (adjusted minus true; heading wrapped) are S-transformed to the
    adjustment's own inner constraints, ``d - G (B G)^-1 B d`` (``G`` the defect directions at
    the true stations, ``B`` = ``G^T`` on their x, y, z and heading:
    :func:`pipeline.network.normals.inner_constraints`), the error the predicted datum-free
    covariance describes; the markers are moved back by the same rigid motion.

    Parameters
    ----------
    result : pipeline.network.adjustment.NetworkAdjustment
        A ``"free"`` datum adjustment.
    true_pose : (s, 6) float
        The true poses of its stations, in its order, m and rad.
    heading_observed : bool
        A heading prior observes the headings (only the translation is a defect).

    Returns
    -------
    NetworkAdjustment
        ``result`` with ``pose`` and ``marker_xyz_m`` aligned.
    """
    import dataclasses

    from pipeline.network.normals import inner_constraints

    pose = np.asarray(result.pose, float)
    true_pose = np.asarray(true_pose, float)
    s = pose.shape[0]
    defects = list(Datum("free").constrained_defects(heading_observed))
    g, b = inner_constraints(true_pose, np.zeros((0, 3)), defects)
    d = pose - true_pose
    d[:, 3] = (d[:, 3] + np.pi) % (2 * np.pi) - np.pi
    alpha = np.zeros(4)
    alpha[defects] = np.linalg.solve(b @ g, b @ d.ravel())
    # the markers: the inverse of the same motion (translation, then rotation by alpha[3]
    # about the stations' centroid)
    centre = true_pose[:, :2].mean(axis=0)
    c, s_ = math.cos(alpha[3]), math.sin(alpha[3])
    markers = np.asarray(result.marker_xyz_m, float).reshape(-1, 3) - alpha[:3]
    xy = markers[:, :2] - centre
    markers[:, :2] = centre + xy @ np.array([[c, -s_], [s_, c]])
    return dataclasses.replace(result, pose=pose - (g @ alpha[defects]).reshape(s, 6),
                               marker_xyz_m=markers)
