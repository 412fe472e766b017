"""ErrorModel: prediction API, domain flags, JSON round trip and corrupted files."""

from __future__ import annotations

import json

import numpy as np
import pytest

from error_model.model import ErrorModel
from markerplan.errors import ConfigError, InputFileError


def test_json_round_trip_predicts_identically(fitted_model, tmp_path):
    path = fitted_model.save(tmp_path / "m.json")
    loaded = ErrorModel.load(path)
    d = np.linspace(1, 60, 50)
    e = np.deg2rad(np.linspace(-40, 20, 50))
    a, b = fitted_model.predict(d, e), loaded.predict(d, e)
    np.testing.assert_array_equal(a.sigma_m, b.sigma_m)
    np.testing.assert_array_equal(a.q95_m, b.q95_m)
    np.testing.assert_array_equal(a.in_domain, b.in_domain)
    assert loaded.to_json() == json.loads(path.read_text())
    assert not list(tmp_path.glob(".*partial*"))


def test_predict_broadcasts_and_flags_out_of_domain(fitted_model):
    p = fitted_model.predict(np.array([[0.5], [10.0], [49.0], [80.0]]), np.deg2rad([-10.0, 60.0]))
    assert p.sigma_m.shape == p.q95_m.shape == p.in_domain.shape == (4, 2)
    # fitted: 1-50 m, elevation -30..10 deg (+2 deg margin)
    np.testing.assert_array_equal(p.in_domain, [[False, False], [True, False], [True, False],
                                                [False, False]])
    assert fitted_model.in_domain(10.0, np.deg2rad(-31.0))
    assert not fitted_model.in_domain(10.0, np.deg2rad(-33.0))
    assert (p.q95_m > p.sigma_m).all()


def test_predict_checks_its_inputs(fitted_model):
    with pytest.raises(ConfigError, match="unknown keyword"):
        fitted_model.predict(10.0, 0.0, visible_fracton=0.5)
    with pytest.raises(ConfigError, match="broadcast"):
        fitted_model.predict([1.0, 2.0, 3.0], [0.1, 0.2])
    with pytest.raises(ConfigError, match="finite"):
        fitted_model.predict([1.0, np.nan], 0.0)
    # optional predictors the model does not use are ignored
    p = fitted_model.predict(10.0, -0.1, expected_points=100)
    assert p.sigma_m.shape == ()


@pytest.mark.parametrize("text, match", [
    ("{not json", "not valid JSON"),
    ('{"format": "something-else"}', "not a markerplan error model"),
    ("[1, 2]", "not a markerplan error model"),
    ("", "not valid JSON"),
])
def test_corrupted_model_file_is_a_one_line_input_file_error(tmp_path, text, match):
    path = tmp_path / "bad.json"
    path.write_text(text)
    with pytest.raises(InputFileError, match=match) as exc:
        ErrorModel.load(path)
    assert "\n" not in str(exc.value)


@pytest.mark.parametrize("mutate", [
    lambda j: j["sigma"]["coefficients"].pop(),
    lambda j: j["envelope"].pop("coefficients"),
    lambda j: j["basis"].update(distance_knots_m=[5.0, 2.0]),
    lambda j: j["domain"].update(elevation_lo_rad=[0.0]),
    lambda j: j.update(format_version=99),
    lambda j: j["sigma"]["coefficients"].__setitem__(0, None),
])
def test_structurally_broken_model_is_rejected(fitted_model, tmp_path, mutate):
    j = fitted_model.to_json()
    mutate(j)
    path = tmp_path / "m.json"
    path.write_text(json.dumps(j))
    with pytest.raises(InputFileError) as exc:
        ErrorModel.load(path)
    assert "\n" not in str(exc.value)


def test_missing_model_file(tmp_path):
    with pytest.raises(InputFileError, match="no such file"):
        ErrorModel.load(tmp_path / "absent.json")


@pytest.mark.parametrize(("mutate", "match"), [
    (lambda d: d["distance_range_m"].reverse(), r"domain distance_range_m: range \[.*\] is "
                                                r"inverted \(min > max\)"),
    (lambda d: d.update(elevation_lo_deg=d["elevation_hi_deg"],
                        elevation_hi_deg=d["elevation_lo_deg"]),
     r"domain elevation_lo_deg / elevation_hi_deg band 0: range .* is inverted"),
    (lambda d: d["distance_range_m"].__setitem__(1, 99.0), "domain distance_range_m .* differs "
                                                           "from the values it copies"),
    (lambda d: d["elevation_hi_deg"].pop(), "domain elevation_hi_deg .* differs"),
])
def test_domain_copies_must_match_what_they_copy(fitted_model, tmp_path, mutate, match):
    """The informational ``distance_range_m`` and ``*_deg`` copies of the domain are ranges that
    are not inverted and equal the band edges and elevation ranges they copy; a model without
    them still loads."""
    j = fitted_model.to_json()
    mutate(j["domain"])
    path = tmp_path / "m.json"
    path.write_text(json.dumps(j))
    with pytest.raises(InputFileError, match=match):
        ErrorModel.load(path)
    j = fitted_model.to_json()
    for key in ("distance_range_m", "elevation_lo_deg", "elevation_hi_deg"):
        del j["domain"][key]
    path.write_text(json.dumps(j))
    assert ErrorModel.load(path).domain == fitted_model.domain
