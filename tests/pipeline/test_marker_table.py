import numpy as np
import pytest

from markerplan.errors import InputFileError
from pipeline.tables.marker_table import (
    COLUMNS,
    MarkerRow,
    line_of_sight,
    read_marker_table,
    write_marker_table,
)

EXPECTED = ("station_id, marker_id, x_m, y_m, z_m, distance_m, elevation_deg, azimuth_deg, "
            "n_points, point_density_per_m2, visible_fraction, fit_rms_m, radius_fit_m, "
            "estimator, accepted, reason, error_m, error_x_m, error_y_m, error_z_m, replicate, "
            "seed").split(", ")


def test_columns_are_the_contract():
    assert list(COLUMNS) == EXPECTED


def test_roundtrip_and_formatting(tmp_path):
    r = MarkerRow("S1", "M01", 3.0, 4.0, -1.0, *line_of_sight([3.0, 4.0, -1.0]), 120, 3819.7,
                  0.95, 0.011, 0.098, "fixed-radius", True, "")
    r.set_error(np.array([3.001, 4.0, -1.002]))
    u = MarkerRow("S1", "", 1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 5, 1.0, 0.25, 0.2, float("nan"),
                  "fixed-radius", False, "too_few_points")
    path = write_marker_table(tmp_path / "m.csv", [r, u])
    rows = read_marker_table(path)
    assert rows[0]["accepted"] == "true" and rows[1]["accepted"] == "false"
    assert float(rows[0]["error_m"]) == pytest.approx(np.hypot(0.001, 0.002), abs=1e-6)
    assert float(rows[0]["elevation_deg"]) == pytest.approx(-11.3099, abs=1e-4)
    assert rows[1]["marker_id"] == "" and rows[1]["error_m"] == "" and rows[1]["seed"] == ""
    assert rows[1]["radius_fit_m"] == ""


def test_azimuth_and_elevation_conventions():
    d, e, a = line_of_sight([0.0, -2.0, 2.0])
    assert d == pytest.approx(np.sqrt(8)) and e == pytest.approx(45) and a == pytest.approx(270)


def test_wrong_header_rejected(tmp_path):
    f = tmp_path / "bad.csv"
    f.write_text("station_id,x_m\nS1,1\n")
    with pytest.raises(InputFileError, match="missing"):
        read_marker_table(f)


def test_accepted_is_read_once_in_any_case(tmp_path):
    """``accepted`` is true/false in any case (:func:`accepted_flags`), and every caller of
    :func:`read_marker_table` sees it written one way."""
    rows = [MarkerRow("S1", f"M{k}", 3.0, 4.0, -1.0, *line_of_sight([3.0, 4.0, -1.0]), 120,
                      3819.7, 0.95, 0.011, 0.098, "fixed-radius", True, "") for k in range(2)]
    path = write_marker_table(tmp_path / "m.csv", rows)
    lines = path.read_text().splitlines()
    lines[1] = lines[1].replace(",true,", ",TRUE,")
    lines[2] = lines[2].replace(",true,", ", False ,")
    path.write_text("\n".join(lines) + "\n")
    assert [r["accepted"] for r in read_marker_table(path)] == ["true", "false"]
