"""``markerplan fit-sphere``: the centre of one sphere from a point-set file."""

from __future__ import annotations

import click

from planner.cli._common import (
    emit_summary,
    estimator_option,
    json_option,
    marker_radius_option,
    point_option,
    require_option,
)

#: Largest scanner coordinate, m (each of x, y, z): 100,000 km holds any geocentric or
#: selenocentric frame, and squares of it stay far from overflow.
SENSOR_LIMIT_M = 1e8


@click.command("fit-sphere")
@click.argument("file", type=click.Path(dir_okay=False, path_type=str))
@marker_radius_option(required=True)
@point_option("--sensor-m", "0,0,0", "X,Y,Z", "Scanner origin in the file's frame, metres.",
              "sensor", old="--sensor", limit=SENSOR_LIMIT_M)
@estimator_option()
@json_option
def command(file: str, marker_radius_m: float | None, sensor: tuple[float, float, float],
            estimator: str, as_json: bool) -> None:
    """Fit a sphere of known radius to the points in FILE (x y z per line, metres).

    Prints the centre, the RMS residual and the number of points used.

    \b
    Example:
      markerplan fit-sphere SPH101.xyz --marker-radius-m 0.05 --json
    """
    require_option(marker_radius_m, "--marker-radius-m")
    from pipeline.scans.pointsets import read_points
    from pipeline.sphere_centres.sphere_fit import fit_sphere

    points = read_points(file)
    fit = fit_sphere(points, marker_radius_m, sensor_m=sensor, method=estimator)
    summary = {"file": file, "sensor_m": list(sensor), **fit.to_dict()}
    x, y, z = fit.centre_m
    human = (f"centre {x:.6f} {y:.6f} {z:.6f} m  rms {fit.rms_m * 1e3:.3f} mm  "
             f"points used {fit.n_used}/{fit.n_points}  ({estimator})")
    emit_summary(summary, as_json, human)
