"""The true tilt of a verified plan's stations: each levels itself to the local vertical of the
body it stands on.

The scan simulator of ``verify --network`` stands each station at its planned position and
heading; on a curved body (:class:`pipeline.network.body.Body`) the rover's inclinometer levels
it to the local vertical there, which leans away from the tangent point by about ``d / R``
(0.0126 deg at 381 m on the Moon). The site frame is taken as the tangent plane at the datum
station, the tangent point of the adjustment
(:func:`pipeline.network.adjustment.tilt_prior_centre`), so that ``adjust --body`` with the same
body centres its roll and pitch priors on the truth, and the plane's prior (``--body plane``)
on a tilt that is wrong by the deflection: the vertical bias of ``D^2 / 2R`` that
``benchmarks/curvature_verify.py`` measures.
"""

from __future__ import annotations

import numpy as np

from pipeline.network.body import Body
from planner.outputs.plan_file import SurveyPlan


def levelled_tilts(plan: SurveyPlan, body: Body, reference: str | None = None,
                   station_ids: list[str] | None = None
                   ) -> dict[str, tuple[float, float]] | None:
    """Roll and pitch of every planned station levelled to ``body``'s local vertical.

    Parameters
    ----------
    plan : SurveyPlan
        Its stations' planned positions (site frame, m) and headings (rad).
    body : Body
    reference : str, optional
        The datum station, whose vertical is the site frame's z axis (``verify
        --reference-station``); default the plan's
        (:func:`planner.verify.network_datum.reference_station`).
    station_ids : list of str, optional
        The stations verified (the reference must be among them); default all.

    Returns
    -------
    tilt_rad : dict of str to (float, float) or None
        Per station id, ``(roll, pitch)`` (:meth:`pipeline.network.body.Body.vertical_tilt`),
        rad; ``None`` on the plane (every station level).

    Raises
    ------
    ConfigError
        The reference is not a station of the plan, or not among ``station_ids``.
    """
    from planner.verify.network_datum import reference_station

    if body.radius_m is None:
        return None
    ids = [st.id for st in plan.stations]
    named = plan.provenance.get("config", {}).get("reference_station")
    tangent = reference_station(reference or (named if isinstance(named, str) else None), ids,
                                station_ids or ids)
    tilt = body.vertical_tilt(np.stack([st.position_m for st in plan.stations]),
                              np.array([st.heading_rad for st in plan.stations]),
                              plan.stations[ids.index(tangent)].position_m[:2])
    return {sid: (float(r), float(p)) for sid, (r, p) in zip(ids, tilt, strict=True)}
