"""Why a network cannot meet its requirement: the stations no layout can tie to the reference
well enough, with the reason (:func:`diagnose_network`), for the planner's one-line refusals."""

from __future__ import annotations

import numpy as np

from planner.accuracy.network import NetworkModel


def diagnose_network(net: NetworkModel, available) -> dict[str, str]:
    """Stations no layout within ``available`` can tie to the reference well enough.

    Parameters
    ----------
    net : NetworkModel
    available : (n,) bool
        Sites a layout may use (every allowed site; by monotonicity the best case). Each
        station is judged against its allowance (:attr:`NetworkModel.allowed_station_m`).

    Returns
    -------
    reasons : dict of station id -> reason
        "disconnected" (no chain of shared usable sites reaches the reference), "heading
        undetermined" (tied through markers at one place only), "too far from the
        reference" (the error at the station itself already exceeds the requirement) or
        "heading too weak" (the lever arm to the working-radius rim does).
    """
    p = net.problem
    ids = p.station_ids
    ref = net.datum_text
    linked = net.connected_to_reference(available)
    out = {}
    for k in np.flatnonzero(~linked):
        out[ids[k]] = (f"disconnected: shares no usable marker site with the part of the "
                       f"network holding the datum, {ref}")
    if out:
        return out
    cov = net.covariance(net.information(available))
    err = net.station_errors_from(cov)
    blocks = cov.station(np.arange(p.n_stations))
    at_station = net.figure.point_errors(blocks[:, :3, :3])
    dist = net.station_distance_m
    allowed = net.allowed_station_m
    for k in range(p.n_stations):
        if not cov.determined[k]:
            out[ids[k]] = ("heading undetermined: tied to the network only through markers "
                           "at one place; it needs two shared sites apart")
        elif err[k] > allowed[k] and at_station[k] > allowed[k]:
            out[ids[k]] = (f"too far from the datum: {at_station[k]:.3f} m at the station "
                           f"itself with every usable site ({dist[k]:.0f} m from {ref}), "
                           f"above {allowed[k]:.4g} m")
        elif err[k] > allowed[k]:
            out[ids[k]] = (f"heading too weak: {err[k]:.3f} m at the {net.radius:g} m "
                           f"working-radius rim ({at_station[k]:.3f} m at the station "
                           f"itself) with every usable site, above {allowed[k]:.4g} m")
    return out
