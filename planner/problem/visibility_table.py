"""The visibility table: plan from station-site pairs computed elsewhere (``--visibility FILE``).

A CSV with one row per station-site pair and the columns

==================  =========================================================================
``station``         station id (must match the plan's stations)
``site``            candidate-site id
``usable``          1/0 (or true/false): whether the pair may be counted on
``bearing_deg``     bearing of the site from the station, site frame, degrees counter-clockwise
                    from +x
``sigma_m``         1-sigma 3D marker-centre error for the pair, metres
``site_x_m``        site-frame marker centre x, metres
``site_y_m``        site-frame marker centre y, metres
``site_z_m``        site-frame marker centre z, metres
``distance_m``      optional: LiDAR-centre-to-marker distance, metres (computed when absent)
==================  =========================================================================

The marker coordinates are needed for the heading lever arm in the accuracy model and for the
output files. A site's coordinates must agree on every row that names it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from markerplan.errors import InputFileError
from markerplan.reading import finite_number, read_csv
from planner.problem.usability import OCCLUDED, USABLE, PlanProblem

REQUIRED = ("station", "site", "usable", "bearing_deg", "sigma_m", "site_x_m", "site_y_m",
            "site_z_m")
_TRUE = {"1", "true", "yes", "y", "t"}
_FALSE = {"0", "false", "no", "n", "f"}
#: Most rows (station-site pairs) accepted.
MAX_ROWS = 5_000_000
#: Largest magnitude of ``bearing_deg``, degrees.
MAX_ABS_BEARING_DEG = 720.0
#: Largest ``sigma_m`` accepted, m (a marker known to worse than this is no marker).
MAX_SIGMA_M = 10.0


def read_visibility_table(path: str | Path, station_ids, station_xyz) -> PlanProblem:
    """Read a visibility table into a :class:`~planner.problem.usability.PlanProblem`.

    Parameters
    ----------
    path : str or Path
        The CSV file (columns above).
    station_ids : sequence of str, (s,)
        The plan's stations.
    station_xyz : (s, 3) float
        Their LiDAR centres, site frame, m.

    Raises
    ------
    InputFileError
        Missing, unreadable or non-UTF-8 file, missing columns, ragged rows, unknown station,
        empty site id, numbers that are not finite or beyond their bounds (coordinates and
        ``distance_m``: :data:`~markerplan.reading.MAX_ABS_COORDINATE_M`; ``bearing_deg``:
        :data:`MAX_ABS_BEARING_DEG`; ``sigma_m``: (0, :data:`MAX_SIGMA_M`]), a negative
        distance, inconsistent site coordinates, a repeated pair, no rows or more than
        :data:`MAX_ROWS` — naming the file, the line and the fix.
    """
    where = f"`visibility_path` {path}"
    header, cells = read_csv(path, where, required=REQUIRED,
                             fix=f"required: {', '.join(REQUIRED)}")
    if not cells:
        raise InputFileError(f"{where}: no rows; give at least one station-site pair")
    if len(cells) > MAX_ROWS:
        raise InputFileError(f"{where}: {len(cells)} rows, more than the {MAX_ROWS} accepted; "
                             "drop pairs beyond the LiDAR's range")
    station_xyz = np.asarray(station_xyz, float)
    st_pos = {sid: k for k, sid in enumerate(station_ids)}
    site_pos: dict[str, int] = {}
    site_xyz: list[tuple[float, float, float]] = []
    ps, pj, bearing, sigma, usable, dist = [], [], [], [], [], []
    for n, cells_n in enumerate(cells, start=2):
        row = {h: c.strip() for h, c in zip(header, cells_n, strict=True)}
        line = f"{where} line {n}"
        sid = row["station"]
        if sid not in st_pos:
            raise InputFileError(f"{line}: unknown station {sid!r:.40}; the plan's stations "
                                 f"are {', '.join(station_ids)}")
        site = row["site"]
        if not site:
            raise InputFileError(f"{line}: the site id is empty; give every row a site id")
        xyz = tuple(finite_number(row[c], f"{line}: {c}") for c in
                    ("site_x_m", "site_y_m", "site_z_m"))
        b = np.radians(finite_number(row["bearing_deg"], f"{line}: bearing_deg",
                                     MAX_ABS_BEARING_DEG))
        s = finite_number(row["sigma_m"], f"{line}: sigma_m", MAX_SIGMA_M)
        if s <= 0:
            raise InputFileError(f"{line}: sigma_m must be > 0, got {row['sigma_m']!r:.40}; "
                                 "give the pair's 1-sigma error in metres")
        d = None
        if row.get("distance_m", ""):
            d = finite_number(row["distance_m"], f"{line}: distance_m")
            if d < 0:
                raise InputFileError(f"{line}: distance_m must be >= 0, got "
                                     f"{row['distance_m']!r:.40}; give the distance in metres")
        u = row["usable"].lower()
        if u not in _TRUE | _FALSE:
            raise InputFileError(f"{line}: usable must be 1/0 or true/false, got "
                                 f"{row['usable']!r:.40}")
        if site not in site_pos:
            site_pos[site] = len(site_xyz)
            site_xyz.append(xyz)
        elif not np.allclose(site_xyz[site_pos[site]], xyz, atol=1e-6):
            raise InputFileError(f"{line}: site {site!r:.40} has coordinates {xyz} here "
                                 f"but {site_xyz[site_pos[site]]} earlier; one site, one place")
        k = st_pos[sid]
        ps.append(k)
        pj.append(site_pos[site])
        bearing.append(b)
        sigma.append(s)
        usable.append(u in _TRUE)
        dist.append(d if d is not None
                    else float(np.linalg.norm(np.subtract(xyz, station_xyz[k]))))
    pairs = set(zip(ps, pj, strict=True))
    if len(pairs) != len(ps):
        raise InputFileError(f"{where}: some station-site pair appears twice; keep one row each")
    n_sites = len(site_xyz)
    return PlanProblem(
        station_ids=tuple(station_ids), station_xyz=np.asarray(station_xyz, float),
        site_ids=tuple(site_pos), site_xyz=np.asarray(site_xyz, float),
        site_existing=np.zeros(n_sites, bool), site_cost=np.ones(n_sites),
        pair_station=np.asarray(ps, np.int64), pair_site=np.asarray(pj, np.int64),
        pair_distance_m=np.asarray(dist, float), pair_bearing_rad=np.asarray(bearing, float),
        pair_sigma_m=np.asarray(sigma, float),
        pair_reason=np.where(usable, USABLE, OCCLUDED).astype(np.int8))
