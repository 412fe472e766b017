"""Known-control verification names where the chain lost each planned marker: a marker the
sensor cannot see (buried below the level ground) is ``not_in_view`` in the station's fates,
its reason and ``fates.csv``; the markers it sees are accepted, within a centimetre."""

import numpy as np
import pytest

from error_model import default_model
from pipeline.chain.stages import build_config
from planner.outputs.plan_file import PlannedStation
from planner.verify.fates import FATES_COLUMNS, FATES_TYPES, stage_counts, write_fates
from planner.verify.known_control import check_station
from planner.verify.station_rule import StationRule

simulate = pytest.importorskip("visibility.simulate")
dem_mod = pytest.importorskip("visibility.dem")

#: Site frame; the station at (0, 0, 1) heading 0 on a level field at z = 0. ``HIDDEN`` is
#: buried: no ray can reach it.
IDS = ("A", "B", "HIDDEN")
CENTRES = np.array([[8.0, 0.0, 0.1], [0.0, 8.0, 0.1], [0.0, -8.0, -1.0]])
STATION = PlannedStation("S1", np.array([0.0, 0.0, 1.0]), 0.0, 0.05, IDS)


@pytest.fixture(scope="module")
def simulated():
    dem = dem_mod.DEM(np.zeros((201, 201)), (-10.0, -10.0), 0.1)
    return simulate.simulate_markers(dem, STATION.position_m, 0.0, CENTRES, marker_ids=list(IDS),
                                     frames=range(0, 800, 8), station_id="S1")


@pytest.fixture(scope="module")
def check(simulated):
    scan, truth = simulated
    return check_station(IDS, CENTRES, build_config(), default_model(), 0.1, 10.0, 0, STATION,
                         scan, truth, rule=StationRule(min_markers=2, min_sectors=2))


def test_a_buried_marker_is_lost_out_of_view_and_named_in_the_reason(check):
    fates = {r.marker_id: r for r in check.fates.rows}
    assert [r.marker_id for r in check.fates.rows] == list(IDS)
    assert fates["HIDDEN"].stage == "not_in_view" and fates["HIDDEN"].n_points == 0
    assert not fates["HIDDEN"].accepted and fates["HIDDEN"].candidate is None
    for mid in ("A", "B"):
        row = fates[mid]
        assert row.stage == "accepted" and row.accepted and row.reason == ""
        assert row.error_m < 0.01 and row.candidate is not None
        assert row.distance_m == pytest.approx(np.hypot(8.0, 0.9), abs=1e-6)
        assert row.elevation_deg == pytest.approx(np.degrees(np.arctan2(-0.9, 8.0)), abs=1e-6)
    assert check.passed and check.n_detected == 2
    assert check.reason == "ok (lost HIDDEN out of view (no return on the marker))"
    assert stage_counts([check.fates, None]) == {"not_in_view": 1, "false_accepts": 0}


def test_two_markers_registering_well_still_break_the_plans_three_direction_rule(simulated):
    """The same detections judged by the planner's default rule (3 markers in 3 of 6
    sectors): the registration meets the requirement, the station fails the promise."""
    scan, truth = simulated
    check = check_station(IDS, CENTRES, build_config(), default_model(), 0.1, 10.0, 0, STATION,
                          scan, truth)
    assert not check.passed and check.achieved_error_m < 0.1 and check.n_detected == 2
    assert check.reason == ("2 marker(s) in 2 of 6 sectors detected and accepted, the plan's "
                            "rule asks >= 3 in >= 3 (lost HIDDEN out of view (no return on "
                            "the marker))")


def test_a_station_short_of_markers_says_which_stage_lost_them(simulated):
    """A plan of A and HIDDEN only (B is in the scene, not in the plan): one matched marker
    cannot register the station, which fails naming the stage of its loss."""
    scan, truth = simulated
    station = PlannedStation("S1", STATION.position_m, 0.0, 0.05, ("A", "HIDDEN"))
    check = check_station(("A", "HIDDEN"), CENTRES[[0, 2]], build_config(), default_model(),
                          0.1, 10.0, 0, station, scan, truth)
    assert not check.passed and check.achieved_error_m is None
    assert check.reason == ("only 1 planned marker(s) detected and accepted (needs 2): lost "
                            "HIDDEN out of view (no return on the marker)")
    assert [(r.marker_id, r.stage) for r in check.fates.rows] == [("A", "accepted"),
                                                                   ("HIDDEN", "not_in_view")]
    assert check.fates.n_false_accepts == 0  # B is a simulated marker, not a rock


def test_fates_csv_has_one_row_per_trial_station_and_marker(check, tmp_path):
    written = write_fates(tmp_path / "fates.csv", [[check.fates], [check.fates]])
    assert [p.name for p in written] == ["fates.csv", "fates.csvt"]
    lines = (tmp_path / "fates.csv").read_text().splitlines()
    assert lines[0] == ",".join(FATES_COLUMNS) and len(lines) == 1 + 2 * len(IDS)
    assert lines[3].startswith("0,S1,HIDDEN,") and ",0,not_in_view,no return on the marker," \
        "false,," in lines[3]
    assert lines[4].startswith("1,S1,A,")
    assert (tmp_path / "fates.csvt").read_text() == ",".join(f'"{t}"' for t in FATES_TYPES) \
        + "\n"
    assert len(FATES_TYPES) == len(FATES_COLUMNS)
