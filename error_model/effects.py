"""Each predictor's effect on the fitted sigma and envelope (the "multivariate analysis").

Every effect is a linear functional ``g @ b`` of a coefficient vector, so its bootstrap
interval comes from the coefficient replicates at no extra fitting cost:

- distance: change per 10 m, the mean slope over the fitted distance range at the median
  ``|elevation|``;
- elevation: change per 10 deg of ``|elevation|``, the mean slope over the fitted range at the
  median distance;
- visible_fraction: change when the visible fraction drops from 1.0 to 0.5;
- expected_points: change when the point count drops from its median to a quarter of it.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from error_model.basis import Basis, transform_extra


def effect_vectors(basis: Basis, distance_m: np.ndarray, elevation_rad: np.ndarray,
                   extras: Mapping[str, np.ndarray]) -> dict[str, tuple[str, np.ndarray]]:
    """Functionals ``g`` (one per predictor) with their description.

    Parameters
    ----------
    basis : Basis
    distance_m, elevation_rad : (n,) float
        Fitted rows (fix the reference ranges and medians).
    extras : mapping of str -> (n,) float

    Returns
    -------
    effects : dict of str -> (description, (p,) float)
        Predictors whose fitted range is a single value are left out.
    """
    a = np.abs(elevation_rad)
    ref = {k: np.array([np.median(v)]) for k, v in extras.items()}
    d_med, a_med = np.median(distance_m), np.median(a)
    d_lo, d_hi = float(distance_m.min()), float(distance_m.max())
    a_lo, a_hi = float(a.min()), float(a.max())
    out: dict[str, tuple[str, np.ndarray]] = {}
    if d_hi > d_lo:
        g = (basis.design([d_hi], [a_med], ref) - basis.design([d_lo], [a_med], ref))[0]
        out["distance"] = (f"change per 10 m (mean slope over {d_lo:.3g}-{d_hi:.3g} m at "
                           f"|elevation| {np.rad2deg(a_med):.3g} deg)", 10.0 * g / (d_hi - d_lo))
    if a_hi > a_lo:
        g = (basis.design([d_med], [a_hi], ref) - basis.design([d_med], [a_lo], ref))[0]
        out["elevation"] = (f"change per 10 deg of |elevation| (mean slope over "
                            f"{np.rad2deg(a_lo):.3g}-{np.rad2deg(a_hi):.3g} deg at "
                            f"{d_med:.3g} m)", np.deg2rad(10.0) * g / (a_hi - a_lo))
    for i, name in enumerate(basis.extras):
        col = basis.n_features - len(basis.extras) + i
        if name == "visible_fraction":
            lo, hi, text = 1.0, 0.5, "change when the visible fraction drops from 1.0 to 0.5"
        else:
            n_med = float(np.median(extras[name]))
            lo, hi = n_med, n_med / 4
            text = f"change when the point count drops from {n_med:.4g} to {hi:.4g}"
        g = np.zeros(basis.n_features)
        g[col] = (transform_extra(name, np.array([hi])) - transform_extra(name, np.array([lo])))[0]
        out[name] = (text, g)
    return out
