"""Held-out check of an error model against the real simulator and pipeline on crater terrain.

The shipped default model is fitted on the range study (level ground, no mounting offsets).
This study scans the ``default`` site's stations (800 frames, cratered terrain, the rig
mis-mounted and self-calibrated by the pipeline) with a noise seed the model never saw, and
compares every accepted marker's centre error with the model's prediction at the measured
distance and elevation: coverage of the 95 % envelope and the ratio of the RMS error to the
predicted sigma, overall and per distance band.

Usage, from the project root:
    .venv/bin/python benchmarks/error_model_holdout.py [--seed 11] [--replicates 1]
        [--stations 7] [--offsets 0.3,0.3,0.015,0] [--model FILE.json]

Replicate ``i`` scans station ``k`` with noise seed ``seed + 100 i + k``. Prints one line per
distance band and a final JSON object. About 60 s per replicate of 7 stations on two idle
cores.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

BANDS_M = ((0.0, 10.0), (10.0, 15.0), (15.0, 20.0), (20.0, 35.0))


def _band_line(label: str, err: np.ndarray, q95: np.ndarray, sigma: np.ndarray) -> dict:
    cover = float(np.mean(err <= q95)) if err.size else float("nan")
    ratio = float(np.sqrt(np.mean(err ** 2) / np.mean(sigma ** 2))) if err.size else float("nan")
    print(f"  {label:>10}: {err.size:3d} markers, envelope covers {cover:6.1%}, "
          f"RMS error / predicted sigma {ratio:.2f}")
    return {"band": label, "n": int(err.size), "coverage": cover, "rms_over_sigma": ratio}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=11, help="simulation noise seed (held out)")
    ap.add_argument("--replicates", type=int, default=1, help="noise replicates pooled")
    ap.add_argument("--stations", type=int, default=7, help="first N default-site stations")
    ap.add_argument("--offsets", default="0.3,0.3,0.015,0",
                    help="true VERTICAL_AXIS_DEG,LFRAME_TILT_DEG,DX_M,DY_M")
    ap.add_argument("--model", default=None, help="error-model JSON (default: shipped)")
    args = ap.parse_args()

    from error_model import default_model
    from error_model.model import ErrorModel
    from pipeline.chain.evaluation import reference_from_truth
    from pipeline.chain.process import process_station
    from pipeline.chain.stages import build_config
    from pipeline.scans.rig import MountingOffsets
    from visibility.sensor import RigConfig
    from visibility.simulate import simulate_station, site_scene
    from visibility.sites import load_site

    model = ErrorModel.load(args.model) if args.model else default_model()
    v = [float(x) for x in args.offsets.split(",")]
    rig = RigConfig(offsets=MountingOffsets(np.radians(v[0]), np.radians(v[1]), (v[2], v[3])))
    site = load_site("default")
    scene = site_scene(site)
    dist, elev, err = [], [], []
    t0 = time.perf_counter()
    for i, k in np.ndindex(args.replicates, args.stations):
        scan, truth = simulate_station(site, k, rig=rig, seed=args.seed + 100 * i + k,
                                       scene=scene)
        rows = [r for r in process_station(scan, build_config(),
                                           reference_from_truth(truth)).rows
                if r.accepted and r.error_m is not None]
        dist += [r.distance_m for r in rows]
        elev += [np.radians(r.elevation_deg) for r in rows]
        err += [r.error_m for r in rows]
        print(f"replicate {i} {truth['station_id']}: {len(rows)} accepted markers with a "
              "reference")
    dist, elev, err = np.array(dist), np.array(elev), np.array(err)
    pred = model.predict(dist, elev)
    q95, sigma = np.asarray(pred.q95_m), np.asarray(pred.sigma_m)
    inside = np.asarray(pred.in_domain)
    print(f"{err.size} markers, {inside.mean():.0%} inside the model's domain, "
          f"{time.perf_counter() - t0:.0f} s; by distance band:")
    bands = [_band_line(f"{lo:g}-{hi:g} m", err[b], q95[b], sigma[b])
             for lo, hi in BANDS_M for b in [(dist >= lo) & (dist < hi)]]
    overall = _band_line("all", err, q95, sigma)
    print(json.dumps({"seed": args.seed, "replicates": args.replicates,
                      "stations": args.stations, "offsets": v,
                      "n_markers": int(err.size), "in_domain": float(inside.mean()),
                      "overall": overall, "bands": bands}))


if __name__ == "__main__":
    main()
