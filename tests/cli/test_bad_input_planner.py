"""Bad input to ``plan``, ``verify`` and ``reduce``: one error line, exit code 1 (2 for click
usage errors), nothing written. Every case fails while reading its input, before ray casting.

See :mod:`tests.cli.bad_input` for the promises :func:`check_refused` asserts.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.cli.bad_input import Case, check_refused

NOT_UTF8 = b"id,x_m,y_m\nS\xff1,0,0\n"
SQUARE = [[-5, -5], [5, -5], [5, 5], [-5, 5], [-5, -5]]
HOLE = [[-1, -1], [1, -1], [1, 1], [-1, 1], [-1, -1]]
VIS_HEADER = "station,site,usable,bearing_deg,sigma_m,site_x_m,site_y_m,site_z_m\n"
VIS_ROW = "S1,A,1,30,0.008,4.3,2.5,0.1\n"
#: Three fiducials on a lander on the default site (site frame, m).
LANDER = "id,x_m,y_m,z_m,sigma_m\nL1,8,-3.8,1.33,0.005\nL2,6.96,-5.6,1.4,0.005\n" \
    "L3,9.04,-5.6,1.31,0.005\n"


def _poly(coords) -> str:
    return json.dumps({"type": "Polygon", "coordinates": coords})


# --- plan -------------------------------------------------------------------------------


def _plan(name, option, fname, content, needle, code=1) -> Case:
    """``plan OPTION FNAME --out out`` with ``content`` written to ``FNAME``."""
    return Case(f"plan-{name}", ["plan", option, fname, "--out", "out"], needle, code,
                files={fname: content})


CONFIG_CASES = [
    _plan("config-not-utf8", "--config", "c.toml", b"requirement_m = 0.1 # \xff\n", "not UTF-8"),
    _plan("config-syntax", "--config", "c.toml", "requirement_m = = 1\n", "not valid TOML"),
    _plan("config-binary", "--config", "c.toml", b"\x00\x01\x02", "not valid TOML"),
    _plan("config-nan", "--config", "c.toml", "requirement_m = nan\n", "requirement_m"),
    _plan("config-inf-range", "--config", "c.toml", "max_range_m = inf\n", "max_range_m"),
    _plan("config-huge-range", "--config", "c.toml", "max_range_m = 1e6\n", "(0, 100] m"),
    _plan("config-tiny-grid", "--config", "c.toml", "grid_spacing_m = 1e-6\n", "grid_spacing_m"),
    _plan("config-huge-grid", "--config", "c.toml", "grid_spacing_m = 1e9\n", "grid_spacing_m"),
    _plan("config-many-sectors", "--config", "c.toml", "n_sectors = 1000000\n", "[1, 36]"),
    _plan("config-many-rays", "--config", "c.toml", "rays_per_marker = 100000\n",
          "rays_per_marker"),
    _plan("config-string-number", "--config", "c.toml", 'requirement_m = "0.1"\n',
          "requirement_m"),
    _plan("config-bool-number", "--config", "c.toml", "max_range_m = true\n", "max_range_m"),
    _plan("config-float-count", "--config", "c.toml", "n_sectors = 6.5\n", "integer"),
    _plan("config-huge-int", "--config", "c.toml", "budget = 99999999999999999999\n", "budget"),
    _plan("config-date", "--config", "c.toml", "time_limit_s = 1979-05-27\n", "time_limit_s"),
    _plan("config-negative", "--config", "c.toml", "min_station_distance_m = -1\n",
          "min_station_distance_m"),
    _plan("config-gap", "--config", "c.toml", "mip_gap = 2\n", "mip_gap"),
    _plan("config-table", "--config", "c.toml", "[plan]\nrequirement_m = 0.1\n",
          "unknown key(s) plan"),
    _plan("config-unknown-key", "--config", "c.toml", "sectors = 4\n", "unknown key(s) sectors"),
    _plan("config-existing-ints", "--config", "c.toml", "existing = [1, 2]\n", "existing"),
    _plan("config-min-sectors", "--config", "c.toml", "n_sectors = 2\nmin_sectors = 3\n",
          "min_sectors"),
    _plan("config-ppm-known-control", "--config", "c.toml", "requirement_ppm = 200\n",
          "known control does not have"),
    _plan("config-ppm-negative", "--config", "c.toml",
          "network = true\nrequirement_ppm = -5\n", "requirement_ppm"),
    Case("plan-ppm-known-control", ["plan", "--requirement-ppm", "200", "--out", "out"],
         "plan in network mode (network = true)"),
    Case("plan-ppm-negative", ["plan", "--network", "--requirement-ppm", "-1", "--out", "out"],
         "--requirement-ppm", 2),
    Case("plan-odometry-known-control", ["plan", "--odometry-percent", "2", "--out", "out"],
         "network mode"),
    Case("plan-control-known-control", ["plan", "--control", "lander.csv", "--out", "out"],
         "network mode's datum: plan in network mode", files={"lander.csv": LANDER}),
    Case("plan-control-and-reference", ["plan", "--network", "--control", "lander.csv",
                                        "--reference-station", "S1", "--out", "out"],
         "drop --reference-station", files={"lander.csv": LANDER}),
    Case("plan-control-off-dem", ["plan", "--network", "--control", "lander.csv", "--out",
                                  "out"], "control point L2",
         files={"lander.csv": "id,x_m,y_m,z_m,sigma_m\nL1,8,-4,1.4,0.005\nL2,80,-4,1.4,0.005\n"}),
    Case("plan-control-underground", ["plan", "--network", "--control", "lander.csv", "--out",
                                      "out"], "below the ground",
         files={"lander.csv": "id,x_m,y_m,z_m,sigma_m\nL1,8,-4,-3,0.005\n"}),
    Case("plan-control-zero-sigma", ["plan", "--network", "--control", "lander.csv", "--out",
                                     "out"], "sigma_m",
         files={"lander.csv": "id,x_m,y_m,z_m,sigma_m\nL1,8,-4,1.4,0\n"}),
    Case("plan-control-id-clash", ["plan", "--network", "--control", "lander.csv", "--out",
                                   "out"], "clash",
         files={"lander.csv": "id,x_m,y_m,z_m,sigma_m\nC00001,8,-4,1.4,0.005\n"}),
    Case("plan-local-markers-without-local", ["plan", "--network", "--local-markers", "--out",
                                              "out"], "set local_requirement_m"),
    Case("plan-odometry-zero", ["plan", "--network", "--odometry-percent", "0", "--out", "out"],
         "--odometry-percent", 2),
    Case("plan-heading-aid-unknown", ["plan", "--network", "--heading-aid", "compass",
                                      "--out", "out"], "--heading-aid", 2),
    Case("plan-heading-sigma-zero", ["plan", "--network", "--config", "c.toml", "--out", "out"],
         "heading_prior_sigma_deg", files={"c.toml": "heading_prior_sigma_deg = 0\n"}),
    Case("plan-config-missing", ["plan", "--config", "nope.toml", "--out", "out"],
         "file not found"),
    Case("plan-config-folder", ["plan", "--config", "d", "--out", "out"], "directory", 2,
         setup=lambda cwd, inputs: (cwd / "d").mkdir()),
]

STATIONS_CASES = [
    _plan("stations-not-utf8", "--stations", "s.csv", NOT_UTF8, "not UTF-8"),
    _plan("stations-ragged", "--stations", "s.csv", "id,x_m,y_m\nS1,0,0,5\n", "row 2 has 4"),
    _plan("stations-missing-column", "--stations", "s.csv", "id,x_m\nS1,0\n", "missing column"),
    _plan("stations-duplicate-column", "--stations", "s.csv", "id,x_m,y_m,x_m\nS1,0,0,0\n",
          "appear twice"),
    _plan("stations-nan", "--stations", "s.csv", "id,x_m,y_m\nS1,nan,0\n", "finite"),
    _plan("stations-inf", "--stations", "s.csv", "id,x_m,y_m\nS1,0,-inf\n", "finite"),
    _plan("stations-1e300", "--stations", "s.csv", "id,x_m,y_m\nS1,1e300,0\n", "magnitude"),
    _plan("stations-text", "--stations", "s.csv", "id,x_m,y_m\nS1,east,0\n", "x_m of 'S1'"),
    _plan("stations-empty-cell", "--stations", "s.csv", "id,x_m,y_m\nS1,,0\n", "x_m of 'S1'"),
    _plan("stations-duplicate-id", "--stations", "s.csv", "id,x_m,y_m\nS1,0,0\nS1,5,5\n",
          "more than once"),
    _plan("stations-empty-id", "--stations", "s.csv", "id,x_m,y_m\n,0,0\n", "id is empty"),
    _plan("stations-header-only", "--stations", "s.csv", "id,x_m,y_m\n", "no points"),
    _plan("stations-empty-file", "--stations", "s.csv", "", "empty"),
    _plan("stations-heading", "--stations", "s.csv", "id,x_m,y_m,heading_deg\nS1,0,0,1e9\n",
          "heading_deg"),
    _plan("stations-outside", "--stations", "s.csv", "id,x_m,y_m\nS1,0,0\nS2,100,100\n",
          "outside the DEM"),
    _plan("stations-geojson-list", "--stations", "s.geojson", "[1, 2]", "JSON object"),
    _plan("stations-geojson-not-collection", "--stations", "s.geojson",
          '{"type": "Point", "coordinates": [0, 0]}', "FeatureCollection"),
    _plan("stations-geojson-no-features", "--stations", "s.geojson",
          '{"type": "FeatureCollection"}', "features"),
    _plan("stations-geojson-feature-number", "--stations", "s.geojson",
          '{"type": "FeatureCollection", "features": [1]}', "feature 0"),
    _plan("stations-geojson-polygon", "--stations", "s.geojson", json.dumps(
        {"type": "FeatureCollection", "features": [
            {"type": "Feature", "geometry": json.loads(_poly([SQUARE]))}]}), "must be a Point"),
    _plan("stations-geojson-coords-string", "--stations", "s.geojson", json.dumps(
        {"type": "FeatureCollection", "features": [
            {"type": "Feature", "geometry": {"type": "Point", "coordinates": "0,0"}}]}),
          "coordinates"),
    _plan("stations-geojson-coord-null", "--stations", "s.geojson", json.dumps(
        {"type": "FeatureCollection", "features": [
            {"type": "Feature", "geometry": {"type": "Point", "coordinates": [None, 0]}}]}),
          "x_m"),
    _plan("stations-geojson-1e400", "--stations", "s.geojson",
          '{"type": "FeatureCollection", "features": [{"type": "Feature", "geometry": '
          '{"type": "Point", "coordinates": [1e400, 0]}}]}', "finite"),
    _plan("stations-geojson-nan", "--stations", "s.geojson",
          '{"type": "FeatureCollection", "features": [{"type": "Feature", "geometry": '
          '{"type": "Point", "coordinates": [NaN, 0]}}]}', "not valid JSON"),
    _plan("stations-geojson-properties-list", "--stations", "s.geojson", json.dumps(
        {"type": "FeatureCollection", "features": [
            {"type": "Feature", "properties": [],
             "geometry": {"type": "Point", "coordinates": [0, 0]}}]}), "properties"),
    _plan("stations-geojson-id-bool", "--stations", "s.geojson", json.dumps(
        {"type": "FeatureCollection", "features": [
            {"type": "Feature", "properties": {"id": True},
             "geometry": {"type": "Point", "coordinates": [0, 0]}}]}), "'id'"),
    Case("plan-stations-missing", ["plan", "--stations", "nope.csv", "--out", "out"],
         "file not found"),
    Case("plan-stations-of-another-site", ["plan", "--stations", "s.csv", "--out", "out"],
         "site preset 'default'", files={"s.csv": "id,x_m,y_m\nS1,-132.66,-134.66\n"}),
    Case("plan-dem-without-stations", ["plan", "--dem", "{inputs}/model.json", "--out", "out"],
         "--stations"),
]

def _terrain(cell_height_m: float | None = None):
    """``setup`` writing ``d.npz``: a flat 41 m x 41 m DEM at 1 m cells centred on the origin,
    its centre cell raised to ``cell_height_m`` (a spike, or a pit when negative)."""
    def setup(cwd, inputs):
        from visibility.dem import DEM, write_dem

        heights = np.zeros((41, 41))
        if cell_height_m is not None:
            heights[20, 20] = cell_height_m
        write_dem(cwd / "d.npz", DEM(heights, (-20.0, -20.0), 1.0))
    return setup


def _on_terrain(name, stations, needle, cell_height_m=None) -> Case:
    """``plan --dem d.npz --stations s.csv`` on :func:`_terrain`."""
    return Case(f"plan-{name}", ["plan", "--dem", "d.npz", "--stations", "s.csv", "--out", "out"],
                needle, files={"s.csv": stations}, setup=_terrain(cell_height_m))


TERRAIN_CASES = [
    _on_terrain("station-underground", "id,x_m,y_m,z_m\nS1,0,0,-500\n",
                "500.00 m below the ground"),
    _on_terrain("station-on-spike", "id,x_m,y_m\nS1,0,0\n", "spike", cell_height_m=2000.0),
    _on_terrain("station-in-pit", "id,x_m,y_m\nS1,0,0\n", "pit", cell_height_m=-500.0),
    Case("plan-station-far-from-boundary", ["plan", "--dem", "d.npz", "--stations", "s.csv",
                                            "--boundary", "b.geojson", "--out", "out"],
         "S1: no candidate site within 30 m: the nearest, C", setup=_terrain(),
         files={"s.csv": "id,x_m,y_m\nS1,-19,-19\nS2,15,15\n",
                "b.geojson": _poly([[[12, 12], [19, 12], [19, 19], [12, 19], [12, 12]]])}),
]

POLYGON_CASES = [
    _plan("boundary-not-utf8", "--boundary", "b.geojson", b'{"type": "\xff"}', "not UTF-8"),
    _plan("boundary-list", "--boundary", "b.geojson", "[]", "JSON object"),
    _plan("boundary-point", "--boundary", "b.geojson", '{"type": "Point", "coordinates": [0, 0]}',
          "Polygon or MultiPolygon"),
    _plan("boundary-features-object", "--boundary", "b.geojson",
          '{"type": "FeatureCollection", "features": {}}', "features"),
    _plan("boundary-strings", "--boundary", "b.geojson",
          _poly([[["a", "b"], [5, -5], [5, 5], [-5, -5]]]), "must be a number"),
    _plan("boundary-flat-coords", "--boundary", "b.geojson", _poly([-5, -5, 5, 5]), "malformed"),
    _plan("boundary-short-ring", "--boundary", "b.geojson", _poly([[[0, 0], [1, 0]]]),
          "malformed ring"),
    _plan("boundary-1e400", "--boundary", "b.geojson",
          '{"type": "Polygon", "coordinates": [[[0, 0], [1e400, 0], [1, 1], [0, 0]]]}', "finite"),
    _plan("boundary-two-polygons", "--boundary", "b.geojson", json.dumps(
        {"type": "MultiPolygon", "coordinates": [[SQUARE], [[[10, 10], [12, 10], [12, 12],
                                                            [10, 10]]]]}), "holds 2 polygons"),
    _plan("boundary-hole", "--boundary", "b.geojson", _poly([SQUARE, HOLE]), "holes"),
    _plan("exclude-bowtie", "--exclude", "x.geojson",
          _poly([[[0, 0], [1, 1], [1, 0], [0, 1], [0, 0]]]), "invalid polygon"),
    _plan("exclude-nan", "--exclude", "x.geojson",
          '{"type": "Polygon", "coordinates": [[[0, 0], [NaN, 0], [1, 1], [0, 0]]]}',
          "not valid JSON"),
    _plan("exclude-deep-nesting", "--exclude", "x.geojson", "[" * 100_000, "not valid JSON"),
    _plan("exclude-empty-collection", "--exclude", "x.geojson",
          '{"type": "FeatureCollection", "features": []}', "no polygons"),
    Case("plan-exclude-missing", ["plan", "--exclude", "nope.geojson", "--out", "out"],
         "file not found"),
]

EXISTING_CASES = [
    _plan("existing-ragged", "--existing", "e.csv", "id,x_m,y_m\nE1,1\n", "row 2 has 2"),
    _plan("existing-duplicate", "--existing", "e.csv", "id,x_m,y_m\nE1,1,1\nE1,2,2\n",
          "more than once"),
    _plan("existing-nan", "--existing", "e.csv", "id,x_m,y_m,z_m\nE1,1,1,nan\n", "z_m of 'E1'"),
    _plan("existing-outside", "--existing", "e.csv", "id,x_m,y_m\nE1,500,1\n", "outside the DEM"),
    _plan("existing-buried", "--existing", "e.csv", "id,x_m,y_m,z_m\nE1,1,1,-5\n",
          "below the ground"),
    _plan("existing-not-utf8", "--existing", "e.csv", NOT_UTF8, "not UTF-8"),
    Case("plan-existing-missing", ["plan", "--existing", "nope.csv", "--out", "out"],
         "file not found"),
]

VISIBILITY_CASES = [
    _plan("visibility-missing-column", "--visibility", "v.csv", "station,site\nS1,A\n",
          "missing column"),
    _plan("visibility-ragged", "--visibility", "v.csv", VIS_HEADER + "S1,A,1\n", "row 2 has 3"),
    _plan("visibility-not-utf8", "--visibility", "v.csv", VIS_HEADER.encode() + b"S\xff,A\n",
          "not UTF-8"),
    _plan("visibility-no-rows", "--visibility", "v.csv", VIS_HEADER, "no rows"),
    _plan("visibility-unknown-station", "--visibility", "v.csv",
          VIS_HEADER + VIS_ROW.replace("S1", "S99"), "unknown station"),
    _plan("visibility-sigma-nan", "--visibility", "v.csv",
          VIS_HEADER + VIS_ROW.replace("0.008", "nan"), "sigma_m"),
    _plan("visibility-sigma-negative", "--visibility", "v.csv",
          VIS_HEADER + VIS_ROW.replace("0.008", "-1"), "sigma_m must be > 0"),
    _plan("visibility-sigma-huge", "--visibility", "v.csv",
          VIS_HEADER + VIS_ROW.replace("0.008", "1e300"), "sigma_m"),
    _plan("visibility-bearing-inf", "--visibility", "v.csv",
          VIS_HEADER + VIS_ROW.replace(",30,", ",inf,"), "bearing_deg"),
    _plan("visibility-coordinate-1e300", "--visibility", "v.csv",
          VIS_HEADER + VIS_ROW.replace("4.3", "1e300"), "site_x_m"),
    _plan("visibility-usable", "--visibility", "v.csv",
          VIS_HEADER + VIS_ROW.replace(",1,30", ",maybe,30"), "usable"),
    _plan("visibility-empty-site", "--visibility", "v.csv",
          VIS_HEADER + VIS_ROW.replace(",A,", ",,"), "site id is empty"),
    _plan("visibility-repeated-pair", "--visibility", "v.csv", VIS_HEADER + VIS_ROW * 2,
          "appears twice"),
    _plan("visibility-site-moves", "--visibility", "v.csv",
          VIS_HEADER + VIS_ROW + VIS_ROW.replace("S1", "S2").replace("4.3", "9.9"),
          "one site, one place"),
]


# --- verify and reduce: corrupted copies of the valid plan.json -----------------------------


def _edit_plan(edit=None, raw: str | None = None, text: str | bytes | None = None):
    """``setup`` writing ``p.json``: the valid plan changed by ``edit(doc)``; ``"__RAW__"``
    strings replaced by ``raw`` (JSON that ``json.dumps`` cannot write, e.g. ``1e400``)."""
    def setup(cwd, inputs):
        if text is not None:
            data = text if isinstance(text, bytes) else text.encode()
        else:
            doc = json.loads((inputs / "plan" / "plan.json").read_text())
            if edit is not None:
                edit(doc)
            data = json.dumps(doc).replace('"__RAW__"', raw or "null").encode()
        (cwd / "p.json").write_bytes(data)
    return setup


def _set(*keys, value):
    """An ``edit`` setting ``doc[k0][k1]... = value``."""
    def edit(doc):
        d = doc
        for k in keys[:-1]:
            d = d[k]
        d[keys[-1]] = value
    return edit


def _drop(*keys):
    """An ``edit`` deleting ``doc[k0][k1]...``."""
    def edit(doc):
        d = doc
        for k in keys[:-1]:
            d = d[k]
        del d[keys[-1]]
    return edit


def _dup_marker(doc):
    doc["markers"].append(dict(doc["markers"][0]))


def _keep_first_station(doc):
    doc["stations"] = doc["stations"][:1]


def _verify(name, needle, edit=None, raw=None, text=None) -> Case:
    return Case(f"verify-{name}", ["verify", "p.json", "--out", "out"], needle,
                setup=_edit_plan(edit, raw, text))


def _reduce(name, needle, edit=None, raw=None, text=None) -> Case:
    return Case(f"reduce-{name}", ["reduce", "p.json", "--out", "out"], needle,
                setup=_edit_plan(edit, raw, text))


VERIFY_CASES = [
    _verify("list", "JSON object", text="[1, 2]"),
    _verify("not-utf8", "not UTF-8", text=b'{"schema": "\xff"}'),
    _verify("not-json", "not a JSON file", text="{not json"),
    _verify("nan", "not a JSON file", _set("requirement", "requirement_m", value="__RAW__"),
            raw="NaN"),
    _verify("other-schema", "not a markerplan plan", _set("schema", value="other")),
    _verify("future-schema", "upgrade markerplan", _set("schema_version", value=99)),
    _verify("schema-version-text", "schema_version", _set("schema_version", value="1")),
    _verify("no-schema-version", "missing 'schema_version'", _drop("schema_version")),
    _verify("no-stations", "'stations' is empty", _set("stations", value=[])),
    _verify("no-markers", "'markers' is empty", _set("markers", value=[])),
    _verify("stations-object", "stations", _set("stations", value={"S1": {}})),
    _verify("missing-requirement", "missing 'requirement'", _drop("requirement")),
    _verify("requirement-list", "requirement", _set("requirement", value=[0.1])),
    _verify("requirement-text", "requirement_m", _set("requirement", "requirement_m",
                                                      value="0.1")),
    _verify("requirement-1e400", "finite", _set("requirement", "requirement_m",
                                                value="__RAW__"), raw="1e400"),
    _verify("working-radius-zero", "working_radius_m",
            _set("requirement", "working_radius_m", value=0)),
    _verify("min-markers-text", "min_markers", _set("requirement", "min_markers", value="3")),
    _verify("min-sectors-zero", "min_sectors", _set("requirement", "min_sectors", value=0)),
    _verify("n-sectors-float", "n_sectors", _set("requirement", "n_sectors", value=6.5)),
    _verify("min-markers-bool", "min_markers", _set("requirement", "min_markers", value=True)),
    _verify("marker-not-object", "markers[0]", _set("markers", 0, value=5)),
    _verify("marker-coordinate-text", "x_m", _set("markers", 0, "x_m", value="1.0")),
    _verify("marker-coordinate-null", "y_m", _set("markers", 0, "y_m", value=None)),
    _verify("marker-missing-z", "'z_m'", _drop("markers", 0, "z_m")),
    _verify("marker-id-number", "id", _set("markers", 0, "id", value=7)),
    _verify("marker-duplicate", "more than once", _dup_marker),
    _verify("station-1e400", "finite", _set("stations", 0, "z_m", value="__RAW__"),
            raw="-1e400"),
    _verify("station-1e300", "magnitude", _set("stations", 0, "x_m", value=1e300)),
    _verify("station-heading-text", "heading_rad", _set("stations", 0, "heading_rad",
                                                        value="north")),
    _verify("station-predicted-negative", "predicted_error_m",
            _set("stations", 0, "predicted_error_m", value=-1)),
    _verify("station-markers-text", "markers", _set("stations", 0, "markers", value="C1")),
    _verify("station-unknown-marker", "not among", _set("stations", 0, "markers",
                                                        value=["nope"])),
    _verify("marker-off-dem", "at (500.00, ", _set("markers", 0, "x_m", value=500.0)),
    _verify("station-off-dem", "station S3 at (500.00, ", _set("stations", 2, "x_m", value=500.0)),
    _verify("site-seed-text", "seed", _set("site", "seed", value="0")),
    _verify("site-radius-zero", "marker_radius_m", _set("site", "marker_radius_m", value=0)),
    _verify("provenance-no-sha", "config_sha256", _drop("provenance", "config_sha256")),
    _verify("provenance-dem-number", "dem", _set("provenance", "inputs", "dem", value=3)),
    Case("verify-missing", ["verify", "nope.json", "--out", "out"], "file not found"),
    Case("verify-no-plan", ["verify", "--out", "out"], "PLAN", 2),
    Case("verify-plan-folder", ["verify", "d", "--out", "out"], "directory", 2,
         setup=lambda cwd, inputs: (cwd / "d").mkdir()),
]

REDUCE_CASES = [
    _reduce("plan-list", "JSON object", text="[]"),
    _reduce("plan-not-utf8", "not UTF-8", text=b'{"markers": "\xff"}'),
    _reduce("plan-missing-markers", "missing 'markers'", _drop("markers")),
    _reduce("plan-no-markers", "'markers' is empty", _set("markers", value=[])),
    _reduce("plan-no-stations", "'stations' is empty", _set("stations", value=[])),
    _reduce("plan-future-schema", "upgrade markerplan", _set("schema_version", value=2)),
    _reduce("plan-marker-nan", "not a JSON file", _set("markers", 0, "x_m", value="__RAW__"),
            raw="NaN"),
    _reduce("plan-marker-list", "markers[1]", _set("markers", 1, value=[1, 2, 3])),
    _reduce("plan-config-list", "config", _set("provenance", "config", value=[])),
    _reduce("plan-config-range", "max_range_m", _set("provenance", "config", "max_range_m",
                                                     value=1e6)),
    _reduce("plan-site-name-number", "name", _set("site", "name", value=1)),
    _reduce("plan-site-list", "site", _set("site", value=["default"])),
    _reduce("plan-station-moved", "planned at (3.00, 0.00) m",
            _set("stations", 0, "x_m", value=3.0)),
    Case("reduce-plan-on-another-site", ["reduce", "{inputs}/plan/plan.json", "--site", "large",
                                         "--out", "out"], "site preset 'large'"),
    Case("reduce-station-ids-not-in-plan", ["reduce", "p.json", "--station-ids", "S2", "--out",
                                            "out"], "unknown planned station id(s) S2",
         setup=_edit_plan(_keep_first_station)),
    Case("reduce-csv-ragged", ["reduce", "m.csv", "--out", "out"], "row 3 has 2",
         files={"m.csv": "id,x_m,y_m\nM1,1,1\nM2,1\n"}),
    Case("reduce-csv-nan", ["reduce", "m.csv", "--out", "out"], "finite",
         files={"m.csv": "id,x_m,y_m\nM1,nan,1\n"}),
    Case("reduce-csv-duplicate", ["reduce", "m.csv", "--out", "out"], "more than once",
         files={"m.csv": "id,x_m,y_m\nM1,1,1\nM1,2,2\n"}),
    Case("reduce-csv-not-utf8", ["reduce", "m.csv", "--out", "out"], "not UTF-8",
         files={"m.csv": NOT_UTF8}),
    Case("reduce-csv-missing-column", ["reduce", "m.csv", "--out", "out"], "missing column",
         files={"m.csv": "name,x,y\nM1,1,1\n"}),
    Case("reduce-config", ["reduce", "{inputs}/plan/plan.json", "--config", "c.toml", "--out",
                           "out"], "n_sectors", files={"c.toml": "n_sectors = 0\n"}),
    Case("reduce-missing", ["reduce", "nope.json", "--out", "out"], "file not found"),
]

CASES = (CONFIG_CASES + STATIONS_CASES + TERRAIN_CASES + POLYGON_CASES + EXISTING_CASES
         + VISIBILITY_CASES + VERIFY_CASES + REDUCE_CASES)


def test_case_names_are_unique():
    names = [c.name for c in CASES]
    assert len(names) == len(set(names)) and len(names) >= 50


@pytest.mark.parametrize("case", CASES, ids=str)
def test_refused(case, capsys, monkeypatch, tmp_path, valid_inputs):
    check_refused(case, capsys, monkeypatch, tmp_path, valid_inputs)
