"""Fuzzing the planner's input readers: any file gives a valid result or a MarkerPlanError.

Each reader gets random bytes, random text and structured-but-corrupted content (CSV cells,
TOML values, JSON trees) and must either return a value its callers can use or raise one of
our errors — never a ``KeyError``, ``TypeError``, ``ValueError`` or NaN reaching the planner.
"""

from __future__ import annotations

import functools
import json
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from markerplan.errors import MarkerPlanError
from planner.config import BOUNDS, PlanConfig, load_config
from planner.outputs.plan_file import read_plan
from planner.problem.candidates import load_polygons
from planner.problem.inputs import read_markers, read_stations
from planner.problem.visibility_table import REQUIRED, read_visibility_table
from planner.reduction.study import _plan_layout
from tests.json_paths import json_paths

FAST = settings(max_examples=60, deadline=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


@functools.cache
def _dem():
    from visibility.sites import load_site

    return load_site("default").dem


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    return tmp_path_factory.mktemp("fuzz")


def _write(folder, name, content) -> object:
    path = folder / name
    if isinstance(content, str):
        content = content.encode("utf-8", "surrogatepass")
    path.write_bytes(content)
    return path


def _refused_or(call):
    """``call()``'s result, or None when it raised one of our errors."""
    try:
        return call()
    except MarkerPlanError as exc:
        assert "\n" not in str(exc), str(exc)
        return None


# --- strategies ---------------------------------------------------------------------------

NUMBERS_AS_TEXT = st.one_of(
    st.sampled_from(["nan", "inf", "-inf", "1e300", "-1e400", "", " ", "0", "1", "-5", "3.5",
                     "1e-320", "0x10", "1_0", "NaN", "infinity", "+2", "1e6"]),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(-10**30, 10**30).map(str))
CELL = st.one_of(NUMBERS_AS_TEXT, st.text(max_size=8),
                 st.sampled_from(["S1", "S2", "M1", "A", "1", "true", "0", "yes"]))
JSON_LEAF = st.one_of(st.none(), st.booleans(), st.integers(-10**20, 10**20),
                      st.floats(allow_nan=False, allow_infinity=False), st.text(max_size=6))
JSON = st.recursive(JSON_LEAF, lambda c: st.one_of(
    st.lists(c, max_size=4), st.dictionaries(st.text(max_size=6), c, max_size=4)),
    max_leaves=20)


def _csv(header, rows) -> str:
    import csv
    import io

    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(header)
    w.writerows(rows)
    return buf.getvalue()


@st.composite
def csv_tables(draw, columns):
    header = draw(st.lists(st.sampled_from([*columns, "extra", ""]), min_size=1, max_size=7)
                  | st.permutations(list(columns)))
    width = st.integers(max(len(header) - 1, 0), len(header) + 1)
    rows = draw(st.lists(width.flatmap(lambda n: st.lists(CELL, min_size=n, max_size=n)),
                         max_size=5))
    return _csv(header, rows)


RAW = st.one_of(st.binary(max_size=64), st.text(max_size=64))


# --- load_config --------------------------------------------------------------------------

TOML_VALUE = st.one_of(
    st.sampled_from(["nan", "inf", "-inf", "1e6", "1e-6", "0", "-1", "true", '"0.1"', "[]",
                     "[1, 2]", '["A", "A"]', "1979-05-27", "{a = 1}", "99999999999999999999",
                     "6.5", "1e308"]),
    st.integers(-10**6, 10**6).map(str),
    st.floats(allow_nan=False, allow_infinity=False).map(repr))


@FAST
@given(st.one_of(RAW, st.lists(st.tuples(st.sampled_from([*BOUNDS, "existing", "redundant",
                                                          "nope"]), TOML_VALUE),
                               max_size=4).map(
    lambda kv: "".join(f"{k} = {v}\n" for k, v in dict(kv).items()))))
def test_load_config(folder, content):
    path = _write(folder, "c.toml", content)
    cfg = _refused_or(lambda: load_config(path))
    if cfg is not None:
        assert isinstance(cfg, PlanConfig)
        for name, (lo, _, hi, _) in BOUNDS.items():
            v = getattr(cfg, name)
            assert v is None or (math.isfinite(v) and lo <= v <= hi)


# --- stations and markers -----------------------------------------------------------------


@FAST
@given(st.one_of(RAW, csv_tables(("id", "x_m", "y_m", "z_m", "heading_deg"))))
def test_read_stations_csv(folder, content):
    path = _write(folder, "s.csv", content)
    out = _refused_or(lambda: read_stations(path, _dem(), 1.0))
    if out is not None:
        ids, xyz, heading = out
        assert len(set(ids)) == len(ids) == len(xyz) == len(heading) > 0
        assert np.isfinite(xyz).all() and np.isfinite(heading).all()


@st.composite
def point_collections(draw):
    def feature(coords, props):
        return {"type": "Feature", "geometry": {"type": "Point", "coordinates": coords},
                "properties": props}
    coords = st.one_of(st.lists(st.floats(-40, 40), min_size=2, max_size=3), JSON)
    props = st.one_of(st.none(), st.fixed_dictionaries(
        {}, optional={"id": st.one_of(st.text(max_size=3), JSON_LEAF),
                      "heading_deg": JSON_LEAF}), JSON)
    feats = draw(st.lists(st.one_of(st.builds(feature, coords, props), JSON), max_size=4))
    doc = draw(st.sampled_from([{"type": "FeatureCollection", "features": feats},
                                {"type": "FeatureCollection"}, feats, {"features": feats}]))
    return json.dumps(doc)


@FAST
@given(st.one_of(RAW, point_collections(), JSON.map(json.dumps)))
def test_read_points_geojson(folder, content):
    path = _write(folder, "p.geojson", content)
    out = _refused_or(lambda: read_markers(path, _dem(), 0.1, option="INPUT"))
    if out is not None:
        ids, xyz = out
        assert len(set(ids)) == len(ids) == len(xyz) > 0 and np.isfinite(xyz).all()


# --- visibility table ---------------------------------------------------------------------


@FAST
@given(st.one_of(RAW, csv_tables((*REQUIRED, "distance_m"))))
def test_read_visibility_table(folder, content):
    path = _write(folder, "v.csv", content)
    xyz = np.array([[0.0, 0.0, 1.0], [5.0, 0.0, 1.0]])
    problem = _refused_or(lambda: read_visibility_table(path, ["S1", "S2"], xyz))
    if problem is not None:
        assert np.isfinite(problem.site_xyz).all()
        assert (problem.pair_sigma_m > 0).all() and np.isfinite(problem.pair_sigma_m).all()
        assert (problem.pair_distance_m >= 0).all()


# --- GeoJSON polygons ---------------------------------------------------------------------

RING = st.lists(st.lists(st.floats(-50, 50), min_size=2, max_size=2), min_size=3, max_size=6) \
    .map(lambda r: [*r, r[0]])


@FAST
@given(st.one_of(RAW, JSON.map(json.dumps),
                 st.builds(lambda rings, kind: json.dumps({"type": kind, "coordinates": rings}),
                           st.one_of(st.lists(RING, min_size=1, max_size=2), JSON),
                           st.sampled_from(["Polygon", "MultiPolygon", "Point"]))))
def test_load_polygons(folder, content):
    path = _write(folder, "x.geojson", content)
    polys = _refused_or(lambda: load_polygons(path, "--exclude"))
    if polys is not None:
        assert polys and all(p.is_valid and p.area > 0 for p in polys)


# --- plan.json ----------------------------------------------------------------------------


def _valid_plan() -> dict:
    return {"schema": "markerplan-plan", "schema_version": 1,
            "provenance": {"config": {"requirement_m": 0.1}, "config_sha256": "ab",
                           "inputs": {"site": "default"}},
            "site": {"name": "default", "seed": 0, "marker_radius_m": 0.1},
            "requirement": {"requirement_m": 0.1, "working_radius_m": 10.0},
            "markers": [{"id": "C1", "x_m": 1.0, "y_m": 2.0, "z_m": 0.1},
                        {"id": "C2", "x_m": -3.0, "y_m": 2.0, "z_m": 0.1}],
            "stations": [{"id": "S1", "x_m": 0.0, "y_m": 0.0, "z_m": 1.0, "heading_rad": 0.0,
                          "predicted_error_m": 0.01, "markers": ["C1", "C2"]}]}


PLAN_PATHS = [p for p in json_paths(_valid_plan()) if p]


@st.composite
def corrupted_plans(draw):
    doc = _valid_plan()
    for _ in range(draw(st.integers(1, 3))):
        path = draw(st.sampled_from(PLAN_PATHS))
        parent = doc
        try:
            for k in path[:-1]:
                parent = parent[k]
            if draw(st.booleans()) and isinstance(parent, dict):
                parent.pop(path[-1], None)
            else:
                parent[path[-1]] = draw(st.one_of(JSON, st.sampled_from(
                    [1e300, -0.0, 2, "1", [], {}, None, True])))
        except (KeyError, IndexError, TypeError):
            pass  # an earlier change removed the path
    return json.dumps(doc)


def _use_like_verify(doc):
    """What ``verify`` reads from an accepted plan."""
    float(doc["requirement"]["requirement_m"])
    float(doc["requirement"]["working_radius_m"])
    float(doc["site"].get("marker_radius_m", 0.10))
    doc["site"]["name"].strip()
    centres = np.array([[m["x_m"], m["y_m"], m["z_m"]] for m in doc["markers"]], float)
    assert np.isfinite(centres).all()
    for s in doc["stations"]:
        pos = np.array([s["x_m"], s["y_m"], s["z_m"]], float)
        assert np.isfinite(pos).all() and math.isfinite(float(s.get("heading_rad") or 0.0))
        sorted(set(s.get("markers", [])))
    assert doc["stations"] and isinstance(doc["provenance"]["config_sha256"], str)


@FAST
@given(st.one_of(RAW, JSON.map(json.dumps), corrupted_plans()))
def test_read_plan(folder, content):
    path = _write(folder, "plan.json", content)
    doc = _refused_or(lambda: read_plan(path, "PLAN", full=True))
    if doc is not None:
        _use_like_verify(doc)
    doc = _refused_or(lambda: read_plan(path, "INPUT", full=False))
    if doc is not None:
        layout = _plan_layout(doc, path)
        assert np.isfinite(layout.xyz).all() and len(set(layout.ids)) == len(layout.ids) > 0
        config = doc.get("provenance", {}).get("config", {})
        assert isinstance(config, dict)


@pytest.mark.slow
@settings(max_examples=1000, deadline=None, suppress_health_check=list(HealthCheck))
@given(st.one_of(RAW, corrupted_plans()))
def test_read_plan_long(folder, content):
    test_read_plan.hypothesis.inner_test(folder, content)
