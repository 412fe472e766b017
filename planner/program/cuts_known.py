"""Known-control mode: valid cuts for the stations a layout fails (no-good and tangent rows)."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from planner.accuracy.checks import StationInfo
from planner.problem.usability import PlanProblem
from planner.program.model import Model, RowKind, info_weights


def accuracy_cuts(problem: PlanProblem, model: Model, selected: np.ndarray, config,
                  infos: list[StationInfo], outer_approximation: bool = False,
                  stations=None) -> tuple[sp.csr_array | None, list[float], list[RowKind]]:
    """Valid cuts for every station whose predicted accuracy fails with ``selected``.

    By default only the combinatorial (no-good) cuts, which stay valid for any looser
    requirement; with ``outer_approximation`` also the tangent cuts (``"oa"``, ``"oa-loss"``,
    ``"info-loss"``, ``"heading-loss"`` rows), valid for ``config.requirement_m`` only.
    ``stations`` (indices, default all) are the stations judged: a joint plan of stations and
    markers (:mod:`planner.program.joint`) judges only those it chose.

    Returns
    -------
    rows : (c, v) sparse or None
        ``None`` when every station passes.
    lower : list of float
        Row lower bounds (upper bounds are +inf).
    kinds : list of RowKind
    """
    rows, lower, kinds = [], [], []
    for s in range(problem.n_stations) if stations is None else stations:
        info = infos[s]
        chosen = info.sites[selected[info.sites]]
        if info.error(chosen) > config.requirement_m:
            grown = info.grow_failing(chosen, None, config.requirement_m)
            rows.append(model.site_row(np.setdiff1d(info.sites, grown)))
            lower.append(1.0)
            kinds.append(RowKind("cut", s))
            for at in (chosen, grown) if outer_approximation else ():
                for oa in info.oa_cuts(at, config.requirement_m, rim="spread"):
                    rows.append(model.site_row(oa[0], oa[1]))
                    lower.append(oa[2])
                    kinds.append(RowKind("oa", s))
            continue
        if not config.redundant:
            continue
        for m in chosen:
            left = chosen[chosen != m]
            if info.error(left) > config.requirement_m:
                grown = info.grow_failing(left, int(m), config.requirement_m)
                rest = np.setdiff1d(info.sites, np.r_[grown, m])
                rows.append(model.implied_row(m, rest))
                lower.append(0.0)
                kinds.append(RowKind("cut-loss", s))
                if not outer_approximation:
                    continue
                for oa in info.oa_cuts(left, config.requirement_m, exclude=int(m)):
                    # if m is selected, the others alone must pass
                    rows.append(model.implied_row(m, oa[0], oa[1], oa[2]))
                    lower.append(0.0)
                    kinds.append(RowKind("oa-loss", s))
                # if m is selected, the others alone must carry the information cuts
                others = np.flatnonzero(problem.pair_site[info.pairs] != m)
                for w, name in zip(info_weights(problem, info.pairs[others], config),
                                   ("info", "heading"), strict=True):
                    rows.append(model.implied_row(m, info.sites[others], w))
                    lower.append(0.0)
                    kinds.append(RowKind(f"{name}-loss", s))
    block = sp.csr_array(sp.vstack(rows)) if rows else None
    return block, lower, kinds

