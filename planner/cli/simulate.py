"""``markerplan simulate``: simulated VLP-16 turntable scans of a site preset."""

from __future__ import annotations

import sys
from dataclasses import asdict
from pathlib import Path

import click

from planner.cli._common import (
    RANGE_NOISE_MM,
    FiniteRange,
    dem_option,
    emit_summary,
    frames_option,
    given_paths,
    json_option,
    lidar_height_option,
    marker_radius_option,
    mounting_offset_options,
    out_option,
    overwrite_option,
    range_noise_option,
    reproject_option,
    require_dem,
    rpm_option,
    seed_option,
    sensor_profile_option,
    site_option,
    site_seed_option,
    station_ids_option,
    stations_option,
)


@click.command("simulate")
@site_option()
@site_seed_option
@dem_option
@reproject_option
@click.option("--dem-fill", type=click.Choice(["nearest"]),
              help="Take NaN/nodata DEM cells as terrain, filled from the nearest valid "
                   "cell (default: they are nodata, where no station or marker may stand).")
@stations_option
@station_ids_option
@marker_radius_option(default_help=" Default: the preset's (0.1).")
@frames_option
@rpm_option
@seed_option()
@lidar_height_option
@mounting_offset_options
@sensor_profile_option
@range_noise_option
@click.option("--incidence-noise-mm", type=RANGE_NOISE_MM, default=None,
              help="Range noise growth with incidence: adds this x tan(incidence) in "
                   "quadrature, mm; overrides the sensor profile's.")
@click.option("--beam-divergence/--no-beam-divergence", default=None,
              help="Model the 3 x 1.5 mrad beam footprint and its mixed returns at marker "
                   "edges; overrides the sensor profile's.")
@click.option("--dropout", "dropout_prob", type=FiniteRange(0.0, 1.0, max_open=True),
              default=None,
              help="Probability that a return is lost; overrides the sensor profile's.")
@out_option(required=True)
@overwrite_option
@json_option
def command(site_name: str, site_seed: int | None, dem_path: Path | None, reproject: bool,
            dem_fill: str | None, stations_path: Path | None, station_ids: tuple[str, ...] | None,
            marker_radius_m: float | None, frames: int, rpm: int, seed: int,
            lidar_height_m: float, offsets, profile, range_noise_mm: float | None,
            incidence_noise_mm: float | None, beam_divergence: bool | None,
            dropout_prob: float | None, out: Path, overwrite: bool, as_json: bool) -> None:
    """Simulate turntable VLP-16 scans of a site: one scan file and one truth file per station.

    Writes station_<id>.scan.npz (pipeline scan format), station_<id>.truth.json (true marker
    centres, station pose, mounting offsets) and site.json (the layout) into --out. The
    preset's markers are scanned; --dem replaces its terrain and --stations its stations (the
    LiDAR centre stands --lidar-height-m above the ground). The sensor's noise, beam footprint and
    the turntable's errors come from --sensor-profile; --range-noise-mm, --incidence-noise-mm,
    --beam-divergence and --dropout override its values.

    \b
    Example:
      markerplan simulate --site default --out scans/
      markerplan simulate --station-ids S1,S2 --frames 200 --axis-offset-mm 5,-3 --out scans/
      markerplan simulate --dem site.tif --stations stations.csv --marker-radius-m 0.15 --out s/
      markerplan simulate --sensor-profile datasheet --no-beam-divergence --out s/
    """
    from tqdm import tqdm

    from markerplan.output_folder import output_folder
    from planner.problem.inputs import select_stations
    from visibility.simulate import simulate_site, write_site_json

    sensor = profile.sensor_config(rpm, range_noise_m=_metres(range_noise_mm),
                                   incidence_noise_m=_metres(incidence_noise_mm),
                                   beam_divergence=beam_divergence, dropout_prob=dropout_prob)
    rig = profile.rig_config(lidar_height_m=lidar_height_m, frames_per_turn=frames,
                             offsets=offsets)
    require_dem(reproject, dem_path)
    with output_folder(out, overwrite, "simulate",
                       inputs=given_paths(dem_path, stations_path)) as stage:
        site = _site(site_name, site_seed, dem_path, dem_fill, stations_path, marker_radius_m,
                     lidar_height_m, reproject, sensor.max_range_m)
        ids = select_stations(site.station_ids, station_ids)
        with tqdm(total=len(ids) * frames, unit="frame", file=sys.stderr, disable=None,
                  desc="simulate") as bar:
            per_station = simulate_site(site, stage, sensor, rig, seed, ids, progress=bar.update,
                                        sensor_profile=profile.name)
        write_site_json(stage / "site.json", site, rig)
    summary = {"out": str(out), "site": site.name, "stations": per_station,
               "n_points": int(sum(s["n_points"] for s in per_station)), "frames": frames,
               "seed": seed, "sensor_profile": profile.to_dict(), "sensor": asdict(sensor)}
    human = "\n".join(f"{s['station_id']}: {s['n_points']} points -> {out / s['scan']}"
                      for s in per_station)
    emit_summary(summary, as_json, human)


def _metres(mm: float | None) -> float | None:
    """Millimetres to metres, ``None`` (not given) kept."""
    return None if mm is None else mm / 1e3


def _site(site_name, site_seed, dem_path, dem_fill, stations_path, marker_radius_m,
          lidar_height_m, reproject, sight_radius_m):
    """The site to scan: the preset, with the DEM (resampled with ``reproject``; the stations
    are then in its file's CRS), stations and marker radius given. A ``--dem`` is read only
    as far as the stations and markers can be seen (``sight_radius_m``, m: the sensor's
    maximum range), as ``plan`` reads it; with ``reproject``, whole."""
    import numpy as np

    from planner.config import MAX_STATIONS
    from planner.problem.inputs import place_stations, read_points
    from visibility.sites import (
        load_site,
        site_with_dem,
        site_with_marker_radius,
        site_with_stations,
    )

    site = load_site(site_name, seed=site_seed)
    points = (None if stations_path is None
              else read_points(stations_path, "`stations_path`", MAX_STATIONS))
    dem = site.dem if dem_path is None else _site_dem(dem_path, dem_fill, reproject, site,
                                                      points, sight_radius_m)
    if points is not None:  # before site_with_dem, which checks the stations it keeps
        ids, xyz, heading = place_stations(points, dem, lidar_height_m)
        if np.any(np.abs(xyz[:, 2] - dem.height_at(xyz[:, :2]) - lidar_height_m) > 1e-3):
            click.echo(f"note: the z_m of --stations {stations_path} are not used: the LiDAR "
                       "centre stands --lidar-height-m above the ground", err=True)
        site = site_with_stations(site, ids, xyz, heading)
    if dem_path is not None:
        site = site_with_dem(site, dem)
    if marker_radius_m is not None:
        site = site_with_marker_radius(site, marker_radius_m)
    return site


def _site_dem(dem_path, dem_fill, reproject, site, station_points, sight_radius_m):
    """``--dem`` read by the window (:func:`planner.problem.inputs.sight_window`) around the
    stations (``station_points`` from the file, else the preset's) and the preset's markers
    it will carry, grown by ``sight_radius_m`` (m); whole with ``reproject`` (the points are
    then in the DEM file's CRS, the markers in the DEM's)."""
    import numpy as np

    from planner.problem.inputs import sight_window
    from visibility.dem import read_dem_by_window

    window = None
    if not reproject:
        stations_xy = (site.station_xy_m if station_points is None
                       else [[p["x_m"], p["y_m"]] for p in station_points])
        window = sight_window(np.vstack([stations_xy, site.marker_centres_m[:, :2]]),
                              sight_radius_m)
    return read_dem_by_window(dem_path, window, dem_fill, f"--dem {dem_path}",
                              reproject=reproject)[0]
