"""The curvature bias through ``verify --network``'s chain: ray-cast scans of a rover levelled to
the Moon's vertical, processed, identified and adjusted with a plane and with a curved prior.

``benchmarks/curvature_bias.py`` shows the bias on the network simulator's observations; this
shows it on the scan simulator's, through the code ``markerplan verify --network --body``
runs: :func:`planner.verify.network.scan_plan` (every station ray-cast by
:func:`visibility.simulate.simulate_markers` at its planned pose, tilted by the local
vertical's deflection ``d / R`` away from the datum station, :mod:`planner.verify.levelling`;
then :func:`pipeline.chain.process.process_station`) and :func:`planner.verify.network.verify_scan`
(association with the plan's markers, network adjustment, comparison with the truth), once
with the adjustment's tilt prior on the plane (roll, pitch ``0 +- 0.01 deg``: earlier
versions) and once on the same body as the simulator.

The site: a straight traverse of ``--stations`` stations ``--spacing`` m apart heading along
it (the datum station first, at the origin: the tangent point), a marker ``--offset`` m either
side of each station and of each midpoint between two, on flat ground (the site frame's
plane: the ground's own curvature, the sagitta, does not enter the tilt priors). The lightest
real path: a noise-free sensor (no range noise, no beam footprint, a perfect turntable; the
2 mm range resolution remains) and ``--frames`` frames per turntable revolution instead of
800, so that a 400 m traverse takes about a minute; the markers are larger than the shipped
0.1 m for the same reason.

Expected (``benchmarks/curvature_bias.py``'s analysis): with the plane prior the network
comes out rotated about the datum by the mean deflection, and the far end is off vertically
by ``D^2 / 2R`` (41.8 mm at 381 m on the Moon); with the curved prior the bias is gone. What
remains is the noise-free chain's own error (the sphere fits of a few hundred points each,
chained through 20 stations: a few mm, mostly across the traverse, as with a level rover:
``--baseline``).

Usage: ``python benchmarks/curvature_verify.py [--stations 20] [--spacing 20] [--frames 200]
[--radius-km 1737.4] [--baseline]``; prints the far station's and the far marker's errors for
each prior.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import tempfile
import time
from pathlib import Path

import numpy as np

from visibility.sensor_profile import SensorProfile


@dataclasses.dataclass(frozen=True)
class FewFrames(SensorProfile):
    """A sensor profile whose rig turns ``frames_per_turn`` frames per revolution."""

    frames_per_turn: int = 800

    def rig_config(self, **settings):
        return super().rig_config(frames_per_turn=self.frames_per_turn, **settings)


def quiet_profile(frames_per_turn: int) -> FewFrames:
    """Noise-free sensor and turntable, ``frames_per_turn`` frames per revolution."""
    from visibility.sensor import SensorConfig

    return FewFrames("quiet", "noise-free, few frames (benchmarks/curvature_verify.py)",
                     SensorConfig(range_noise_m=0.0, beam_divergence=False),
                     frames_per_turn=frames_per_turn)


def traverse_plan(folder: Path, n_stations: int, spacing_m: float, offset_m: float = 4.0,
                  marker_radius_m: float = 0.2) -> Path:
    """Write a flat DEM and the ``plan.json`` of a straight traverse along x (module doc).

    Parameters
    ----------
    folder : Path
    n_stations : int
    spacing_m : float
        Between consecutive stations, m.
    offset_m : float
        Markers' distance either side of the line, m.
    marker_radius_m : float

    Returns
    -------
    plan_path : Path
    """
    from visibility.dem import DEM, write_dem

    length = (n_stations - 1) * spacing_m
    cell = 0.25
    nx, ny = int(np.ceil((length + 60.0) / cell)) + 1, int(np.ceil(2 * (offset_m + 30.0) / cell))
    dem_path = write_dem(folder / "flat.npz", DEM(np.zeros((ny, nx)),
                                                  (-30.0, -(offset_m + 30.0)), cell))
    x = spacing_m * np.arange(n_stations)
    along = np.arange(0.0, length + spacing_m / 4, spacing_m / 2)
    markers = [(a, side * offset_m, marker_radius_m) for a in along for side in (1, -1)]
    doc = {
        "schema": "markerplan-plan", "schema_version": 1,
        "site": {"name": "default", "seed": 0, "marker_radius_m": marker_radius_m},
        "requirement": {"requirement_m": 0.1, "working_radius_m": 10.0},
        "provenance": {"config_sha256": "0" * 64, "inputs": {"dem": str(dem_path)},
                       "config": {"inclinometer_sigma_deg": 0.01}},
        "markers": [{"id": f"M{j + 1:03d}", "x_m": float(mx), "y_m": float(my), "z_m": float(mz)}
                    for j, (mx, my, mz) in enumerate(markers)],
        "stations": [{"id": f"S{i + 1:02d}", "x_m": float(xi), "y_m": 0.0, "z_m": 1.0,
                      "heading_rad": 0.0} for i, xi in enumerate(x)]}
    path = folder / "plan.json"
    path.write_text(json.dumps(doc, indent=1))
    return path


def verify_curved(plan_path: Path, simulated, priors: dict, frames_per_turn: int = 200,
                  seed: int = 0) -> dict:
    """Scan the plan once with the rover levelled to ``simulated`` (a Body) and verify that one
    scan with each body of ``priors`` (name -> Body) as the adjustment's tilt prior.

    Returns
    -------
    figures : dict
        Per prior name: ``far_station_error_m`` (the last station's achieved error),
        ``far_marker_dxyz_m`` (the farthest marker's adjusted minus true centre, (3,)),
        ``far_marker_dz_m`` (its z), ``sigma0_squared``,
        ``n_rejected``, ``body`` (the prior's name); plus ``scan_s``, the time of the scans,
        and ``truth_tilt_rad``, the simulator's roll and pitch of every station.
    """
    from error_model import default_model
    from planner.outputs.plan_file import load_plan, read_plan
    from planner.verify.network import NetworkVerifySettings, scan_plan, verify_scan

    plan = load_plan(plan_path)
    doc = read_plan(plan_path, "PLAN", full=True)
    t0 = time.perf_counter()
    scanned = scan_plan(plan, seed, progress=False, profile=quiet_profile(frames_per_turn),
                        body=simulated)
    out: dict = {"scan_s": time.perf_counter() - t0,
                 "truth_tilt_rad": {sid: t.pose[4:].tolist() for sid, t in scanned[1].items()}}
    far = max(range(len(plan.marker_ids)), key=lambda j: plan.marker_xyz_m[j, 0])
    for name, body in priors.items():
        with tempfile.TemporaryDirectory() as tmp:
            check = verify_scan(scanned, Path(tmp) / "markers.csv", plan_path, doc,
                                default_model(), "default", NetworkVerifySettings(body=body),
                                seed=seed)
        marker = {m.marker_id: m for m in check.markers}.get(plan.marker_ids[far])
        out[name] = {"far_station_error_m": check.stations[-1].achieved_error_m,
                     "far_marker_dxyz_m": None if marker is None else marker.achieved_xyz_m,
                     "far_marker_dz_m": None if marker is None else marker.achieved_xyz_m[2],
                     "sigma0_squared": check.sigma0_squared,
                     "n_rejected": len(check.rejected),
                     "body": check.config["body"]["name"]}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--stations", type=int, default=20)
    ap.add_argument("--spacing", type=float, default=20.0, help="m between stations")
    ap.add_argument("--frames", type=int, default=200, help="frames per turntable revolution")
    ap.add_argument("--radius-km", type=float, default=None,
                    help="a sphere of this radius instead of the Moon")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--baseline", action="store_true",
                    help="also scan with a level rover (the plane) and adjust with the plane "
                         "prior: the chain's own error without curvature")
    args = ap.parse_args()

    from pipeline.network.body import Body

    body = (Body.named("moon") if args.radius_km is None
            else Body("sphere", 1e3 * args.radius_km))
    with tempfile.TemporaryDirectory() as tmp:
        plan_path = traverse_plan(Path(tmp), args.stations, args.spacing)
        figures = verify_curved(plan_path, body, {"plane prior": Body(),
                                                  f"curved prior ({body.name})": body},
                                args.frames, args.seed)
        if args.baseline:
            level = verify_curved(plan_path, Body(), {"plane prior": Body()}, args.frames,
                                  args.seed)
            figures["level rover, plane prior"] = level["plane prior"]
    length = (args.stations - 1) * args.spacing
    print(f"site: {args.stations} stations {args.spacing:g} m apart in a straight line, far "
          f"station {length:.1f} m from the datum (tangent point); rover levelled to "
          f"{body.name} (R {body.radius_m / 1e3:.1f} km); {args.frames} frames per turn, "
          f"noise-free sensor; scans {figures.pop('scan_s'):.1f} s")
    figures.pop("truth_tilt_rad")
    print(f"expected plane-prior vertical bias at the far end D^2/2R = "
          f"{1e3 * length ** 2 / (2 * body.radius_m):.1f} mm")
    for name, f in figures.items():
        d = f["far_marker_dxyz_m"]
        d = "n/a" if d is None else "(" + ", ".join(f"{1e3 * v:+.1f}" for v in d) + ")"
        print(f"{name:>24}: far station achieved error {1e3 * f['far_station_error_m']:.1f} mm; "
              f"far marker error (dx, dy, dz) {d} mm; sigma0^2 "
              f"{f['sigma0_squared']:.3f}; {f['n_rejected']} removed by snooping")


if __name__ == "__main__":
    main()
