import csv
from pathlib import Path

import numpy as np
import pytest

from markerplan.errors import InputFileError
from planner.config import PlanConfig
from planner.problem.usability import USABLE, PlanProblem
from planner.problem.visibility_table import REQUIRED, read_visibility_table
from planner.program import plan_sites
from tests.planner.instances import make_problem, ring


def write_visibility_table(path: str | Path, problem: PlanProblem) -> Path:
    """Write a problem's pairs as a visibility table (a user's table, as the round trip
    through :func:`read_visibility_table` needs; non-usable reasons become ``usable = 0``)."""
    path = Path(path)
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow([*REQUIRED, "distance_m"])
        for k in range(problem.pair_station.size):
            j = problem.pair_site[k]
            x, y, z = problem.site_xyz[j]
            w.writerow([problem.station_ids[problem.pair_station[k]], problem.site_ids[j],
                        int(problem.pair_reason[k] == USABLE),
                        f"{np.degrees(problem.pair_bearing_rad[k]):.6f}",
                        f"{problem.pair_sigma_m[k]:.6g}" if np.isfinite(problem.pair_sigma_m[k])
                        else "1", f"{x:.4f}", f"{y:.4f}", f"{z:.4f}",
                        f"{problem.pair_distance_m[k]:.4f}"])
    return path


def test_round_trip_gives_the_same_plan(tmp_path):
    p = make_problem([[0, 0], [10, 0]], np.vstack([ring([0, 0], 6, range(15, 360, 30)),
                                                   ring([10, 0], 6, range(0, 360, 45))]),
                     occluded=[(0, 1), (1, 3)])
    path = write_visibility_table(tmp_path / "vis.csv", p)
    q = read_visibility_table(path, p.station_ids, p.station_xyz)
    assert np.array_equal(q.pair_reason, p.pair_reason)
    assert np.allclose(q.pair_sigma_m, p.pair_sigma_m, rtol=1e-5)
    cfg = PlanConfig(requirement_m=0.05)
    assert plan_sites(q, cfg).selected.sum() == plan_sites(p, cfg).selected.sum()


def test_bad_tables(tmp_path):
    f = tmp_path / "v.csv"
    f.write_text("station,site,usable\nS1,a,1\n")
    with pytest.raises(InputFileError, match="missing column"):
        read_visibility_table(f, ["S1"], np.zeros((1, 3)))
    head = "station,site,usable,bearing_deg,sigma_m,site_x_m,site_y_m,site_z_m\n"
    f.write_text(head + "S9,a,1,0,0.01,1,0,0\n")
    with pytest.raises(InputFileError, match="unknown station"):
        read_visibility_table(f, ["S1"], np.zeros((1, 3)))
    f.write_text(head + "S1,a,maybe,0,0.01,1,0,0\n")
    with pytest.raises(InputFileError, match="usable"):
        read_visibility_table(f, ["S1"], np.zeros((1, 3)))
    f.write_text(head + "S1,a,1,0,0.01,1,0,0\nS1,b,1,0,x,1,0,0\n")
    with pytest.raises(InputFileError, match="line 3"):
        read_visibility_table(f, ["S1"], np.zeros((1, 3)))
    f.write_text(head)
    with pytest.raises(InputFileError, match="no rows"):
        read_visibility_table(f, ["S1"], np.zeros((1, 3)))
