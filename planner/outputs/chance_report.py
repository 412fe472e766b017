"""What a plan says of its chance to work: the ``detection`` and ``chance`` sections of
``plan.json`` and their lines in ``report.md``.

A plan made with a detection model (:mod:`planner.problem.detection_odds`) records the model
and every planned station-marker pair's chance of being detected and accepted; its chance
section gives each station's certified chance of passing (:mod:`planner.accuracy.chance`), the
plan's (known control: their product, stations using their own pairs; network mode, where
the stations' figures judge count and directions: the whole network's with its accuracy,
:mod:`planner.accuracy.network_chance`), and the pass rate over sampled detection outcomes
(:mod:`planner.accuracy.sampled_chance`), beside the constraint the plan was made for. In
network mode ``network.judges_local`` says whether each outcome also judged the local
requirement's station pairs and (``local_markers``) marker pairs.
"""

from __future__ import annotations


def chance_sections(outcome) -> dict:
    """``{"detection": ..., "chance": ...}`` of a :class:`~planner.run.PlanOutcome` (empty
    when the plan knew no detection chances)."""
    if outcome.chance is None:
        return {}
    prob, res = outcome.problem, outcome.result
    q = prob.detection_p
    pairs = [{"station": prob.station_ids[s], "site": prob.site_ids[prob.pair_site[p]],
              "probability": round(float(q[p]), 6)}
             for s in range(prob.n_stations) for p in prob.selected_pairs(s, res.selected)]
    chance = outcome.chance
    kinds = [k.family for k in res.model.row_kind]
    whole = outcome.network_chance
    section = {
        "epsilon": chance.epsilon, "station_target": chance.station_target,
        "plan_pass_probability": chance.pass_low if whole is None else whole.pass_low,
        "union_bound_pass_probability": chance.union_pass_low,
        "stations": {prob.station_ids[s]: {"pass_probability": c.pass_low,
                                           "fail_low": c.fail_low, "fail_high": c.fail_high,
                                           "exact": c.exact, "n_markers": c.n_markers}
                     for s, c in enumerate(chance.stations)},
        "cuts": {"chance": kinds.count("chance"),
                 "chance_undecided": kinds.count("chance-undecided"),
                 "chance_count": kinds.count("chance-count"),
                 "chance_critical": kinds.count("chance-critical"),
                 "chance_network": kinds.count("chance-network")},
        "baselines": {name.replace(" ", "_"): p
                      for name, p in outcome.baseline_chances.items()},
    }
    if whole is not None:
        cfg = outcome.config
        section["network"] = {**whole.to_json(), "judges_local": {
            "station_pairs": cfg.local_requirement_m is not None,
            "marker_pairs": cfg.local_requirement_m is not None and bool(cfg.local_markers)}}
    if outcome.sampled is not None:
        section["sampled"] = outcome.sampled.to_json()
    return {"detection": {"model": outcome.detection, "pairs": pairs}, "chance": section}


def chance_markdown(doc: dict) -> list[str]:
    """The report's lines on the plan's chance to work (none without a detection model)."""
    if "chance" not in doc:
        return ["", "## Chance to work", "",
                "No detection model: every planned marker is counted as detected."]
    ch, model = doc["chance"], doc["detection"]["model"]
    eps = ch["epsilon"]
    whole = ch.get("network")
    head = ("Made without a chance constraint (`--chance-epsilon none`)" if eps is None else
            f"Made to fail with chance at most **{eps:g}** (each station at most "
            f"{ch['station_target']:.4g}, a union bound)" if whole is None else
            f"Made to fail with chance at most **{eps:g}** as a whole network, each station's "
            f"count and directions with chance at most {ch['station_target']:.4g}")
    lines = ["", "## Chance to work", "",
             f"{head}, each planned marker detected and accepted with the chance the "
             f"detection model `{model.get('name')}` gives it, independently.", "",
             f"- certified chance that every station passes: "
             f"**{100 * ch['plan_pass_probability']:.2f} %**"
             + ("" if whole is None else
                f" (the whole network with its accuracy: losses of up to "
                f"{whole['max_losses']} of its {whole['n_pairs']} pairs judged, the rest "
                "bounded)" if whole["max_losses"] else
                f" (no certified bound: {whole['n_pairs']:,} pairs are too many to enumerate; "
                "the sampled figure below is the plan's)")]
    judges = (whole or {}).get("judges_local", {})
    if judges.get("station_pairs"):
        lines.append("- every outcome also judges the local requirement's station pairs"
                     + (" and the pairs of the selected markers it still estimates (a marker "
                        "none of whose measurements was detected drops its pairs)"
                        if judges.get("marker_pairs") else ""))
    if "sampled" in ch:
        s = ch["sampled"]
        lines.append(f"- in {s['n_samples']} sampled detection outcomes: "
                     f"{100 * s['pass_rate']:.2f} % passed (Wilson 95 % "
                     f"{100 * s['wilson_95'][0]:.1f}–{100 * s['wilson_95'][1]:.1f} %)")
    for name, p in ch["baselines"].items():
        lines.append(f"- {name.replace('_', ' ')} baseline: {100 * p:.2f} %")
    if ch["cuts"]["chance_undecided"]:
        lines.append(f"- {ch['cuts']['chance_undecided']} chance cut(s) the bounds could not "
                     "prove: the marker count is not proven the fewest")
    lines += ["", "| station | chance of passing"
              + (" (count and directions)" if whole is not None else "") + " | markers |",
              "|---|---:|---:|"]
    for sid, st in ch["stations"].items():
        lines.append(f"| {sid} | {100 * st['pass_probability']:.2f} %"
                     f"{'' if st['exact'] else ' (bound)'} | {st['n_markers']} |")
    return lines
