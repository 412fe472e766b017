"""Reading and checking marker tables."""

from __future__ import annotations

import numpy as np
import pytest

from error_model.table import fit_data, read_marker_tables
from markerplan.errors import DataError, InputFileError
from pipeline.tables.marker_table import COLUMNS
from tests.error_model.synthetic import synthetic_table, write_csv


def test_csv_round_trip_keeps_values_and_types(tmp_path):
    table = synthetic_table(50, seed=1)
    write_csv(tmp_path / "t.csv", table)
    got = read_marker_tables(tmp_path / "t.csv")
    assert tuple(got.columns) == COLUMNS
    np.testing.assert_allclose(got["distance_m"], table["distance_m"], atol=5e-7)  # 6 decimals
    np.testing.assert_array_equal(np.isnan(got["error_m"]), np.isnan(table["error_m"]))
    np.testing.assert_array_equal(got["accepted"], table["accepted"])
    assert got["station_id"][0] == table["station_id"][0]


def test_several_tables_concatenate(tmp_path):
    write_csv(tmp_path / "a.csv", synthetic_table(30, seed=1))
    write_csv(tmp_path / "b.csv", synthetic_table(20, seed=2))
    got = read_marker_tables([tmp_path / "a.csv", tmp_path / "b.csv"])
    assert got.n_rows == 50
    assert len(got.sources) == 2


def test_fit_data_keeps_accepted_finite_rows_in_si_units():
    table = synthetic_table(400, seed=3)
    from error_model.table import as_marker_table

    data = fit_data(as_marker_table(table), 10, ["visible_fraction", "expected_points"])
    keep = table["accepted"] & np.isfinite(table["error_m"])
    assert data.n_rows == keep.sum()
    np.testing.assert_allclose(data.elevation_rad, np.deg2rad(table["elevation_deg"][keep]))
    assert data.counts["dropped_not_accepted"] == (~table["accepted"]).sum()
    assert set(data.extras) == {"visible_fraction", "expected_points"}
    np.testing.assert_array_equal(data.extras["expected_points"], table["n_points"][keep])


@pytest.mark.parametrize("edit, err, match", [
    (lambda lines: [lines[0].replace("error_m,", "err,")] + lines[1:], InputFileError,
     "missing column"),
    (lambda lines: [lines[0]] + [lines[1].replace("true", "maybe", 1)] + lines[2:],
     InputFileError, "true/false"),
    (lambda lines: [], InputFileError, "empty"),
    (lambda lines: lines[:2] + [lines[2] + ",extra"] + lines[3:], InputFileError, "cells"),
])
def test_malformed_csv_is_a_one_line_error(tmp_path, edit, err, match):
    path = tmp_path / "t.csv"
    write_csv(path, synthetic_table(50, seed=1))
    lines = path.read_text().splitlines()
    path.write_text("\n".join(edit(lines)) + "\n" if edit(lines) else "")
    with pytest.raises(err, match=match) as exc:
        read_marker_tables(path)
    assert "\n" not in str(exc.value)


def test_non_numeric_cell_names_column_and_line(tmp_path):
    table = synthetic_table(10, seed=1)
    table["distance_m"] = table["distance_m"].astype(object)
    table["distance_m"][3] = "far"
    write_csv(tmp_path / "t.csv", table)
    with pytest.raises(InputFileError, match="'distance_m' line 5"):
        read_marker_tables(tmp_path / "t.csv")


def test_missing_file_is_an_input_file_error(tmp_path):
    with pytest.raises(InputFileError, match="cannot be read"):
        read_marker_tables(tmp_path / "absent.csv")


def test_all_nan_column_and_out_of_range_values_are_data_errors(tmp_path):
    table = synthetic_table(100, seed=1)
    table["distance_m"][:] = np.nan
    write_csv(tmp_path / "t.csv", table)
    with pytest.raises(DataError, match="'distance_m' is all NaN"):
        fit_data(read_marker_tables(tmp_path / "t.csv"), 10)
    table = synthetic_table(100, seed=1)
    table["distance_m"][0] = -1.0
    table["accepted"][0] = True
    table["error_m"][0] = 0.01
    from error_model.table import as_marker_table

    with pytest.raises(DataError, match="distance_m must be > 0"):
        fit_data(as_marker_table(table), 10)


def _accepted_yes(lines: list[str]) -> list[str]:
    cells = lines[1].split(",")
    cells[lines[0].split(",").index("accepted")] = "yes"
    return [lines[0], ",".join(cells), *lines[2:]]


@pytest.mark.parametrize(("edit", "match"), [
    (lambda lines: lines + lines[1:], r"t.csv: 50 rows repeat an earlier row exactly: row 52 "
                                      r"repeats row 2, .* and 47 more \(station "),
    (_accepted_yes, r"column 'accepted' row 2 must be true/false, got 'yes'"),
])
def test_repeated_rows_and_accepted_other_than_true_false_are_refused(tmp_path, edit, match):
    path = tmp_path / "t.csv"
    write_csv(path, synthetic_table(50, seed=1))
    path.write_text("\n".join(edit(path.read_text().splitlines())) + "\n")
    with pytest.raises(InputFileError, match=match):
        read_marker_tables(path)
