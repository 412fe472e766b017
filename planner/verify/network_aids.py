"""The pose aids a network plan was made with, simulated for ``verify --network``.

A plan records its aids in ``provenance.config`` (:meth:`planner.config.PlanConfig.
aids_record`): a heading reference (``heading_prior_sigma_deg`` or the ``heading_aid`` class,
with a boresight bias ``heading_bias_sigma_deg``) and odometry between consecutive stations
(``odometry_percent``, ``odometry_heading_deg_per_m``), closed from the last station back to the
first on a closed traverse (``odometry_loop_m``). Verification reads them from the truth the
scans were simulated at, with the plan's sigmas:

- odometry: between consecutive adjusted stations in the plan's order, the true relative pose
  (:meth:`pipeline.network.aids.OdometryReadings.from_poses`) plus noise of 1-sigma
  ``odometry_percent / 100 * d`` per axis and ``odometry_heading_deg_per_m * d`` on the heading
  (``d`` the true 3D distance between the two). A station left out of the adjustment is skipped:
  its neighbours are then one reading apart, of their own distance;
- the closing reading of a closed traverse: the first adjusted station's true pose in the
  levelled frame of the last, with the same noise over the closing legs' distance
  (``odometry_loop_m``, plus the straight steps to stations left out at either end:
  :func:`planner.accuracy.aids.closing_distance_m`);
- heading reference: each station's true heading plus one bias common to all (drawn once) plus
  independent noise.

The draws come from their own generator seeded by verify's seed (the same seed: the same
readings and outputs), in a fixed order over the stations verified (plan order): the bias, one
heading noise per station, then four odometry noises per station (a reading takes those of the
station it is read from: the closing reading those of the last adjusted station).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from markerplan.errors import ConfigError, InputFileError

#: Separates the aids' random stream from the scans' for the same verify seed.
_STREAM = 29


@dataclass(frozen=True)
class PlanAids:
    """A plan's pose aids, resolved (degrees and percent, as ``plan.json`` records them).

    Attributes
    ----------
    heading_sigma_deg : float or None
        Random 1-sigma of the heading reference; None: none.
    heading_bias_sigma_deg : float
        Its boresight bias, 1-sigma (0: none).
    odometry_percent, odometry_heading_deg_per_m : float or None
        Odometry sigmas per metre driven; None: not observed.
    odometry_loop_m : float or None
        A closed traverse's closing legs' distance, m; None: an open traverse.
    """

    heading_sigma_deg: float | None = None
    heading_bias_sigma_deg: float = 0.0
    odometry_percent: float | None = None
    odometry_heading_deg_per_m: float | None = None
    odometry_loop_m: float | None = None

    @property
    def odometry(self) -> bool:
        return self.odometry_percent is not None or self.odometry_heading_deg_per_m is not None

    def settings(self) -> dict:
        """The :class:`~pipeline.network.adjustment.AdjustmentSettings` keywords of the aids."""
        def rad(v):
            return None if v is None else math.radians(v)

        return {"heading_prior_sigma_rad": rad(self.heading_sigma_deg),
                "heading_bias_sigma_rad": rad(self.heading_bias_sigma_deg or None),
                "odometry_ratio": (None if self.odometry_percent is None
                                   else self.odometry_percent / 100.0),
                "odometry_heading_rad_per_m": rad(self.odometry_heading_deg_per_m)}

    def record(self) -> dict:
        """The aids as used, for the verification's configuration."""
        return {"heading_prior_sigma_deg": self.heading_sigma_deg,
                "heading_bias_sigma_deg": self.heading_bias_sigma_deg,
                "odometry_percent": self.odometry_percent,
                "odometry_heading_deg_per_m": self.odometry_heading_deg_per_m,
                "odometry_loop_m": self.odometry_loop_m}

    def readings(self, station_ids: list[str], pose: np.ndarray, seed: int):
        """An :func:`pipeline.network.run.adjust_tables` ``aids``: the simulated readings of
        the adjusted network (module doc).

        Parameters
        ----------
        station_ids : list of str
            The stations verified, in the plan's order.
        pose : (s, 6) float
            Their true poses (``POSE_PARAMETERS``), site frame, m and rad.
        seed : int
            Verify's seed.

        Returns
        -------
        aids : callable
            ``aids(observations)`` -> ``(OdometryReadings or None, HeadingReadings or None)``.
        """
        from pipeline.network.aids import HeadingReadings, OdometryReadings
        from planner.accuracy.aids import closing_distance_m

        s = len(station_ids)
        rng = np.random.default_rng([_STREAM, int(seed)])
        bias = rng.normal(0.0, math.radians(self.heading_bias_sigma_deg))
        heading_noise = rng.normal(size=s)
        odometry_noise = rng.normal(size=(s, 4))

        def aids(obs):
            where = {sid: i for i, sid in enumerate(station_ids)}
            kept = [where[sid] for sid in obs.station_ids]
            heading = None
            if self.heading_sigma_deg is not None:
                heading = HeadingReadings(pose[kept, 3] + bias + heading_noise[kept]
                                          * math.radians(self.heading_sigma_deg))
            odometry = None
            chain = sorted(kept)
            if self.odometry and len(chain) > 1:
                loop = (None if self.odometry_loop_m is None
                        else closing_distance_m(pose[:, :3], self.odometry_loop_m, chain))
                exact = OdometryReadings.from_poses(
                    np.arange(len(chain)), pose[chain, :3], pose[chain, 3], loop)
                d = exact.driven_m
                noise = odometry_noise[chain[:d.size]]
                ratio = (self.odometry_percent or 0.0) / 100.0
                rate = math.radians(self.odometry_heading_deg_per_m or 0.0)
                order = np.array([obs.station_ids.index(station_ids[i]) for i in chain])
                odometry = OdometryReadings(order,
                                            exact.delta_xyz_m + noise[:, :3] * (ratio * d)[:, None],
                                            exact.delta_heading_rad + noise[:, 3] * rate * d, loop)
            return odometry, heading

        return aids


def plan_aids(doc: dict, plan_path, heading_sigma_deg: float | None) -> PlanAids:
    """The aids of a plan document (``provenance.config``); ``heading_sigma_deg`` the heading
    reference's random sigma as already resolved (the plan's or ``heading_aid``'s).

    Raises
    ------
    InputFileError
        An aid's value that is not a plan's (named).
    """
    from planner.config import PlanConfig

    cfg = doc["provenance"].get("config", {})
    keys = ("heading_aid", "heading_bias_sigma_deg", "odometry_percent",
            "odometry_heading_deg_per_m", "odometry_loop_m")
    try:
        config = PlanConfig(network=True, **{k: cfg.get(k) for k in keys},
                            heading_prior_sigma_deg=heading_sigma_deg)
        bias = config.heading_sigmas_deg[1] if heading_sigma_deg is not None else 0.0
    except (ConfigError, TypeError) as exc:
        raise InputFileError(f"`plan_path` {plan_path}: provenance config: {exc}") from exc
    return PlanAids(heading_sigma_deg, float(bias), config.odometry_percent,
                    config.odometry_heading_deg_per_m, config.odometry_loop_m)
