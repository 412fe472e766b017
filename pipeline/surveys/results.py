"""The output tables of ``markerplan process``: ``markers.csv``, ``stations.csv``,
``edges.csv`` and ``summary.json`` (values spelled by :mod:`markerplan.writing`)."""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from markerplan.writing import json_default, write_csv
from pipeline.chain.process import StationResult
from pipeline.tables.marker_table import write_marker_table

STATION_COLUMNS = ("station_id", "n_points", "n_frames", "n_candidates", "n_accepted",
                   "n_reference", "n_matched_accepted", "mean_error_m", "max_error_m",
                   "n_edges", "mean_abs_edge_residual_m", "rms_edge_residual_m", "calibrated",
                   "vertical_axis_error_deg", "sigma_vertical_axis_error_deg",
                   "lframe_tilt_deg", "sigma_lframe_tilt_deg", "axis_offset_x_m",
                   "axis_offset_y_m", "sigma_axis_offset_x_m", "sigma_axis_offset_y_m",
                   "n_spheres", "axis_offset_estimate_x_m", "axis_offset_estimate_y_m",
                   "axis_offset_chi2", "axis_offset_resolved")
EDGE_COLUMNS = ("station_id", "marker_a", "marker_b", "reference_length_m",
                "estimated_length_m", "residual_m")


def station_record(result: StationResult) -> dict[str, Any]:
    """One ``stations.csv`` row (degrees at this edge only)."""
    s, c = result.summary, result.calibration
    sig_ax = c.get("sigma_axis_offset_m", [None, None])
    est = c.get("axis_offset_estimate_m", [None, None])
    deg = (lambda v: None if v is None else float(np.degrees(v)))  # noqa: E731
    return {
        **{k: s.get(k) for k in STATION_COLUMNS[:12]},
        "calibrated": c["enabled"],
        "vertical_axis_error_deg": deg(result.offsets.vertical_axis_error_rad),
        "sigma_vertical_axis_error_deg": deg(c.get("sigma_vertical_axis_error_rad")),
        "lframe_tilt_deg": deg(result.offsets.lframe_tilt_rad),
        "sigma_lframe_tilt_deg": deg(c.get("sigma_lframe_tilt_rad")),
        "axis_offset_x_m": result.offsets.axis_offset_m[0],
        "axis_offset_y_m": result.offsets.axis_offset_m[1],
        "sigma_axis_offset_x_m": sig_ax[0], "sigma_axis_offset_y_m": sig_ax[1],
        "n_spheres": c.get("n_spheres"),
        "axis_offset_estimate_x_m": est[0], "axis_offset_estimate_y_m": est[1],
        "axis_offset_chi2": c.get("axis_offset_chi2"),
        "axis_offset_resolved": c.get("axis_offset_resolved"),
    }


def write_results(folder, results: list[StationResult], prov: dict[str, Any],
                  other_files: Sequence[str] = ()) -> dict[str, Any]:
    """Write ``markers.csv``, ``stations.csv``, ``edges.csv`` and ``summary.json``.

    Parameters
    ----------
    folder : path-like
        Existing output folder.
    results : list of StationResult
    prov : dict
        :func:`markerplan.provenance.provenance` record.
    other_files : sequence of str
        Files the command wrote into ``folder`` besides these (e.g. point clouds), listed in
        ``summary.json`` after them.

    Returns
    -------
    summary : dict
        The content of ``summary.json``.
    """
    folder = Path(folder)
    write_marker_table(folder / "markers.csv", [r for res in results for r in res.rows])
    write_csv(folder / "stations.csv", STATION_COLUMNS, [station_record(res) for res in results])
    write_csv(folder / "edges.csv", EDGE_COLUMNS, [e for res in results for e in res.edges])
    summary = {"stations": [res.summary for res in results],
               "files": ["markers.csv", "stations.csv", "edges.csv", "summary.json",
                         *other_files],
               "provenance": prov}
    (folder / "summary.json").write_text(json.dumps(summary, indent=1, sort_keys=True,
                                                    default=json_default) + "\n")
    return summary

