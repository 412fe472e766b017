"""Bad error models, marker tables and DEMs are refused with one line.

Commands: ``fit-error-model`` (marker tables), ``plan``/``verify --error-model`` (model JSON),
``simulate``/``plan --dem`` (DEMs). Each case is checked by
:func:`tests.cli.bad_input.check_refused`: exit code, one error line naming the problem, no
traceback, nothing written.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from tests.cli.bad_input import Case, check_refused
from tests.cli.invoke import run_cli

# --- error models ------------------------------------------------------------------------


def _model(edit: Callable[[dict], object], name: str = "bad.json") -> Callable[[Path, Path], None]:
    """Setup: copy the valid model, apply ``edit`` to its JSON, write it as ``name``."""

    def setup(cwd: Path, inputs: Path) -> None:
        doc = json.loads((inputs / "model.json").read_text())
        edit(doc)
        (cwd / name).write_text(json.dumps(doc))

    return setup


def _model_text(replace: Callable[[str], str]) -> Callable[[Path, Path], None]:
    """Setup: the valid model's text, edited as text (for NaN, Infinity, 1e300...)."""

    def setup(cwd: Path, inputs: Path) -> None:
        doc = json.loads((inputs / "model.json").read_text())
        doc["sigma"]["coefficients"][0] = "@@"
        (cwd / "bad.json").write_text(replace(json.dumps(doc)))

    return setup


def _set(path: tuple, value) -> Callable[[dict], None]:
    def edit(doc: dict) -> None:
        *parents, last = path
        for key in parents:
            doc = doc[key]
        doc[last] = value

    return edit


def _drop(key: str) -> Callable[[dict], None]:
    return lambda doc: doc.pop(key)


PLAN = ["plan", "--error-model", "bad.json", "--out", "out"]
VERIFY = ["verify", "{inputs}/plan/plan.json", "--error-model", "bad.json", "--out", "out"]

MODEL_CASES = [
    Case("plan-model-list", PLAN, "not a markerplan error model", files={"bad.json": "[1, 2]"}),
    Case("plan-model-not-json", PLAN, "not valid JSON", files={"bad.json": "{oops"}),
    Case("plan-model-empty", PLAN, "not valid JSON", files={"bad.json": ""}),
    Case("plan-model-nan", PLAN, "NaN", setup=_model_text(lambda t: t.replace('"@@"', "NaN"))),
    Case("plan-model-infinity", PLAN, "Infinity",
         setup=_model_text(lambda t: t.replace('"@@"', "-Infinity"))),
    Case("plan-model-1e300", PLAN, "beyond the accepted magnitude",
         setup=_model_text(lambda t: t.replace('"@@"', "1e300"))),
    Case("plan-model-not-utf8", PLAN, "not UTF-8",
         files={"bad.json": b'{"format": "markerplan-error-model", "x": "\xff\xfe"}'}),
    Case("plan-model-future-version", PLAN, "format_version 2 is newer",
         setup=_model(_set(("format_version",), 2))),
    Case("plan-model-missing-domain", PLAN, "missing 'domain'", setup=_model(_drop("domain"))),
    Case("plan-model-sigma-string", PLAN, "sigma: expected dict",
         setup=_model(_set(("sigma",), "0.01"))),
    Case("plan-model-quantile-above-1", PLAN, "quantile must lie in (0, 1)",
         setup=_model(_set(("envelope", "quantile"), 1.5))),
    Case("plan-model-quantile-string", PLAN, "expected int or float",
         setup=_model(_set(("envelope", "quantile"), "0.95"))),
    Case("plan-model-inverted-distance", PLAN, "non-decreasing",
         setup=_model(lambda d: d["domain"]["band_edges_m"].reverse())),
    Case("plan-model-negative-sigma", PLAN, "<= 0 inside the fitted domain",
         setup=_model(_set(("sigma", "coefficients"), [-0.01, 0.0, 0.0]))),
    Case("plan-model-negative-slope", PLAN, "must be >= 0",
         setup=_model(_set(("envelope", "coefficients"), [0.01, -0.001, 0.0]))),
    Case("plan-model-missing", PLAN, "no such file"),
    Case("verify-model-zero-sigma", VERIFY, "<= 0 inside the fitted domain",
         setup=_model(_set(("sigma", "coefficients"), [0.0, 0.0, 0.0]))),
    Case("verify-model-inverted-elevation", VERIFY, "elevation range",
         setup=_model(lambda d: d["domain"].update(elevation_lo_rad=d["domain"]["elevation_hi_rad"],
                                                   elevation_hi_rad=d["domain"]["elevation_lo_rad"]))),
    Case("verify-model-wrong-count", VERIFY, "expected 3 numbers",
         setup=_model(_set(("sigma", "coefficients"), [0.01, 0.001]))),
    Case("verify-model-boolean", VERIFY, "boolean",
         setup=_model(_set(("sigma", "coefficients"), [True, 0.001, 0.001]))),
    Case("verify-model-unknown-extra", VERIFY, "unknown extra predictor",
         setup=_model(_set(("basis", "extras"), ["colour"]))),
    Case("verify-model-knot-beyond-90", VERIFY, "pi/2",
         setup=_model(_set(("basis", "elevation_knots_rad"), [2.0]))),
    Case("verify-model-wrong-format", VERIFY, "not a markerplan error model",
         setup=_model(_set(("format",), "something-else"))),
    Case("verify-model-list", VERIFY, "not a markerplan error model",
         files={"bad.json": "[]"}),
]

# --- marker tables -----------------------------------------------------------------------


def _table(edit: Callable[[list[list[str]]], list[list[str]] | None],
           name: str = "bad.csv") -> Callable[[Path, Path], None]:
    """Setup: the valid marker table as rows of cells, edited in place, written as ``name``."""

    def setup(cwd: Path, inputs: Path) -> None:
        lines = (inputs / "markers.csv").read_text().splitlines()
        rows = [ln.split(",") for ln in lines]
        rows = edit(rows) or rows
        (cwd / name).write_text("\n".join(",".join(r) for r in rows) + "\n")

    return setup


def _cell(column: str, value: str, row: int = 1) -> Callable[[list[list[str]]], None]:
    def edit(rows: list[list[str]]) -> None:
        rows[row][rows[0].index(column)] = value

    return edit


FIT = ["fit-error-model", "bad.csv", "--out", "out"]

TABLE_CASES = [
    Case("fit-table-ragged-row", FIT, "cells", setup=_table(lambda r: r[1].append("x"))),
    Case("fit-table-nan", FIT, "finite", setup=_table(_cell("distance_m", "nan"))),
    Case("fit-table-inf", FIT, "finite", setup=_table(_cell("error_m", "inf", 2))),
    Case("fit-table-1e300", FIT, "beyond the accepted magnitude",
         setup=_table(_cell("elevation_deg", "1e300"))),
    Case("fit-table-text-number", FIT, "must be a number",
         setup=_table(_cell("distance_m", "far"))),
    Case("fit-table-bad-bool", FIT, "true/false", setup=_table(_cell("accepted", "maybe"))),
    Case("fit-table-not-utf8", FIT, "not UTF-8",
         files={"bad.csv": b"distance_m,elevation_deg,error_m,accepted\n1,2,0.01,\xe9t\xe9\n"}),
    Case("fit-table-header-only", FIT, "usable rows", setup=_table(lambda r: r[:1])),
    Case("fit-table-none-accepted", FIT, "usable rows",
         setup=_table(lambda r: [r[0]] + [[*x[:r[0].index("accepted")], "false",
                                           *x[r[0].index("accepted") + 1:]] for x in r[1:]])),
    Case("fit-table-missing-column", FIT, "missing column",
         setup=_table(lambda r: [[c for c, h in zip(x, r[0], strict=True) if h != "error_m"]
                                 for x in r])),
    Case("fit-table-duplicate-column", FIT, "appear twice",
         setup=_table(lambda r: [[*x, x[r[0].index("distance_m")]] for x in r])),
    Case("fit-table-empty", FIT, "empty", files={"bad.csv": ""}),
    Case("fit-table-missing", FIT, "no such file"),
    Case("fit-table-folder", ["fit-error-model", "adir", "--out", "out"], "directory", code=2,
         setup=lambda cwd, inputs: (cwd / "adir").mkdir()),
]

# --- DEMs --------------------------------------------------------------------------------


def _tif(name: str = "bad.tif", *, crs: str | None = "EPSG:32633", bands: int = 1,
         cell: tuple[float, float] = (1.0, 1.0), heights: np.ndarray | None = None,
         rotated: bool = False, dtype: str = "float64",
         west_north: tuple[float, float] = (500000.0, 4000000.0)
         ) -> Callable[[Path, Path], None]:
    """Setup: a small GeoTIFF with the given defect (``west_north``: its top-left corner)."""

    def setup(cwd: Path, inputs: Path) -> None:
        import rasterio
        from rasterio.transform import Affine

        h = np.full((6, 8), 1.0) if heights is None else heights
        t = Affine(cell[0], 0.3 if rotated else 0.0, west_north[0], 0.0, -cell[1],
                   west_north[1])
        with rasterio.open(cwd / name, "w", driver="GTiff", height=h.shape[0],
                           width=h.shape[1], count=bands, dtype=dtype, crs=crs,
                           transform=t) as dst:
            for b in range(1, bands + 1):
                dst.write(h.astype(dtype), b)

    return setup


def _npz(name: str = "bad.npz", **members) -> Callable[[Path, Path], None]:
    """Setup: an .npz with exactly ``members`` (defaults: a valid 4 x 5 DEM)."""

    def setup(cwd: Path, inputs: Path) -> None:
        base = {"heights_m": np.zeros((4, 5)), "origin_m": np.array([0.0, 0.0]),
                "cell_size_m": np.array(1.0), "crs": np.array("")}
        base.update(members)
        np.savez(cwd / name, **{k: v for k, v in base.items() if v is not None})

    return setup


def _with_nan() -> np.ndarray:
    h = np.full((6, 8), 1.0)
    h[2, 3] = np.nan
    return h


def _nodata_under_s1() -> np.ndarray:
    """Flat 61 x 61 heights (1 m cells over the default site, -30..30 m) with nodata at the
    centre cell, under station S1 at (0, 0)."""
    h = np.zeros((61, 61))
    h[30, 30] = np.nan
    return h


_NODATA_UNDER_S1 = _tif(heights=_nodata_under_s1(), west_north=(-30.5, 30.5))


SIM = ["simulate", "--dem", "bad.tif", "--out", "out"]
SIM_NPZ = ["simulate", "--dem", "bad.npz", "--out", "out"]
PLAN_DEM = ["plan", "--dem", "bad.tif", "--stations", "{inputs}/stations.csv", "--out", "out"]
PLAN_NPZ = ["plan", "--dem", "bad.npz", "--stations", "{inputs}/stations.csv", "--out", "out"]

DEM_CASES = [
    Case("simulate-dem-geographic", SIM, "geographic (degrees), but DEM cells and heights must "
         "be metres; pass --reproject", setup=_tif(crs="EPSG:4326")),
    Case("plan-dem-geographic", PLAN_DEM, "gdalwarp", setup=_tif(crs="EPSG:4326")),
    Case("simulate-dem-us-feet", SIM, "not metres", setup=_tif(crs="EPSG:2229")),
    Case("simulate-dem-two-bands", SIM, "2 bands", setup=_tif(bands=2)),
    Case("plan-dem-three-bands", PLAN_DEM, "3 bands", setup=_tif(bands=3)),
    Case("simulate-dem-non-square", SIM, "cells must be square, got 1 x 2; pass --reproject",
         setup=_tif(cell=(1.0, 2.0))),
    Case("plan-dem-rotated", PLAN_DEM, "north-up", setup=_tif(rotated=True)),
    Case("simulate-station-on-nodata", SIM, "station S1 at (0.00, 0.00) m stands on DEM nodata",
         setup=_NODATA_UNDER_S1),
    Case("plan-station-on-nodata", PLAN_DEM, "station S1 at (0.00, 0.00) m stands on DEM "
         "nodata", setup=_NODATA_UNDER_S1),
    Case("simulate-dem-all-inf", SIM, "every cell is nodata",
         setup=_tif(heights=np.full((6, 8), np.inf))),
    Case("plan-dem-1e300", PLAN_DEM, "within",
         setup=_tif(heights=np.r_[[np.full(8, 1e300)], np.ones((5, 8))])),
    Case("simulate-dem-all-nan", SIM, "every cell is nodata",
         setup=_tif(heights=np.full((6, 8), np.nan))),
    Case("simulate-dem-complex", SIM, "not a real number", setup=_tif(dtype="complex64")),
    Case("simulate-dem-empty", SIM, "empty", files={"bad.tif": b""}),
    Case("plan-dem-corrupt", PLAN_DEM, "not a raster GDAL can read",
         files={"bad.tif": b"II*\x00" + bytes(range(256)) * 4}),
    Case("simulate-dem-missing", SIM, "does not exist"),
    Case("simulate-dem-not-a-raster", ["simulate", "--dem", "bad.csv", "--out", "out"],
         "not a raster GDAL can read",
         files={"bad.csv": "1,2\n"}),
    Case("simulate-dem-bad-fill", [*SIM, "--dem-fill", "mean"], "mean", code=2,
         setup=_tif(heights=_with_nan())),
    Case("simulate-npz-missing-member", SIM_NPZ, "lacks member", setup=_npz(cell_size_m=None)),
    Case("plan-npz-missing-member", PLAN_NPZ, "heights_m", setup=_npz(heights_m=None)),
    Case("simulate-npz-1d-heights", SIM_NPZ, "2-D", setup=_npz(heights_m=np.zeros(5))),
    Case("simulate-npz-text-heights", SIM_NPZ, "2-D array of numbers",
         setup=_npz(heights_m=np.array([["a", "b"], ["c", "d"]]))),
    Case("simulate-npz-origin-shape", SIM_NPZ, "origin_m",
         setup=_npz(origin_m=np.array([1.0, 2.0, 3.0]))),
    Case("plan-npz-zero-cell", PLAN_NPZ, "cell size must be > 0",
         setup=_npz(cell_size_m=np.array(0.0))),
    Case("simulate-npz-nan-cell", SIM_NPZ, "cell size", setup=_npz(cell_size_m=np.array(np.nan))),
    Case("simulate-npz-geographic", SIM_NPZ, "geographic",
         setup=_npz(crs=np.array("EPSG:4326"))),
    Case("simulate-npz-bad-crs", SIM_NPZ, "not a CRS", setup=_npz(crs=np.array("nonsense"))),
    Case("simulate-npz-tiny", SIM_NPZ, "2 x 2", setup=_npz(heights_m=np.zeros((1, 5)))),
    Case("simulate-npz-2x2-preset", SIM_NPZ, "outside the DEM (2 x 2 cells of 1 m) [0.0, 1.0] x "
         "[0.0, 1.0] m; the 7 stations need [-12.0, 12.0] x [-10.4, 10.4] m",
         setup=_npz(heights_m=np.zeros((2, 2)))),
    Case("simulate-npz-2x2-stations", [*SIM_NPZ, "--stations", "st.csv"],
         "outside the DEM (2 x 2 cells of 1 m) [0.0, 1.0] x [0.0, 1.0] m; the 11 markers need",
         files={"st.csv": "id,x_m,y_m\nA,0.5,0.5\n"}, setup=_npz(heights_m=np.zeros((2, 2)))),
    Case("simulate-npz-is-npy", SIM_NPZ, "single .npy",
         setup=lambda cwd, inputs: np.save(cwd / "x.npy", np.zeros((3, 3))) or
         (cwd / "x.npy").rename(cwd / "bad.npz")),
    Case("plan-npz-garbage", PLAN_NPZ, "not a readable .npz",
         files={"bad.npz": b"PK\x03\x04" + b"\x00" * 60}),
]

CASES = MODEL_CASES + TABLE_CASES + DEM_CASES


@pytest.mark.parametrize("case", CASES, ids=str)
def test_refused(case, capsys, monkeypatch, tmp_path, valid_inputs):
    check_refused(case, capsys, monkeypatch, tmp_path, valid_inputs)


def test_dem_nodata_message_names_no_option_plan_lacks(capsys, monkeypatch, tmp_path,
                                                       valid_inputs):
    """``plan`` has no ``--dem-fill``: its nodata message must not suggest it."""
    _NODATA_UNDER_S1(tmp_path, valid_inputs)
    monkeypatch.chdir(tmp_path)
    code, _, err = run_cli(capsys, [a.replace("{inputs}", str(valid_inputs)) for a in PLAN_DEM])
    assert code == 1 and "nodata" in err
    assert "--dem-fill" not in err, err
