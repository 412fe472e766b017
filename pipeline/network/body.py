"""The body the survey stands on: the curvature of the local vertical across a site.

An inclinometer levels a station to *local gravity*. The site frame is a plane: its z axis is
the vertical at one point, the tangent point. On a sphere of radius ``R`` whose surface touches
the site frame's ``z = 0`` plane at the tangent point ``(x0, y0)`` (centre at
``(x0, y0, -R)``), the local vertical at the site-frame position ``(x, y, z)`` is the unit
vector

    u = (x - x0, y - y0, z + R) / |(x - x0, y - y0, z + R)|

which leans *away from* the tangent point by ``atan(d / (R + z)) ~ d / R`` (``d`` the
horizontal distance): 0.0126 deg at 381 m on the Moon, 1.26 sigma of a 0.01 deg inclinometer.
A station levelled there has the levelled-station-to-site rotation
``Rz(heading) Ry(pitch) Rx(roll)`` (:func:`pipeline.scans.rig.station_to_site_matrix`) whose third
column is ``u``. With ``v = Rz(-heading) u``, that is

    roll = -asin(v_y),   pitch = atan2(v_x, v_z)

— about ``pitch ~ d_forward / R``, ``roll ~ -d_left / R`` with ``d_forward``, ``d_left`` the
station's offset from the tangent point along and across its heading. This deflection is what
the network adjustment centres its roll and pitch priors on
(:mod:`pipeline.network.adjustment`) and what the network simulator levels its stations to
(:mod:`pipeline.network.simulation`). A plane (``radius_m`` None) has no deflection: today's
model, for sites whose body or frame is unknown.

A prior's centre does not change a covariance, so the planner's predicted accuracy
(:mod:`planner.accuracy.network`) does not depend on the body.

Ignored: the ellipsoid's flattening (the Moon's is 0.0012, Earth's 1/298: a change of the
deflection by that fraction), the deflection of the vertical by mass anomalies, and the
site frame being a map projection rather than the tangent plane (its scale error, a few ppm
over a site).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from markerplan.errors import ConfigError
from pipeline.scans.rig import rot_z

#: Mean radii of the named bodies, m (the Moon: IAU/IAG 2015 mean radius 1737.4 km; Earth: the
#: IUGG mean radius R1 6371.0 km). ``plane`` has none.
BODY_RADIUS_M = {"moon": 1_737_400.0, "earth": 6_371_000.0, "plane": None}


@dataclass(frozen=True)
class Body:
    """A sphere of radius ``radius_m`` (m), or the plane (``radius_m`` None).

    Attributes
    ----------
    name : str
        ``"moon"``, ``"earth"``, ``"plane"`` or, for any other radius, ``"sphere"``.
    radius_m : float or None
        Radius of the sphere, m (> 0); None for the plane.

    Examples
    --------
    >>> Body.named("moon")
    Body(name='moon', radius_m=1737400.0)
    >>> Body.named("mars")
    Traceback (most recent call last):
    ...
    markerplan.errors.ConfigError: `body` must be one of moon, earth, plane, got 'mars'
    """

    name: str = "plane"
    radius_m: float | None = None

    def __post_init__(self):
        r = self.radius_m
        if r is None:
            if self.name != "plane":
                raise ConfigError(f"body {self.name!r} needs a radius_m > 0; give "
                                  "Body.named('moon'|'earth'|'plane') or Body('sphere', R)")
            return
        if isinstance(r, bool) or not isinstance(r, int | float) or not (
                math.isfinite(r) and r > 0):
            raise ConfigError(f"`radius_m` of the body must be a finite number > 0 (m), got "
                              f"{r!r:.40}; give body moon, earth or plane")
        known = BODY_RADIUS_M.get(self.name, False)
        if self.name not in ("sphere", *BODY_RADIUS_M) or (known is not False and known != r):
            raise ConfigError(f"body {self.name!r} with radius {r!r} m: a radius of your own is "
                              "Body('sphere', R), the named ones are Body.named(name)")

    @classmethod
    def named(cls, name: str) -> Body:
        """The body called ``name`` (``moon``, ``earth`` or ``plane``)."""
        if name not in BODY_RADIUS_M:
            raise ConfigError(f"`body` must be one of {', '.join(BODY_RADIUS_M)}, got {name!r}")
        return cls(name, BODY_RADIUS_M[name])

    def to_dict(self) -> dict:
        """``{"name": ..., "radius_m": ...}`` for the outputs (radius None for the plane)."""
        return {"name": self.name, "radius_m": self.radius_m}

    def vertical_tilt(self, position_m: np.ndarray, heading_rad: np.ndarray,
                      tangent_point_m=(0.0, 0.0)) -> np.ndarray:
        """Roll and pitch of stations levelled to the local vertical (module doc).

        Parameters
        ----------
        position_m : (n, 3) float
            Station positions, site frame, m.
        heading_rad : (n,) float
            Station headings (``POSE_PARAMETERS``' heading), rad.
        tangent_point_m : (2,) float
            Horizontal site-frame position where the site frame's z axis is the local
            vertical, m.

        Returns
        -------
        tilt_rad : (n, 2) float
            ``(roll, pitch)`` of each station, rad (zeros for the plane).

        Examples
        --------
        At 381 m east of the tangent point a station heading east pitches by 381 / R (nose
        up), one heading north (the tangent point on its left) rolls by 381 / R:

        >>> moon = Body.named("moon")
        >>> t = moon.vertical_tilt(np.array([[381.0, 0, 0], [381.0, 0, 0]]),
        ...                        np.array([0.0, np.pi / 2]))
        >>> (np.round(np.degrees(t), 5) + 0.0).tolist()
        [[0.0, 0.01256], [0.01256, 0.0]]
        >>> Body().vertical_tilt(np.zeros((1, 3)), np.zeros(1)).tolist()
        [[0.0, 0.0]]
        """
        p = np.asarray(position_m, dtype=float).reshape(-1, 3)
        h = np.asarray(heading_rad, dtype=float).reshape(-1)
        if h.shape[0] != p.shape[0]:
            raise ConfigError(f"`heading_rad` must have shape ({p.shape[0]},), got {h.shape}")
        if self.radius_m is None:
            return np.zeros((p.shape[0], 2))
        up = np.column_stack([p[:, 0] - tangent_point_m[0], p[:, 1] - tangent_point_m[1],
                              p[:, 2] + self.radius_m])
        up /= np.linalg.norm(up, axis=1, keepdims=True)
        v = np.einsum("nji,nj->ni", rot_z(h), up)  # Rz(h)^T u
        return np.column_stack([-np.arcsin(v[:, 1]), np.arctan2(v[:, 0], v[:, 2])])
