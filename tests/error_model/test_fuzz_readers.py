"""Fuzzing the error model's readers: a mutated model JSON or marker table either reads into a
usable object or raises a one-line :class:`~markerplan.errors.MarkerPlanError`, never anything
else."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from error_model.default import DEFAULT_MODEL_PATH
from error_model.model import ErrorModel
from error_model.table import fit_data, read_marker_tables
from markerplan.errors import MarkerPlanError
from tests.error_model.synthetic import synthetic_table, write_csv
from tests.json_paths import json_paths

FAST = settings(max_examples=100, deadline=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture])

VALID = json.loads(DEFAULT_MODEL_PATH.read_text())

#: Values a mutation puts in place of a valid one: other types, non-finite, absurd, signs.
ODD_VALUES = st.sampled_from([None, True, False, "", "x", "0.95", [], {}, [1], {"a": 1}, 0, 1,
                              -1, 2, 0.0, -0.5, 1.5, 1e300, -1e300, math.nan, math.inf,
                              -math.inf, 10**400, [math.nan], [1e300, 1.0], "NaN"])


#: Paths into the parts of the model the reader interprets (``info`` is kept verbatim).
INTERPRETED = [p for p in json_paths(VALID) if p and p[0] in
               ("format", "format_version", "predictors", "basis", "sigma", "envelope",
                "domain")]


def _mutate(doc, path, action, value):
    parent = doc
    for key in path[:-1]:
        parent = parent[key]
    if not isinstance(parent, dict | list):  # an earlier mutation replaced the container
        return
    last = path[-1]
    if action == "drop":
        if isinstance(parent, dict):
            del parent[last]
        else:
            parent.pop(last)
    elif action == "scale" and isinstance(parent[last], int | float) \
            and not isinstance(parent[last], bool):
        parent[last] = parent[last] * value if isinstance(value, float) else value
    else:
        parent[last] = value


def _check_load(path):
    try:
        model = ErrorModel.load(path)
    except MarkerPlanError as exc:
        assert "\n" not in str(exc)
        return None
    # a model that loads predicts a positive, finite error inside its domain
    dom = model.domain
    d = np.asarray(dom.band_edges_m[:-1])
    e = 0.5 * (np.asarray(dom.elevation_lo_rad) + np.asarray(dom.elevation_hi_rad))
    extras = {x: np.full(d.size, dom.extras[x][1]) for x in model.basis.extras}
    p = model.predict(d, e, **extras)
    assert np.isfinite(p.sigma_m).all() and (p.sigma_m > 0).all()
    assert np.isfinite(p.q95_m).all() and (p.q95_m > 0).all()
    return model


def test_shipped_model_loads():
    assert _check_load(DEFAULT_MODEL_PATH) is not None


@FAST
@given(mutations=st.lists(st.tuples(st.sampled_from(INTERPRETED),
                                    st.sampled_from(["drop", "set", "scale"]), ODD_VALUES),
                          min_size=1, max_size=3))
def test_mutated_model_json_is_read_or_refused(tmp_path_factory, mutations):
    doc = json.loads(json.dumps(VALID))
    for path, action, value in mutations:
        try:
            _mutate(doc, path, action, value)
        except (KeyError, IndexError, TypeError, OverflowError):
            pass  # an earlier mutation removed or replaced the parent (or made it a huge
            # integer that a float scale cannot multiply): skip this one
    path = tmp_path_factory.mktemp("fuzz") / "m.json"
    try:
        text = json.dumps(doc)  # NaN and Infinity written as the non-JSON tokens
    except (ValueError, OverflowError):
        return
    path.write_text(text)
    _check_load(path)


@FAST
@given(cut=st.integers(0, 4000), junk=st.binary(max_size=40))
def test_damaged_model_bytes_are_read_or_refused(tmp_path_factory, cut, junk):
    data = DEFAULT_MODEL_PATH.read_bytes()
    path = tmp_path_factory.mktemp("fuzz") / "m.json"
    path.write_bytes(data[:cut] + junk + data[cut + len(junk):])
    _check_load(path)


@FAST
@given(doc=st.recursive(st.none() | st.booleans() | st.floats() | st.integers()
                        | st.text(max_size=5),
                        lambda kids: st.lists(kids, max_size=3)
                        | st.dictionaries(st.sampled_from(list(VALID)), kids, max_size=4),
                        max_leaves=12))
def test_arbitrary_json_is_refused(tmp_path_factory, doc):
    path = tmp_path_factory.mktemp("fuzz") / "m.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(MarkerPlanError) as exc:
        ErrorModel.load(path)
    assert "\n" not in str(exc.value)


# --- marker tables -----------------------------------------------------------------------

_TABLE = synthetic_table(40, seed=5)
ODD_CELLS = st.sampled_from(["", "nan", "NaN", "inf", "-inf", "1e300", "-1e400", "x", "1,2",
                             '"', "true", "maybe", "0", "-1", "1e5", " 3 ", "\x00", "é",
                             "9" * 400])


def _table_text(tmp_path_factory) -> list[str]:
    path = tmp_path_factory.mktemp("fuzz") / "t.csv"
    write_csv(path, _TABLE)
    return path.read_text().splitlines()


@FAST
@given(edits=st.lists(st.tuples(st.integers(0, 40), st.integers(0, 25), ODD_CELLS),
                      max_size=4),
       drop_lines=st.lists(st.integers(0, 40), max_size=3), data=st.data())
def test_mutated_marker_table_is_read_or_refused(tmp_path_factory, edits, drop_lines, data):
    lines = _table_text(tmp_path_factory)
    rows = [ln.split(",") for ln in lines]
    for r, c, value in edits:
        row = rows[min(r, len(rows) - 1)]
        if c < len(row):
            row[c] = value
        else:
            row.append(value)
    keep = [r for i, r in enumerate(rows) if i not in set(drop_lines)]
    text = "\n".join(",".join(r) for r in keep) + "\n"
    encoding = data.draw(st.sampled_from(["utf-8", "latin-1", "utf-16"]))
    path = tmp_path_factory.mktemp("fuzz") / "t.csv"
    try:
        path.write_bytes(text.encode(encoding))
    except UnicodeEncodeError:
        return
    try:
        table = read_marker_tables([path, path] if data.draw(st.booleans()) else [path])
    except MarkerPlanError as exc:
        assert "\n" not in str(exc)
        return
    for name, col in table.columns.items():
        if col.dtype.kind == "f":
            finite = col[np.isfinite(col)]
            assert np.abs(finite).max(initial=0) <= 2.0**64, name
    try:
        fit_data(table, 5, ["visible_fraction", "expected_points"],
                 estimator=data.draw(st.sampled_from([None, "hemisphere_icp", "other"])))
    except MarkerPlanError as exc:
        assert "\n" not in str(exc)


@FAST
@given(data=st.binary(max_size=300))
def test_random_bytes_table_is_read_or_refused(tmp_path_factory, data):
    path = tmp_path_factory.mktemp("fuzz") / "t.csv"
    path.write_bytes(b"distance_m,elevation_deg,error_m,accepted\n" + data)
    try:
        read_marker_tables(path)
    except MarkerPlanError as exc:
        assert "\n" not in str(exc)
