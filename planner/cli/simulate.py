"""``markerplan simulate``: simulated VLP-16 turntable scans of a site preset."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from planner.cli._common import (
    FRAMES,
    RANGE_NOISE_MM,
    RPM,
    SEED,
    FiniteRange,
    emit_summary,
    given_paths,
    json_option,
    mounting_offset_options,
    mounting_offsets,
    out_option,
    overwrite_option,
)


def _select_stations(site_ids: list[str], text: str | None) -> list[str]:
    """``--stations``: a count (first N stations) or comma-separated ids."""
    from markerplan.errors import ConfigError

    if text is None:
        return list(site_ids)
    text = text.strip()
    if text.isdigit():
        n = int(text)
        if not 1 <= n <= len(site_ids):
            raise ConfigError(f"--stations count must be 1..{len(site_ids)}, got {n}")
        return list(site_ids[:n])
    ids = [s.strip() for s in text.split(",") if s.strip()]
    unknown = [s for s in ids if s not in site_ids]
    if unknown or not ids:
        raise ConfigError(f"--stations: unknown station id(s) {', '.join(unknown) or text!r}; "
                          f"valid ids are {', '.join(site_ids)} (or give a count)")
    return ids


@click.command("simulate")
@click.option("--site", "site_name", default="default", show_default=True,
              help="Site preset: default (40 m crater field) or large (300 m).")
@click.option("--site-seed", type=SEED, default=0, show_default=True,
              help="Seed of the synthetic terrain.")
@click.option("--dem", "dem_path", type=click.Path(dir_okay=False, path_type=Path),
              help="Use this DEM (.tif/.tiff/.npz, site-frame metres) instead of the preset's "
                   "terrain; the preset's stations and markers are placed on it.")
@click.option("--dem-fill", type=click.Choice(["nearest"]),
              help="Fill NaN/nodata DEM cells (default: refuse them).")
@click.option("--stations", help="Station ids (S1,S3) or a count (first N). Default: all.")
@click.option("--frames", type=FRAMES, default=800, show_default=True,
              help="Frames per turntable revolution.")
@click.option("--rpm", type=RPM, default=600, show_default=True,
              help="VLP-16 spin rate, 300-1200 in steps of 60.")
@click.option("--seed", type=SEED, default=0, show_default=True, help="Simulation noise seed.")
@click.option("--lidar-height", "lidar_height_m", type=FiniteRange(0.1, 10.0),
              default=1.0, show_default=True,
              help="LiDAR centre above the ground, metres.")
@mounting_offset_options
@click.option("--range-noise-mm", type=RANGE_NOISE_MM, default=15.0, show_default=True,
              help="1-sigma range noise, mm (datasheet +-3 cm read as 2 sigma).")
@click.option("--incidence-noise-mm", type=RANGE_NOISE_MM, default=0.0, show_default=True,
              help="Extra noise x tan(incidence), mm.")
@click.option("--beam-divergence", is_flag=True,
              help="Sample returns inside the 3 x 1.5 mrad beam footprint.")
@click.option("--dropout", "dropout_prob", type=FiniteRange(0.0, 1.0, max_open=True),
              default=0.0, show_default=True,
              help="Probability that a return is lost.")
@out_option(required=True)
@overwrite_option
@json_option
def command(site_name: str, site_seed: int, dem_path: Path | None, dem_fill: str | None,
            stations: str | None, frames: int, rpm: int, seed: int, lidar_height_m: float,
            vertical_axis_error_deg: float, lframe_tilt_deg: float, axis_offset_mm: str,
            range_noise_mm: float, incidence_noise_mm: float, beam_divergence: bool,
            dropout_prob: float, out: Path, overwrite: bool, as_json: bool) -> None:
    """Simulate turntable VLP-16 scans of a site: one scan file and one truth file per station.

    Writes station_<id>.scan.npz (pipeline scan format), station_<id>.truth.json (true marker
    centres, station pose, mounting offsets) and site.json (the layout) into --out.

    \b
    Example:
      markerplan simulate --site default --out scans/
      markerplan simulate --stations S1,S2 --frames 200 --axis-offset-mm 5,-3 --out scans/ --json
    """
    from tqdm import tqdm

    from markerplan.output_folder import output_folder
    from visibility.dem import read_dem
    from visibility.sensor import RigConfig, SensorConfig
    from visibility.simulate import simulate_site, write_site_json
    from visibility.sites import load_site, site_with_dem

    offsets = mounting_offsets(vertical_axis_error_deg, lframe_tilt_deg, axis_offset_mm)
    sensor = SensorConfig(rpm=rpm, range_noise_m=range_noise_mm / 1e3,
                          incidence_noise_m=incidence_noise_mm / 1e3,
                          beam_divergence=beam_divergence, dropout_prob=dropout_prob)
    rig = RigConfig(lidar_height_m=lidar_height_m, frames_per_turn=frames, offsets=offsets)
    with output_folder(out, overwrite, "simulate", inputs=given_paths(dem_path)) as stage:
        site = load_site(site_name, seed=site_seed)
        if dem_path is not None:
            site = site_with_dem(site, read_dem(
                dem_path, fill=dem_fill, what=f"--dem {dem_path}",
                nodata_fix="pass --dem-fill nearest, or fill them (e.g. gdal_fillnodata.py) "
                           "or crop the DEM"))
        ids = _select_stations(site.station_ids, stations)
        with tqdm(total=len(ids) * frames, unit="frame", file=sys.stderr, disable=None,
                  desc="simulate") as bar:
            per_station = simulate_site(site, stage, sensor, rig, seed, ids, progress=bar.update)
        write_site_json(stage / "site.json", site, rig)
    summary = {"out": str(out), "site": site.name, "stations": per_station,
               "n_points": int(sum(s["n_points"] for s in per_station)), "frames": frames,
               "seed": seed}
    human = "\n".join(f"{s['station_id']}: {s['n_points']} points -> {out / s['scan']}"
                      for s in per_station)
    emit_summary(summary, as_json, human)
