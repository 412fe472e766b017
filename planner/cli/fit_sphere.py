"""``markerplan fit-sphere``: the centre of one sphere from a point-set file."""

from __future__ import annotations

import click

from planner.cli._common import emit_summary, json_option, parse_numbers

_METHODS = ("fixed-radius", "hemisphere-icp")


@click.command("fit-sphere")
@click.argument("file", type=click.Path(dir_okay=False, path_type=str))
@click.option("--radius", "radius_m", type=float, required=True,
              help="Known sphere radius, metres (e.g. 0.1 for a 0.20 m marker).")
@click.option("--sensor", default="0,0,0", show_default=True,
              help="Scanner origin X,Y,Z in the file's frame, metres.")
@click.option("--method", type=click.Choice(_METHODS), default="fixed-radius", show_default=True,
              help="Estimator: ASTM E3125-17 line-of-sight fixed-radius fit, or the published "
                   "hemisphere ICP.")
@json_option
def command(file: str, radius_m: float, sensor: str, method: str, as_json: bool) -> None:
    """Fit a sphere of known radius to the points in FILE (x y z per line, metres).

    Prints the centre, the RMS residual and the number of points used.

    \b
    Example:
      markerplan fit-sphere SPH101.xyz --radius 0.05 --json
    """
    from pipeline.pointsets import read_points
    from pipeline.sphere_fit import fit_sphere

    sensor_m = None if sensor is None else parse_numbers(sensor, "--sensor", "0,0,1.0")
    points = read_points(file)
    fit = fit_sphere(points, radius_m, sensor_m=sensor_m, method=method)
    summary = {"file": file, "sensor_m": list(sensor_m), **fit.to_dict()}
    x, y, z = fit.centre_m
    human = (f"centre {x:.6f} {y:.6f} {z:.6f} m  rms {fit.rms_m * 1e3:.3f} mm  "
             f"points used {fit.n_used}/{fit.n_points}  ({method})")
    emit_summary(summary, as_json, human)
