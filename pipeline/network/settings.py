"""The settings of a network adjustment (:class:`AdjustmentSettings`): priors and aids, test
levels, robust estimation, variance components, the body's vertical and how the covariance is
held; each checked when made. Used by :func:`pipeline.network.adjustment.adjust`."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from markerplan.errors import ConfigError
from pipeline.network import robust as robust_
from pipeline.network import variance
from pipeline.network.body import Body
from pipeline.network.observations import SIGMA_RULE, usable_sigma

#: How the covariance is held (:attr:`AdjustmentSettings.covariance`).
COVARIANCE_KINDS = ("auto", "dense", "sparse")

#: ``covariance="auto"`` holds marginal blocks only above this many parameters (6s + 3k): the
#: full array is then above 36 MB and the marginal blocks are faster too.
SPARSE_ABOVE_PARAMETERS = 2000


@dataclass(frozen=True)
class AdjustmentSettings:
    """Priors, test levels and iteration limits of :func:`adjust`.

    Attributes
    ----------
    inclinometer_sigma_rad : float
        1-sigma of each station's roll and pitch prior, rad (at least
        :data:`~pipeline.network.observations.MIN_SIGMA`). The prior's centre is the local
        vertical's deflection on ``body`` (0 on the plane); the covariance does not depend on it.
    heading_prior_sigma_rad : float or None
        1-sigma of a heading observation around the nominal heading (sun sensor), rad (at
        least :data:`~pipeline.network.observations.MIN_SIGMA`); None for none. Needs nominal
        poses or heading readings (then centred on those).
    heading_bias_sigma_rad : float or None
        1-sigma of the heading reference's common boresight bias, rad (eliminated: the heading
        observations correlated, :mod:`pipeline.network.aids`); needs the heading prior.
    odometry_ratio, odometry_heading_rad_per_m : float or None
        1-sigma of odometry readings per metre driven: per axis of the relative position (e.g.
        0.02), and of the relative heading (rad/m); needed with odometry readings.
    alpha0, beta0 : float
        Significance level and power of the test of each point observation (Baarda), in
        (0, 1).
    snooping : bool
        Remove blunders by data snooping (not with ``robust``).
    max_rejections : int
        Most observations data snooping may remove.
    max_iterations : int
        Gauss-Newton iterations before giving up.
    robust : {None, "huber", "igg3"}
        Robust estimation (:mod:`pipeline.network.robust`) instead of data snooping: None for
        plain least squares.
    robust_k0, robust_k1 : float
        Tuning constants, standardised-residual units: Huber's ``k`` (``robust_k0``; default
        :data:`~pipeline.network.robust.HUBER_K`) or IGG-III's ``k0 < k1`` (defaults
        :data:`~pipeline.network.robust.IGG3_K0`, :data:`~pipeline.network.robust.IGG3_K1`).
    variance_components : {None, "station", "range"}
        Estimate a variance factor per observing station or per range band
        (:mod:`pipeline.network.variance`); None for none.
    body : Body
        The body whose local vertical the inclinometer levels to
        (:class:`~pipeline.network.body.Body`); default the plane (no deflection: the model of
        earlier versions, and right where the body or the site frame is unknown).
    tangent_point_m : (2,) float or None
        Horizontal site-frame position where the site frame's z axis is the local vertical, m;
        None for the reference station's initial position (the datum station defines the site
        frame; :meth:`~pipeline.network.observations.Datum.resolve`'s station for the other
        datums).
    covariance : {"auto", "dense", "sparse"}
        ``"dense"``: the full covariance array; ``"sparse"``: only its marginal blocks
        (:class:`pipeline.network.marginals.MarginalCovariance`, exact; downdated between
        data-snooping rounds as the dense one is); ``"auto"``: sparse above
        :data:`SPARSE_ABOVE_PARAMETERS` parameters.
    """

    inclinometer_sigma_rad: float = math.radians(0.01)
    heading_prior_sigma_rad: float | None = None
    heading_bias_sigma_rad: float | None = None
    odometry_ratio: float | None = None
    odometry_heading_rad_per_m: float | None = None
    alpha0: float = 0.001
    beta0: float = 0.80
    snooping: bool = True
    max_rejections: int = 20
    max_iterations: int = 20
    robust: str | None = None
    robust_k0: float = robust_.HUBER_K
    robust_k1: float = robust_.IGG3_K1
    variance_components: str | None = None
    body: Body = Body()
    tangent_point_m: tuple[float, float] | None = None
    covariance: str = "auto"

    def __post_init__(self):
        def sigma(name, value):
            if not (isinstance(value, int | float) and usable_sigma(value)):
                raise ConfigError(f"{name} must be a number {SIGMA_RULE}, got {value!r}")

        sigma("inclinometer_sigma_rad", self.inclinometer_sigma_rad)
        for name in ("heading_prior_sigma_rad", "heading_bias_sigma_rad", "odometry_ratio",
                     "odometry_heading_rad_per_m"):
            if getattr(self, name) is not None:
                sigma(name, getattr(self, name))
        if self.heading_bias_sigma_rad is not None and self.heading_prior_sigma_rad is None:
            raise ConfigError("heading_bias_sigma_rad needs a heading reference: set "
                              "heading_prior_sigma_rad too, or drop the bias")
        for name in ("alpha0", "beta0"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and 0 < value < 1):
                raise ConfigError(f"{name} must lie in (0, 1), got {value!r}")
        for name, least in (("max_rejections", 0), ("max_iterations", 1)):
            value = getattr(self, name)
            if not (isinstance(value, int) and value >= least):
                raise ConfigError(f"{name} must be an integer >= {least}, got {value!r}")
        if self.covariance not in COVARIANCE_KINDS:
            raise ConfigError(f"covariance must be one of {', '.join(COVARIANCE_KINDS)}, got "
                              f"{self.covariance!r}")
        for name, allowed in (("robust", robust_.ESTIMATORS),
                              ("variance_components", variance.GROUPINGS)):
            if getattr(self, name) not in (None, *allowed):
                raise ConfigError(f"{name} must be None or one of {', '.join(allowed)}, got "
                                  f"{getattr(self, name)!r}")
        k0, k1 = self.robust_k0, self.robust_k1
        if not all(isinstance(k, int | float) and 0 < k < math.inf for k in (k0, k1)):
            raise ConfigError(f"robust_k0 and robust_k1 must be finite numbers > 0, got {k0!r} "
                              f"and {k1!r}")
        if self.robust == "igg3" and not k0 < k1:
            raise ConfigError(f"IGG-III needs robust_k0 < robust_k1, got {k0!r} and {k1!r}")
        if not isinstance(self.body, Body):
            raise ConfigError(f"body must be a Body (Body.named('moon'|'earth'|'plane')), got "
                              f"{self.body!r:.40}")
        tp = self.tangent_point_m
        if tp is not None and not (np.shape(tp) == (2,) and all(
                isinstance(v, int | float) and math.isfinite(v) for v in tp)):
            raise ConfigError(f"tangent_point_m must be None or 2 finite numbers (x, y) in m, got "
                              f"{tp!r:.60}")
        if self.robust is not None and self.snooping:
            raise ConfigError("robust estimation replaces data snooping: give snooping=False "
                              f"with robust={self.robust!r}")
