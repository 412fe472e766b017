"""Network-mode studies: what planning a network instead of known control
changes on one site, shared by ``benchmarks/network_studies.py`` and
``notebooks/06_network_mode.py``.

Every study takes a built :class:`~planner.problem.usability.PlanProblem` and a
:class:`~planner.config.PlanConfig`, re-runs :func:`planner.program.plan_sites` with one setting
changed (build, solve and report stay separate) and returns plain, JSON-ready dicts:

- :func:`compare_modes` — (a) the known-control optimum, the network optimum, and the
  known-control optimum judged as a network tied to the reference station;
- :func:`error_vs_distance` — (b) every station's network error against its distance from the
  reference, with a fitted slope in cm per 100 m;
- :func:`tradeoff` — (c) requirement against fewest markers in network mode;
- :func:`heading_prior` — (d) fewest markers and worst error against a heading-prior sigma;
- :func:`baselines` — (e) greedy and regular-grid baselines in network mode against the optimum.

A plan stopped by its time limit is never called optimal: its record keeps the solver status,
the objective, the proven bound and the gap (:func:`plan_text` shows it as ``<= N, bound B``).
Errors are 95 % bounds, m, relative to the reference station (the datum).
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from markerplan.errors import InfeasiblePlanError, PlanTimeLimitError
from markerplan.writing import json_float
from planner.accuracy.checks import evaluate_layout
from planner.problem.usability import PlanProblem
from planner.program import plan_sites
from planner.program.baselines import greedy_network, regular_grid

#: The studies, by letter (as the script's ``--studies`` names them).
STUDIES = {"a": "known control vs network", "b": "error vs distance from the reference",
           "c": "trade-off curve", "d": "heading prior", "e": "baselines"}
#: The key of each study's result in :func:`run_studies`'s document.
_KEYS = {"modes": "a", "distance": "b", "tradeoff": "c", "heading_prior": "d", "baselines": "e"}



def run_plan(problem: PlanProblem, config) -> tuple[dict, np.ndarray | None]:
    """Plan once and summarise.

    Returns
    -------
    record : dict
        ``markers``, ``status``, ``objective``, ``dual_bound``, ``gap``,
        ``worst_station_error_m``, ``worst_marker_error_m`` (network mode; None otherwise),
        ``iterations``, ``time_s``; or ``status`` "infeasible" (no layout meets the
        requirement) or "no_solution" (the time limit ran out before a passing layout was
        found) and ``error`` (the planner's one-line reason).
    selected : (n,) bool or None
        The layout (None when infeasible).
    """
    t = time.perf_counter()
    try:
        r = plan_sites(problem, config)
    except InfeasiblePlanError as exc:
        status = "no_solution" if isinstance(exc, PlanTimeLimitError) else "infeasible"
        return {"status": status, "error": str(exc),
                "time_s": round(time.perf_counter() - t, 2)}, None
    sol = r.solution
    merr = r.check.marker_error_m
    rec = {"markers": int(r.selected.sum()), "status": sol.status,
           "objective": json_float(sol.objective), "dual_bound": json_float(sol.dual_bound),
           "gap": json_float(sol.gap), "worst_station_error_m": json_float(r.check.error_m.max()),
           "worst_marker_error_m": None if merr is None else json_float(np.nanmax(merr)),
           "iterations": r.iterations, "time_s": round(time.perf_counter() - t, 2)}
    return rec, r.selected


def plan_text(rec: dict) -> str:
    """Marker count with its status: ``3 (optimal)``, ``<= 723 (time limit, bound 684, gap 5 %)``,
    ``infeasible`` or ``no layout in the time limit``."""
    if rec.get("markers") is None:
        return {"no_solution": "no layout in the time limit"}.get(rec.get("status"),
                                                                  rec.get("status", "not run"))
    if rec["status"] == "optimal":
        return f"{rec['markers']} (optimal)"
    bound = rec.get("dual_bound")
    gap = rec.get("gap")
    extra = "" if bound is None else f", bound {math.ceil(bound - 1e-6):d}"
    extra += "" if gap is None else f", gap {100 * gap:.0f} %"
    return f"<= {rec['markers']} ({rec['status'].replace('_', ' ')}{extra})"


def judge_as_network(problem: PlanProblem, selected: np.ndarray, config, net) -> dict:
    """A layout judged as ``plan --network`` judges a plan (``config.network`` must be set):
    worst station and marker error (None when some are undetermined: not tied to the reference,
    or heading free), the worst among the determined ones, and how many of each exceed
    ``requirement_m`` (undetermined ones included) or are undetermined. Markers on sites no
    station can use (a regular grid's) are counted in ``markers`` and ``markers_unseen`` but
    not judged, as :func:`planner.program.baselines.regular_grid` does."""
    check = evaluate_layout(problem, selected, config, net=net)
    req = config.requirement_m
    selected = np.asarray(selected, bool)
    merr = check.marker_error_m[selected & (net.n_stations_seeing > 0)]
    serr = check.error_m
    return {"worst_station_error_m": json_float(serr.max()),
            "worst_marker_error_m": json_float(merr.max()) if merr.size else None,
            "worst_determined_station_error_m": json_float(serr[np.isfinite(serr)].max())
            if np.isfinite(serr).any() else None,
            "worst_determined_marker_error_m": json_float(merr[np.isfinite(merr)].max())
            if np.isfinite(merr).any() else None,
            "stations_failing": int(np.sum(serr > req)),
            "markers_failing": int(np.sum(merr > req)),
            "stations_undetermined": int(np.sum(~np.isfinite(serr))),
            "markers_undetermined": int(np.sum(~np.isfinite(merr))),
            "markers_unseen": int(np.sum(selected & (net.n_stations_seeing == 0))),
            "n_stations": problem.n_stations, "markers": int(np.sum(selected))}


def compare_modes(problem: PlanProblem, config, net) -> tuple[dict, dict]:
    """(a) Known-control optimum, network optimum, and the known-control optimum as a network.

    Parameters
    ----------
    problem : PlanProblem
    config : PlanConfig
        Network settings (reference, heading prior) apply; ``network`` is set per mode.
    net : planner.accuracy.network.NetworkModel
        Of ``problem`` and ``config.replace(network=True)``.

    Returns
    -------
    record : dict
        ``known_control``, ``known_control_as_network`` (None when known control is
        infeasible), ``network``.
    layouts : dict of name -> (n,) bool
        ``known_control`` and ``network`` layouts that exist.
    """
    kc, kc_sel = run_plan(problem, config.as_known_control())
    nw, nw_sel = run_plan(problem, config.replace(network=True))
    as_net = None if kc_sel is None else \
        judge_as_network(problem, kc_sel, config.replace(network=True), net)
    layouts = {k: v for k, v in (("known_control", kc_sel), ("network", nw_sel))
               if v is not None}
    return {"known_control": kc, "known_control_as_network": as_net, "network": nw}, layouts


def error_vs_distance(problem: PlanProblem, net, layouts: dict) -> dict:
    """(b) Every station's network error against its horizontal distance from the reference.

    Parameters
    ----------
    net : planner.accuracy.network.NetworkModel
    layouts : dict of name -> (n,) bool

    Returns
    -------
    record : dict
        ``reference``, ``station_ids``, ``distance_m`` (s,), and per layout ``error_m`` (s,)
        and the least-squares line ``slope_cm_per_100m`` and ``intercept_m`` over the
        determined stations (None when fewer than two distinct distances).
    """
    xy = problem.station_xyz[:, :2]
    dist = np.linalg.norm(xy - xy[net.reference], axis=1)
    out = {"reference": problem.station_ids[net.reference],
           "station_ids": list(problem.station_ids),
           "distance_m": [round(float(d), 3) for d in dist], "layouts": {}}
    for name, sel in layouts.items():
        err = net.station_errors(sel)
        fin = np.isfinite(err)
        slope = intercept = None
        if np.unique(np.round(dist[fin], 6)).size >= 2:
            b, a = np.polyfit(dist[fin], err[fin], 1)
            slope, intercept = float(b) * 1e4, float(a)
        out["layouts"][name] = {"error_m": [json_float(e) for e in err],
                                "slope_cm_per_100m": slope, "intercept_m": intercept}
    return out


def tradeoff(problem: PlanProblem, config, requirements_m) -> list[dict]:
    """(c) Fewest markers in network mode at each requirement (one plan per point)."""
    out = []
    for req in requirements_m:
        rec, _ = run_plan(problem, config.replace(network=True, requirement_m=float(req)))
        out.append({"requirement_m": float(req), **rec})
    return out


def heading_prior(problem: PlanProblem, config, sigmas_deg, requirements_m=None,
                  layout: np.ndarray | None = None) -> list[dict]:
    """(d) Fewest markers and worst errors in network mode with a heading prior of each sigma
    (degrees, 1-sigma; None: no prior), at each requirement (default ``config``'s).

    Each plan is re-optimised, so its worst error is that of one of possibly many optimal
    layouts. With ``layout`` ((n,) bool, e.g. the network plan without a prior) every record
    also carries ``same_layout_worst_station_error_m``: that one layout's worst station error
    under the prior, which isolates what the prior itself buys.
    """
    from planner.accuracy.network import network_model

    out = []
    for req in requirements_m or [config.requirement_m]:
        for s in sigmas_deg:
            cfg = config.replace(network=True, requirement_m=float(req),
                                 heading_prior_sigma_deg=None if s is None else float(s))
            rec, _ = run_plan(problem, cfg)
            if layout is not None:
                rec["same_layout_worst_station_error_m"] = json_float(
                    network_model(problem, cfg).station_errors(layout).max())
            out.append({"requirement_m": float(req), "heading_prior_sigma_deg": s, **rec})
    return out


def baselines(problem: PlanProblem, config, net, bounds_xy, optimum: dict | None = None,
              grid_step_m: float = 0.5) -> dict:
    """(e) Greedy (:func:`~planner.program.baselines.greedy_network`) and regular-grid
    (:func:`~planner.program.baselines.regular_grid` in network mode) baselines.

    Parameters
    ----------
    net : planner.accuracy.network.NetworkModel
        Of ``config.replace(network=True)``.
    bounds_xy : (xmin, ymin, xmax, ymax)
        What the grid covers (:func:`planner.run.plan_bounds`).
    optimum : dict, optional
        The network plan's record (:func:`run_plan`), copied into the result.
    grid_step_m : float
        Grid spacings tried: ``max_range_m`` down to ``grid_spacing_m`` in this step.
    """
    cfg = config.replace(network=True)
    out = {"optimum": optimum}
    t = time.perf_counter()
    try:
        g = greedy_network(problem, cfg, net)
        out["greedy"] = {"markers": g.n_markers, "meets_requirement": g.meets_requirement,
                         **_judged(problem, g.selected, cfg, net)}
    except InfeasiblePlanError as exc:
        out["greedy"] = {"markers": None, "meets_requirement": False, "error": str(exc)}
    out["greedy"]["time_s"] = round(time.perf_counter() - t, 2)
    t = time.perf_counter()
    spacings = np.arange(cfg.max_range_m, cfg.grid_spacing_m - 1e-9, -grid_step_m)
    r = regular_grid(problem, cfg, bounds_xy, spacings_m=spacings, net=net)
    out["regular_grid"] = {"markers": r.n_markers, "meets_requirement": r.meets_requirement,
                           "spacing_m": r.spacing_m, **_judged(problem, r.selected, cfg, net),
                           "time_s": round(time.perf_counter() - t, 2)}
    return out


def _judged(problem, selected, cfg, net) -> dict:
    j = judge_as_network(problem, selected, cfg, net)
    return {k: j[k] for k in ("worst_station_error_m", "worst_marker_error_m", "markers_unseen")}


# -- report -------------------------------------------------------------------------------------
def _cm(x) -> str:
    return "-" if x is None else f"{100 * x:.1f}"


def _worst(rec: dict, what: str) -> str:
    """Worst error in cm; ``inf`` (and the worst determined one) when some are undetermined."""
    if rec.get(f"worst_{what}_error_m") is not None or \
            rec.get(f"worst_determined_{what}_error_m") is None:
        return _cm(rec.get(f"worst_{what}_error_m"))
    return f"inf (else {_cm(rec[f'worst_determined_{what}_error_m'])})"


def _table(header: list[str], rows: list[list[str]]) -> list[str]:
    w = [max(len(h), *(len(r[i]) for r in rows)) if rows else len(h)
         for i, h in enumerate(header)]
    line = "  ".join(h.ljust(w[i]) for i, h in enumerate(header))
    return [line, "-" * len(line)] + ["  ".join(c.ljust(w[i]) for i, c in enumerate(r))
                                      for r in rows]


def report_lines(doc: dict, studies: str = "abcde", header: bool = True) -> list[str]:
    """The studies of one site (:func:`run_studies`) as plain-text tables (errors in cm);
    ``studies``: which of them (letters of :data:`STUDIES`) when present in ``doc``."""
    out = [f"site {doc['site']}: {doc['n_stations']} stations, {doc['n_candidates']} candidate "
           f"sites (grid {doc['grid_spacing_m']:g} m), requirement {doc['requirement_m']:g} m, "
           f"reference {doc['reference']}, time limit {doc['time_limit_s']:g} s per plan"] \
        if header else []
    doc = {k: v for k, v in doc.items() if _KEYS.get(k, "") in studies}
    a = doc.get("modes")
    if a:
        kc, nw, asn = a["known_control"], a["network"], a["known_control_as_network"]
        out += ["", "(a) known control vs network mode"]
        rows = [["known control", plan_text(kc), _cm(kc.get("worst_station_error_m")), "-",
                 f"{kc['time_s']:.1f}"]]
        if asn:
            und = [f"{asn[f'{k}s_undetermined']} {k}s" for k in ("station", "marker")
                   if asn.get(f"{k}s_undetermined")]
            rows.append(["known-control plan as a network", str(asn["markers"]),
                         _worst(asn, "station"), _worst(asn, "marker"),
                         f"{asn['stations_failing']}/{asn['n_stations']} stations, "
                         f"{asn['markers_failing']}/{asn['markers']} markers fail"
                         + (f" ({', '.join(und)} undetermined)" if und else "")])
        rows.append(["network mode", plan_text(nw), _cm(nw.get("worst_station_error_m")),
                     _cm(nw.get("worst_marker_error_m")), f"{nw['time_s']:.1f}"])
        out += _table(["plan", "markers", "worst station cm", "worst marker cm",
                       "time s / failing"], rows)
    b = doc.get("distance")
    if b:
        out += ["", f"(b) station error against distance from the reference {b['reference']}"]
        names = list(b["layouts"])
        rows = [[sid, f"{d:.1f}"] + [_cm(b["layouts"][n]["error_m"][i]) for n in names]
                for i, (sid, d) in enumerate(zip(b["station_ids"], b["distance_m"],
                                                 strict=True))]
        rows.sort(key=lambda r: float(r[1]))
        rows.append(["slope cm/100 m", ""] + [
            "-" if b["layouts"][n]["slope_cm_per_100m"] is None
            else f"{b['layouts'][n]['slope_cm_per_100m']:.1f}" for n in names])
        out += _table(["station", "distance m"] + [f"{n} plan cm" for n in names], rows)
    c = doc.get("tradeoff")
    if c:
        out += ["", "(c) trade-off in network mode: requirement vs fewest markers"]
        out += _table(["requirement m", "markers", "worst station cm", "worst marker cm",
                       "time s"],
                      [[f"{p['requirement_m']:g}", plan_text(p),
                        _cm(p.get("worst_station_error_m")),
                        _cm(p.get("worst_marker_error_m")), f"{p['time_s']:.1f}"] for p in c])
    d = doc.get("heading_prior")
    if d:
        out += ["", "(d) heading prior (network mode)"]
        out += _table(["requirement m", "heading prior sigma deg", "markers",
                       "worst station cm", "worst marker cm", "time s",
                       "same layout cm"],
                      [[f"{p['requirement_m']:g}", "none" if p["heading_prior_sigma_deg"] is None
                        else f"{p['heading_prior_sigma_deg']:g}", plan_text(p),
                        _cm(p.get("worst_station_error_m")),
                        _cm(p.get("worst_marker_error_m")), f"{p['time_s']:.1f}",
                        _cm(p.get("same_layout_worst_station_error_m"))] for p in d])
        out.append("(same layout: worst station error of the network plan without a prior, "
                   "judged with each prior)")
    e = doc.get("baselines")
    if e:
        out += ["", "(e) baselines in network mode vs the optimum"]
        rows = []
        if e.get("optimum"):
            o = e["optimum"]
            rows.append(["integer program", plan_text(o), "yes" if o.get("markers") else "no",
                         _cm(o.get("worst_station_error_m")), _cm(o.get("worst_marker_error_m")),
                         f"{o['time_s']:.1f}"])
        g = e["greedy"]
        rows.append(["greedy (network)", str(g["markers"]) if g["markers"] else "failed",
                     "yes" if g["meets_requirement"] else "no",
                     _cm(g.get("worst_station_error_m")), _cm(g.get("worst_marker_error_m")),
                     f"{g['time_s']:.1f}"])
        r = e["regular_grid"]
        spacing = f", {r['spacing_m']:g} m" if r["spacing_m"] else ", no spacing passes"
        unseen = r.get("markers_unseen")
        rows.append([f"regular grid (network{spacing})", str(r["markers"])
                     + (f" ({unseen} unseen)" if unseen else ""),
                     "yes" if r["meets_requirement"] else "no",
                     _cm(r["worst_station_error_m"]), _cm(r["worst_marker_error_m"]),
                     f"{r['time_s']:.1f}"])
        out += _table(["layout", "markers", "meets", "worst station cm", "worst marker cm",
                       "time s"], rows)
    return out


# -- the whole set ------------------------------------------------------------------------------
def run_studies(problem: PlanProblem, config, bounds_xy, requirements_m=(0.06, 0.08, 0.10,
                                                                         0.12, 0.15, 0.20),
                sigmas_deg=(None, 2.0, 1.0, 0.5, 0.1), studies: str = "abcde",
                grid_step_m: float = 0.5, info: dict | None = None,
                prior_requirements_m=None, on_study=None) -> tuple[dict, dict]:
    """Run the chosen studies (letters of :data:`STUDIES`) on one problem.

    ``on_study(letter, doc)``, when given, is called after each study (e.g. to log partial
    results of a long run).

    ``requirements_m``: the trade-off curve's points (c); ``sigmas_deg`` and
    ``prior_requirements_m`` (default ``config.requirement_m``): the heading-prior study (d).

    Returns
    -------
    doc : dict
        JSON-ready: ``modes`` (a), ``distance`` (b), ``tradeoff`` (c), ``heading_prior`` (d),
        ``baselines`` (e) for the studies run, plus ``info`` and the setup.
    layouts : dict of name -> (n,) bool
        Known-control and network plans (for maps and figures).
    """
    from planner.accuracy.network import network_model

    unknown = sorted(set(studies) - set(STUDIES))
    if unknown:
        from markerplan.errors import ConfigError

        raise ConfigError(f"`studies` are letters of {''.join(STUDIES)}, got {studies!r}")
    net_cfg = config.replace(network=True)
    net = network_model(problem, net_cfg)
    doc = {**(info or {}), "n_stations": problem.n_stations,
           "grid_spacing_m": config.grid_spacing_m, "requirement_m": config.requirement_m,
           "time_limit_s": config.time_limit_s, "reference": problem.station_ids[net.reference],
           "heading_prior_sigma_deg": config.heading_prior_sigma_deg, "studies": studies}
    layouts: dict = {}
    done = on_study or (lambda letter, doc: None)
    if {"a", "b", "d", "e"} & set(studies):
        doc["modes"], layouts = compare_modes(problem, config, net)
        done("a", doc)
    if "b" in studies:
        doc["distance"] = error_vs_distance(problem, net, layouts)
        done("b", doc)
    if "c" in studies:
        doc["tradeoff"] = tradeoff(problem, config, requirements_m)
        done("c", doc)
    if "d" in studies:
        doc["heading_prior"] = heading_prior(problem, config, sigmas_deg, prior_requirements_m,
                                             layouts.get("network"))
        done("d", doc)
    if "e" in studies:
        doc["baselines"] = baselines(problem, config, net, bounds_xy, doc["modes"]["network"],
                                     grid_step_m)
        done("e", doc)
    return doc, layouts


# -- figures ------------------------------------------------------------------------------------
def _pyplot():
    # lazy: pyplot takes ~1 s to import, paid only once a figure is drawn
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_error_vs_distance(doc: dict, path: str | Path, dpi: int = 90) -> Path:
    """Scatter of station error against distance from the reference, one series per layout,
    with the fitted lines and the requirement (``doc``: :func:`run_studies`)."""
    plt = _pyplot()
    b = doc["distance"]
    d = np.asarray(b["distance_m"])
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    labels = {"known_control": "known-control plan", "network": "network plan"}
    # the first series hollow and larger, so a second one on the same points stays visible
    styles = ({"marker": "o", "s": 80, "facecolors": "none", "edgecolors": "C0"},
              {"marker": "s", "s": 22, "color": "C1"})
    for c, ((name, lay), style) in enumerate(zip(b["layouts"].items(), styles, strict=False)):
        e = np.array([np.nan if v is None else v for v in lay["error_m"]])
        ax.scatter(d, 100 * e, label=labels.get(name, name), **style)
        if lay["slope_cm_per_100m"] is not None:
            xs = np.array([0.0, d.max()])
            ax.plot(xs, 100 * lay["intercept_m"] + lay["slope_cm_per_100m"] * xs / 100,
                    color=f"C{c}", lw=1, ls="-" if c == 0 else ":",
                    label=f"fit: {lay['slope_cm_per_100m']:.1f} cm per 100 m")
    ax.axhline(100 * doc["requirement_m"], color="k", ls="--", lw=1, label="requirement")
    ax.set_xlabel(f"distance from the reference station {b['reference']} (m)")
    ax.set_ylabel("95 % station error as a network (cm)")
    ax.set_title(f"{doc.get('site', '')}: error against distance from the datum")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return Path(path)


def plot_tradeoff_and_prior(doc: dict, path: str | Path, dpi: int = 90) -> Path:
    """Left (c): requirement against fewest markers in network mode; a time-limited point is
    drawn open (an upper bound), one without a layout as x. Right (d): worst station error
    against the heading-prior sigma, one line per requirement, labelled with the marker
    count, and dotted the no-prior network plan judged with each prior (``doc``:
    :func:`run_studies`)."""
    plt = _pyplot()
    panels = [k for k in ("tradeoff", "heading_prior") if doc.get(k)]
    fig, axes = plt.subplots(1, len(panels), figsize=(5.4 * len(panels), 4.0), squeeze=False)
    for ax, key in zip(axes[0], panels, strict=True):
        pts = doc[key]
        if key == "tradeoff":
            for p in pts:
                x = p["requirement_m"]
                if p.get("markers") is None:
                    ax.plot(x, 0, "x", color="C3")
                else:
                    ax.plot(x, p["markers"], "o", color="C0",
                            mfc="C0" if p["status"] == "optimal" else "none")
            ok = [(p["requirement_m"], p["markers"]) for p in pts if p.get("markers")]
            if ok:
                ax.plot(*zip(*ok, strict=True), color="C0", lw=1)
            ax.set_xlabel("requirement (m)")
            ax.set_ylabel("fewest markers (network mode)")
            ax.set_ylim(bottom=0)
            ax.set_title("trade-off: filled optimal, open time limit, x none", fontsize=9)
            continue
        sig = list(dict.fromkeys(p["heading_prior_sigma_deg"] for p in pts))
        for c, req in enumerate(dict.fromkeys(p["requirement_m"] for p in pts)):
            row = [p for p in pts if p["requirement_m"] == req]
            xs = [sig.index(p["heading_prior_sigma_deg"]) for p in row]
            ys = [np.nan if p.get("worst_station_error_m") is None
                  else 100 * p["worst_station_error_m"] for p in row]
            ax.plot(xs, ys, "o-", color=f"C{c}", label=f"requirement {req:g} m")
            same = [p.get("same_layout_worst_station_error_m") for p in row]
            if c == 0 and all(v is not None for v in same):
                ax.plot(xs, [100 * v for v in same], "k:", lw=1,
                        label="the no-prior network plan, judged with the prior")
            for x, y, p in zip(xs, ys, row, strict=True):
                if np.isfinite(y):
                    ax.annotate(plan_text(p).split(" (")[0], (x, y), fontsize=7,
                                xytext=(3, 3), textcoords="offset points")
        ax.set_xticks(range(len(sig)), ["none" if v is None else f"{v:g}" for v in sig])
        ax.set_xlabel("heading prior sigma (deg)")
        ax.set_ylabel("worst station error (cm)")
        ax.set_ylim(bottom=0)
        ax.set_title("heading prior: labels = markers", fontsize=9)
        ax.legend(fontsize=8)
    fig.suptitle(f"{doc.get('site', '')}: network mode", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return Path(path)
