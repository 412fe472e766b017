"""``report.md`` of ``markerplan adjust``: the adjustment as a surveyor reads it, top to bottom.

Datum and frame first; then the fit (variance factor, degrees of freedom, global test, variance
components of observation groups when estimated); the observations data snooping removed and
why, or those robust estimation down-weighted; the stations, the relative accuracy of
neighbouring stations (:mod:`planner.network.relative`) and the markers, weakest first; the
reliability figures (redundancy numbers, minimal detectable biases and their effect); how
markers were identified; inputs and provenance. The numbers are those of the other files
(:mod:`planner.network.record`).
"""

from __future__ import annotations

from planner.accuracy.figure import ErrorFigure
from planner.network.relative import relative_markdown

#: Rows of the weakest-first tables shown in full (the CSV files hold every one).
MAX_ROWS = 15


def _mm(value: float | None) -> str:
    """Metres as millimetres for the report.

    >>> _mm(0.01234), _mm(None)
    ('12.3 mm', '—')
    """
    return "—" if value is None else f"{1e3 * value:.1f} mm"


def report_markdown(doc: dict, stations: list[dict], markers: list[dict],
                    observations: list[dict], relative: list[dict] = ()) -> str:
    """The Markdown report.

    Parameters
    ----------
    doc : dict
        The ``adjustment.json`` document (:func:`planner.network.record.adjustment_record`).
    stations, markers, observations : list of dict
        The rows of ``stations.csv``, ``markers.csv`` and ``observations.csv``.
    relative : list of dict
        The rows of ``relative.csv`` (:mod:`planner.network.relative`; shown when ``doc`` has
        a ``relative`` section).

    Returns
    -------
    text : str
    """
    st, req = doc["statistics"], doc["requirement"]
    lines = [f"# Network adjustment — {st['n_stations']} stations, {st['n_markers']} markers",
             "", _verdict(doc), ""]
    lines += _datum(doc) + _fit(doc) + _variance(doc) + _snooping(doc) + _robust(doc)
    lines += _stations(stations, req) + relative_markdown(doc.get("relative"), list(relative))
    lines += _markers(markers) + _reliability(doc, observations) + _identity(doc)
    lines += _provenance(doc)
    return "\n".join(lines) + "\n"


def _verdict(doc: dict) -> str:
    st, req, test = doc["statistics"], doc["requirement"], doc["global_test"]
    fit = ("no redundancy: the fit cannot be tested" if test["passed"] is None else
           f"the data agree with the error model (global test passed, sigma0² = "
           f"{test['statistic']:.3f}{_pessimistic(test)})" if test["passed"] else
           f"**global test failed**: sigma0² = {test['statistic']:.3f} outside "
           f"[{test['lower']:.3f}, {test['upper']:.3f}], {test['verdict']}")
    rejected = st["n_rejected"]
    return (f"{req['n_stations_meeting']} of {st['n_stations']} stations meet the "
            f"{req['requirement_m']:g} m requirement (95 % over a {req['working_radius_m']:g} m "
            f"working radius); the weakest is {req['worst_station']} at "
            f"{_mm(req['worst_station_error_95_m'])}. Relative to the datum "
            f"({doc['datum']['description']}), {fit}; data snooping removed "
            f"{rejected} observation{'s' if rejected != 1 else ''}.")


def _pessimistic(test: dict) -> str:
    return "; below the range: the error model is pessimistic" \
        if test["verdict"] == "error model pessimistic" else ""


def _datum(doc: dict) -> list[str]:
    d = doc["datum"]
    lines = ["## Datum and frame", "", f"- Datum: {d['description']}."]
    if d["kind"] == "control":
        lines += [f"  - {c['marker_id']}: ({', '.join(f'{v:.3f}' for v in c['xyz_m'])}) m ± "
                  f"{', '.join(f'{v:g}' for v in c['sigma_m'])} m" for c in d["control"]]
    lines += [f"- Frame: {doc['frame']}.",
              "- Every sigma, ellipse and station error is relative to this datum; ellipsoids "
              "are 95 % (chi² with 3 degrees of freedom) from the a-priori covariance "
              "(sigma0 = 1, the error model's sigmas taken as known).", ""]
    return lines


def _fit(doc: dict) -> list[str]:
    st, test, solver = doc["statistics"], doc["global_test"], doc["provenance"]["solver"]
    if test["passed"] is None:
        verdict = "not testable (no redundancy)"
    else:
        verdict = (f"{'passed' if test['passed'] else 'FAILED'}: sigma0² = "
                   f"{test['statistic']:.3f}, range [{test['lower']:.3f}, "
                   f"{test['upper']:.3f}] (chi²({test['dof']}) / dof, two-sided "
                   f"{100 * test['alpha']:g} %; above it fails, below it the error model is "
                   "pessimistic)" + ("" if test["verdict"] == "ok" else
                                     f": {test['verdict']}"))
    return ["## Fit", "", "| quantity | value |", "|---|---:|",
            f"| observations (marker centres) | {st['n_observations']} "
            f"({st['n_observation_components']} components) |",
            f"| unknowns | {st['n_unknowns']} ({st['n_stations']} poses x 6, "
            f"{st['n_markers']} centres x 3) |",
            f"| degrees of freedom | {st['dof']} |",
            f"| sigma0² (a posteriori variance factor) | "
            f"{_num(st['sigma0_squared'], '.4f')} |",
            f"| Gauss-Newton iterations | {st['iterations']} ({solver['status']}) |", "",
            f"Global test: {verdict}.", ""]


def _num(value: float | None, spec: str) -> str:
    return "—" if value is None else format(value, spec)


def _snooping(doc: dict) -> list[str]:
    ds = doc["data_snooping"]
    k = ds["critical_value"]
    lines = ["## Data snooping", "",
             f"Each point observation (a marker centre) is tested as one 3-dimensional group: "
             f"T = vᵀ Q_vv⁻¹ v, chi²(3) when the model holds, and w = Φ⁻¹(1 − p/2) from its "
             f"p-value (Baarda's |w| for one dimension); alpha0 = {ds['alpha0']:g} (critical "
             f"value w {k:.2f}, T {ds['critical_value_T']:.2f} for 3 dimensions), beta0 = "
             f"{ds['beta0']:g}; "
             + ("the observation with the largest w above it is removed and the network "
                "adjusted again, until none is. A removed centre disagrees with the rest of the "
                "network beyond its noise: a mis-identified or moved marker, or a bad sphere "
                "fit." if ds["enabled"] else
                "snooping was **off**: observations are flagged, never removed."), ""]
    if ds["rejected"]:
        lines += ["| round | station | marker | w | T | why |", "|---:|---|---|---:|---:|---|"]
        lines += [f"| {r['round']} | {r['station_id']} | {r['marker_id']} | {r['w']:.2f} | "
                  f"{r['T']:.4g} | w {r['w']:.1f} > {k:.2f}, the largest in round "
                  f"{r['round']} |" for r in ds["rejected"]]
        lines.append("")
    else:
        lines += ["No observation was removed.", ""]
    if ds["flagged"]:
        lines += ["Flagged but kept (w above the critical value): "
                  + ", ".join(f"{f['station_id']}→{f['marker_id']} (w {f['w']:.2f})"
                              for f in ds["flagged"]) + ".", ""]
    return lines


def _robust(doc: dict) -> list[str]:
    rb = doc["robust"]
    if rb is None:
        return []
    name = {"huber": "Huber", "igg3": "IGG-III (Yang)"}[rb["estimator"]]
    constants = ", ".join(f"{key} = {value:g}" for key, value in rb["constants"].items())
    lines = ["## Robust estimation", "",
             f"{name} M-estimator ({constants}), iteratively reweighted least squares in "
             f"{rb['rounds']} round(s): each point observation's weight is multiplied by a "
             "factor in [0, 1] from its standardised residual (the w of its point test, with "
             "its own weights); nothing is removed. Sigmas and ellipsoids below are those of "
             "the robust weights.", ""]
    down = rb["downweighted"]
    if not down:
        return lines + ["No observation was down-weighted.", ""]
    lines += [f"Down-weighted observations ({len(down)}), lowest weight first:", "",
              "| station | marker | weight | w |", "|---|---|---:|---:|"]
    lines += [f"| {d['station_id']} | {d['marker_id']} | {d['weight']:.3f} | {d['w']:.2f} |"
              for d in down[:MAX_ROWS]]
    if len(down) > MAX_ROWS:
        lines.append(f"| … {len(down) - MAX_ROWS} more in observations.csv | | | |")
    return lines + [""]


def _variance(doc: dict) -> list[str]:
    vc = doc["variance_components"]
    if vc is None:
        return []
    lines = ["## Variance components", "",
             f"Variance factor of each {vc['groups']} group (iterated Förstner / simplified "
             "Helmert estimator, v_gᵀ P_g v_g / r_g): 1 when the error model's sigmas hold for "
             "the group, 4 when its errors are twice as large. The adjustment above keeps the "
             "error model's weights; sd is an estimate's scatter under the model "
             "(sigma0² √(2 / r_g)).", "",
             "| group | observations | redundancy | sigma0² | sd |", "|---|---:|---:|---:|---:|"]
    lines += [f"| {c['group']} | {c['n_observations']} | {c['redundancy']:.1f} | "
              f"{_num(c['sigma0_squared'], '.3f')} | {_num(c['sd'], '.3f')} |"
              for c in vc["components"]]
    return lines + [""]


def _stations(stations: list[dict], req: dict) -> list[str]:
    ordered = sorted(stations, key=lambda s: (-s["station_error_95_m"], s["station_id"]))
    lines = ["## Stations, weakest first", "",
             f"Station error: the 95 % figure of the error of points registered with the "
             f"station's pose, over the station and its {req['working_radius_m']:g} m working "
             f"radius (requirement {req['requirement_m']:g} m): "
             f"{ErrorFigure(req['error_figure']).describe()}.", "",
             "| station | station error | ellipsoid (95 %) a / b / c | sigma heading | "
             "observations | meets |", "|---|---:|---:|---:|---:|---|"]
    for s in ordered[:MAX_ROWS]:
        ref = " (datum)" if s["reference"] else ""
        lines.append(f"| {s['station_id']}{ref} | {_mm(s['station_error_95_m'])} | "
                     f"{_axes(s)} | {s['sigma_heading_deg'] * 3600:.1f}″ | "
                     f"{s['n_observations']} | {'yes' if s['meets_requirement'] else '**no**'} |")
    if len(ordered) > MAX_ROWS:
        lines.append(f"| … {len(ordered) - MAX_ROWS} more in stations.csv | | | | | |")
    return lines + [""]


def _axes(row: dict) -> str:
    return " / ".join(f"{1e3 * row[k]:.1f}" for k in ("ellipsoid_major_m", "ellipsoid_middle_m",
                                                        "ellipsoid_minor_m")) + " mm"


def _markers(markers: list[dict]) -> list[str]:
    ordered = sorted(markers, key=lambda m: (-m["ellipsoid_major_m"], m["marker_id"]))
    lines = ["## Markers, weakest first", "",
             "| marker | ellipsoid (95 %) a / b / c | stations |", "|---|---:|---|"]
    for m in ordered[:MAX_ROWS]:
        ctl = " (control)" if m["control"] else ""
        lines.append(f"| {m['marker_id']}{ctl} | {_axes(m)} | {m['stations']} |")
    if len(ordered) > MAX_ROWS:
        lines.append(f"| … {len(ordered) - MAX_ROWS} more in markers.csv | | |")
    single = [m["marker_id"] for m in markers if m["n_stations"] == 1]
    lines.append("")
    if single:
        lines += [f"Seen by one station only ({len(single)}): {', '.join(single)} — they tie no "
                  "stations together and their observations are uncontrolled (redundancy 0).",
                  ""]
    return lines


def _reliability(doc: dict, observations: list[dict]) -> list[str]:
    rel = doc["reliability"]
    lines = ["## Reliability", ""]
    if rel["mean_redundancy"] is None:
        return lines + ["No observation was kept.", ""]
    lines += [f"- Redundancy numbers: mean {rel['mean_redundancy']:.2f}, smallest "
              f"{rel['min_redundancy']:.2f}; {rel['n_weak']} observation(s) with a component "
              "below 0.1 (an error there hardly shows in its residual), "
              f"{rel['n_uncontrolled']} uncontrolled (redundancy 0: a marker seen once)."]
    big = rel["largest_mdb"]
    if big is not None:
        lines.append(f"- Largest minimal detectable bias (controlled observations): "
                     f"{_mm(big['mdb_m'])} at {big['station_id']}→{big['marker_id']}.")
    eff = rel["largest_mdb_effect"]
    if eff is not None:
        lines.append(f"- Largest effect of an undetected bias of MDB size on any station or "
                     f"marker position: {_mm(eff['mdb_effect_m'])} "
                     f"({eff['station_id']}→{eff['marker_id']}).")
    kept = [o for o in observations if o["status"] != "removed" and o["mdb_effect_m"] is not None
            and o["mdb_effect_m"] < float("inf")]
    worst = sorted(kept, key=lambda o: (-o["mdb_effect_m"], o["station_id"], o["marker_id"]))
    if worst:
        lines += ["", "Weakest observations (largest MDB effect):", "",
                  "| station | marker | smallest redundancy | largest MDB | MDB effect |",
                  "|---|---|---:|---:|---:|"]
        for o in worst[:10]:
            r = min(o[f"redundancy_{a}"] for a in "xyz")
            mdb = max(o[f"mdb_{a}_m"] for a in "xyz")
            lines.append(f"| {o['station_id']} | {o['marker_id']} | {r:.2f} | {_mm(mdb)} | "
                         f"{_mm(o['mdb_effect_m'])} |")
    return lines + [""]


def _identity(doc: dict) -> list[str]:
    ident = doc["identity"]
    how = {"plan": "gated association with the plan's markers from each station's nominal pose",
           "geometry": "consistent inter-marker distances across stations (no plan)",
           "table": "the marker tables' marker_id column (ids assigned in the field)"}
    lines = ["## Marker identity", "",
             f"{ident['n_identified']} of {ident['n_detections']} accepted detections identified "
             f"by {how.get(ident['method'], ident['method'])}."]
    if ident["unidentified"]:
        counts: dict[tuple[str, str], int] = {}
        for u in ident["unidentified"]:
            key = (u["station_id"], u["reason"].replace("_", " "))
            counts[key] = counts.get(key, 0) + 1
        lines.append("Left out (no marker id): " + ", ".join(
            f"{n} at {s}" + (f" ({why})" if why else "") for (s, why), n in counts.items())
            + "; observations.csv lists only identified detections, adjustment.json all.")
    return lines + [""]


def _provenance(doc: dict) -> list[str]:
    prov = doc["provenance"]
    lines = ["## Inputs and provenance", ""]
    lines += [f"- {i['kind']} `{i['path']}` (sha256 `{i['sha256'][:12]}`)"
              for i in prov.get("inputs", [])]
    lines += [f"- error model: {prov['error_model']}",
              f"- solver: {prov['solver']['name']}, {prov['solver']['status']} after "
              f"{prov['solver']['iterations']} iteration(s)",
              f"- markerplan {prov['markerplan_version']}; configuration sha256 "
              f"`{prov['config_sha256'][:12]}` (adjustment.json holds it in full)", ""]
    return lines
