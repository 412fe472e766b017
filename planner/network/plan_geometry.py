"""A ``plan.json`` as the network adjustment takes it: the plan's geometry and settings
(:class:`pipeline.network.detections.PlanGeometry`), and an adjustment's configuration resolved
against the plan and the planner's defaults (``adjust``, ``verify --network``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from markerplan.errors import ConfigError, InputFileError
from markerplan.reading import finite_number, require_type
from pipeline.network.detections import PlanGeometry
from pipeline.network.observations import MIN_SIGMA, usable_sigma


def read_plan_geometry(path: Path) -> PlanGeometry:
    """Markers, stations and requirement of a ``plan.json`` (checked by
    :func:`planner.outputs.plan_file.read_plan`, typed by
    :func:`planner.outputs.plan_file.plan_layout`; the terrain is not loaded).

    Parameters
    ----------
    path : Path
        The ``plan.json`` written by ``markerplan plan``.

    Returns
    -------
    PlanGeometry

    Raises
    ------
    InputFileError
        As :func:`planner.outputs.plan_file.read_plan`, or an inclinometer or heading-prior sigma in
        its configuration that is not a number in (0, 10] degrees.
    """
    from planner.outputs.plan_file import read_plan

    return plan_geometry(read_plan(path, "`plan_path`", full=True), path)


def plan_geometry(doc: dict, path: Path) -> PlanGeometry:
    """:func:`read_plan_geometry` of a plan document already read (``full=True``) from
    ``path``."""
    from planner.outputs.plan_file import plan_dem_path, plan_layout

    cfg = doc["provenance"].get("config", {})
    what = f"`plan_path` {path}: provenance config"
    incl, heading = (_plan_sigma_deg(cfg, k, what)
                     for k in ("inclinometer_sigma_deg", "heading_prior_sigma_deg"))
    if heading is None and cfg.get("heading_aid") is not None:  # the class's random sigma
        from planner.accuracy.aids import heading_aid_sigmas_deg

        try:
            heading = heading_aid_sigmas_deg(cfg["heading_aid"])[0]
        except ConfigError as exc:
            raise InputFileError(f"{what} heading_aid: {exc}") from exc
    reference = cfg.get("reference_station")
    figure = cfg.get("error_figure", "ellipsoid")
    from planner.config import ERROR_FIGURES

    if figure not in ERROR_FIGURES:
        raise InputFileError(f"{what} error_figure: must be one of "
                             f"{', '.join(map(repr, ERROR_FIGURES))}, got {figure!r:.40}; plan "
                             "again or correct the member")
    layout = plan_layout(doc)
    return PlanGeometry(
        Path(path), layout.marker_ids, layout.marker_xyz_m,
        tuple(s.id for s in layout.stations),
        np.array([s.position_m for s in layout.stations], dtype=float),
        np.array([s.heading_rad for s in layout.stations]),
        float(doc["requirement"]["working_radius_m"]), float(doc["requirement"]["requirement_m"]),
        incl, heading, reference if isinstance(reference, str) else None,
        plan_dem_path(doc["provenance"]), _plan_crs(doc["site"], path), figure,
        _plan_heading_bias_deg(doc, path) if heading is not None else None)


def _plan_heading_bias_deg(doc: dict, path: Path) -> float | None:
    """The boresight bias of the plan's heading reference, degrees, from its ``network.datum``
    record of the aids (:meth:`planner.config.PlanConfig.aids_record`); ``None`` when it records
    none or 0 (a plan that is no network plan records no aids)."""
    datum = doc.get("network")
    datum = datum.get("datum") if isinstance(datum, dict) else None
    bias = datum.get("heading_bias_sigma_deg") if isinstance(datum, dict) else None
    if bias is None:
        return None
    bias = finite_number(bias, f"`plan_path` {path}: network datum heading_bias_sigma_deg", 10.0)
    if bias < 0.0 or (bias and not usable_sigma(np.radians(bias))):
        raise InputFileError(f"`plan_path` {path}: network datum heading_bias_sigma_deg: must be "
                             f"0 (none) or at least {np.degrees(MIN_SIGMA):.2g} degrees (a "
                             f"1-sigma), got {bias:g}; plan again or correct it")
    return bias or None


def _plan_crs(site: dict, path: Path) -> str | None:
    """The plan's ``site.crs_wkt`` (``None`` when absent or null), checked to be a CRS."""
    wkt = site.get("crs_wkt")
    if wkt is None:
        return None
    from rasterio.crs import CRS
    from rasterio.errors import CRSError

    try:
        require_type(wkt, str, f"`plan_path` {path}: site crs_wkt")
        return CRS.from_user_input(wkt).to_wkt()
    except CRSError as exc:
        raise InputFileError(f"`plan_path` {path}: site crs_wkt is not a CRS ({exc}); plan again "
                             "or remove the member") from exc


def _plan_sigma_deg(cfg: dict, key: str, what: str) -> float | None:
    """The plan's angle sigma ``cfg[key]``, degrees, in [degrees(MIN_SIGMA), 10]; ``None``
    when it records none.

    A sigma of 0 would make the prior exact (an infinite weight), so it is refused rather than
    read as "not set"; one below :data:`pipeline.network.observations.MIN_SIGMA` would
    overflow its weight."""
    if cfg.get(key) is None:
        return None
    sigma = finite_number(cfg[key], f"{what} {key}", 10.0)
    if not usable_sigma(np.radians(sigma)):
        raise InputFileError(
            f"{what} {key}: must be at least {np.degrees(MIN_SIGMA):.2g} deg for an adjustment "
            "(0 would make the prior exact, and a smaller sigma's weight 1/sigma^2 overflows), "
            f"got {sigma:g}; plan again with a `config_path` setting {key} to the sensor's 1-sigma "
            "(e.g. 0.01)")
    return sigma


def body_configuration(body, reference_id: str) -> dict:
    """The record of the body whose local vertical centred the tilt priors
    (:class:`pipeline.network.body.Body`) and of its tangent point (the reference station's
    initial position: :class:`pipeline.network.adjustment.AdjustmentSettings`'s default).

    >>> from pipeline.network.body import Body
    >>> body_configuration(Body.named("moon"), "S01")["radius_m"]
    1737400.0
    """
    return {**body.to_dict(),
            "tangent_point": f"station {reference_id}'s initial position (the reference)"}


def resolved_configuration(plan_geometry, **options) -> dict:
    """The resolved configuration of an adjustment (``adjust``, ``verify --network``).

    Parameters
    ----------
    plan_geometry : PlanGeometry or None
        The plan's settings, when a plan is given.
    **options
        The command's options; ``inclinometer_sigma_deg``, ``working_radius_m``,
        ``requirement_m``, ``heading_prior_sigma_deg`` and ``error_figure`` are required keys
        (``None``: not given).

    Returns
    -------
    config : dict
        ``options`` with each of those five not given taken from the plan, else from
        :class:`planner.config.PlanConfig`'s defaults.
    """
    from planner.config import PlanConfig

    plan, defaults = plan_geometry, PlanConfig()
    for key in ("inclinometer_sigma_deg", "working_radius_m", "requirement_m",
                "heading_prior_sigma_deg", "error_figure"):
        if options[key] is None:
            from_plan = getattr(plan, key) if plan is not None else None
            options[key] = from_plan if from_plan is not None else getattr(defaults, key)
    return options
