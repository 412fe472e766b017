import json
from types import SimpleNamespace

import numpy as np
import pytest

from markerplan.errors import ConfigError, DataError, InputFileError
from planner.config import PlanConfig
from planner.problem.candidates import candidate_sites, ground_slope_rad, load_polygons
from visibility.dem import DEM


def _dem():
    # 20 m x 20 m, flat except a 45-degree ramp for x > 5 (rising 1 m per m)
    x = np.arange(-10.0, 10.0 + 1e-9, 0.1)
    xx, yy = np.meshgrid(x, x)
    return DEM(np.where(xx > 5.0, xx - 5.0, 0.0), (-10.0, -10.0), 0.1)


def test_grid_boundary_exclusion_slope_stations_and_craters():
    dem = _dem()
    cfg = PlanConfig(grid_spacing_m=1.0, max_slope_deg=20.0, min_station_distance_m=2.0,
                     exclude_crater_interiors=True)
    boundary = [[-8, -8], [8, -8], [8, 8], [-8, 8]]
    exclusion = [[-8, -8], [-4, -8], [-4, 8], [-8, 8]]
    crater = SimpleNamespace(centre_xy_m=(0.0, -5.0), diameter_m=2.0)
    c = candidate_sites(dem, cfg, boundary=boundary, exclusions=[exclusion],
                        station_xy=[[0.0, 5.0]], craters=[crater], marker_radius_m=0.1)
    xy = c.centre_m[:, :2]
    assert np.all((xy >= -8) & (xy <= 8))
    assert np.all(xy[:, 0] > -4)  # exclusion zone
    assert np.all(xy[:, 0] < 5)  # the 45-degree ramp is too steep
    assert np.all(np.hypot(xy[:, 0], xy[:, 1] - 5.0) >= 2.0)
    assert np.all(np.hypot(xy[:, 0], xy[:, 1] + 5.0) >= 1.0)
    assert np.allclose(c.centre_m[:, 2], dem.height_at(xy) + 0.1)
    assert set(c.dropped) == {"outside boundary", "excluded zone", "near station",
                              "out of range", "crater interior", "too steep"}
    assert c.dropped["out of range"] == 0  # 30 m range: the 16 m square is all in it
    assert len(set(c.ids)) == len(c)
    # grid spacing: neighbours 1 m apart
    assert np.isclose(np.min(np.diff(np.unique(xy[:, 0]))), 1.0)


def test_slope_of_a_ramp():
    assert np.allclose(ground_slope_rad(_dem(), np.array([[7.0, 0.0], [0.0, 0.0]])),
                       [np.pi / 4, 0.0], atol=1e-9)


def test_empty_candidate_set_is_a_one_line_error():
    with pytest.raises(DataError, match="no candidate marker site") as exc:
        candidate_sites(_dem(), PlanConfig(), exclusions=[[[-11, -11], [11, -11], [11, 11],
                                                          [-11, 11]]])
    assert "\n" not in str(exc.value)
    with pytest.raises(DataError, match="does not overlap"):
        candidate_sites(_dem(), PlanConfig(), boundary=[[50, 50], [60, 50], [60, 60]])


def test_geojson_polygons_and_malformed_ones(tmp_path):
    good = {"type": "FeatureCollection", "features": [
        {"type": "Feature", "properties": {},
         "geometry": {"type": "Polygon", "coordinates": [[[0, 0], [1, 0], [1, 1], [0, 0]]]}}]}
    p = tmp_path / "ok.geojson"
    p.write_text(json.dumps(good))
    assert load_polygons(p)[0].area == pytest.approx(0.5)
    bowtie = {"type": "Polygon", "coordinates": [[[0, 0], [1, 1], [1, 0], [0, 1], [0, 0]]]}
    cases = {"bowtie": (bowtie, "invalid polygon"),
             "point": ({"type": "Point", "coordinates": [0, 0]}, "Polygon or MultiPolygon"),
             "flat": ({"type": "Polygon", "coordinates": [[[0, 0], [1, 0], [2, 0], [0, 0]]]},
                      "zero area"),
             "short": ({"type": "Polygon", "coordinates": [[[0, 0], [1, 0]]]}, "malformed")}
    for name, (geom, msg) in cases.items():
        f = tmp_path / f"{name}.geojson"
        f.write_text(json.dumps(geom))
        with pytest.raises(InputFileError, match=msg):
            load_polygons(f)
    bad = tmp_path / "bad.geojson"
    bad.write_text("{not json")
    with pytest.raises(InputFileError, match="not valid JSON"):
        load_polygons(bad)


def test_sites_out_of_range_of_every_station_are_dropped():
    # flat 20 m x 20 m, one station at (-5, 0): range 6 m + 0.1 m radius
    dem = DEM(np.zeros((201, 201)), (-10.0, -10.0), 0.1)
    cfg = PlanConfig(grid_spacing_m=1.0, max_range_m=6.0, min_station_distance_m=1.0)
    near = candidate_sites(dem, cfg, station_xy=[[-5.0, 0.0, 1.5]])
    wide = candidate_sites(dem, cfg.replace(max_range_m=100.0), station_xy=[[-5.0, 0.0]])
    d_wide = np.hypot(wide.centre_m[:, 0] + 5.0, wide.centre_m[:, 1])
    keep = d_wide <= 6.1
    np.testing.assert_array_equal(near.centre_m, wide.centre_m[keep])
    assert near.dropped["out of range"] == int((~keep).sum()) > 0
    assert wide.dropped["out of range"] == 0
    assert near.dropped["near station"] == wide.dropped["near station"] == 4
    assert list(near.dropped) == ["outside boundary", "near station", "out of range",
                                  "too steep"]


def test_grid_limit_counts_the_sites_in_range(monkeypatch):
    import planner.problem.candidates as candidates

    dem = DEM(np.zeros((201, 201)), (-10.0, -10.0), 0.1)
    cfg = PlanConfig(grid_spacing_m=0.5, max_range_m=2.0, min_station_distance_m=0.5)
    monkeypatch.setattr(candidates, "MAX_GRID_POINTS", 100)
    kept = candidate_sites(dem, cfg, station_xy=[[0.0, 0.0]])  # 1600 grid points, ~50 in range
    assert len(kept) < 100
    with pytest.raises(ConfigError, match="candidate sites in range of a station.*more than "
                                          "the 100 accepted"):
        candidate_sites(dem, cfg.replace(max_range_m=10.0), station_xy=[[0.0, 0.0]])
    monkeypatch.setattr(candidates, "MAX_RAW_GRID_POINTS", 1000)
    with pytest.raises(ConfigError, match="1.6e\\+03 candidate grid points"):
        candidate_sites(dem, cfg, station_xy=[[0.0, 0.0]])


def test_dropping_out_of_range_sites_leaves_the_plan_unchanged(monkeypatch):
    """The default site planned with a 12 m range: the same markers (by position) whether or not
    the sites out of every station's range were ray cast."""
    import planner.run as run
    from error_model import default_model
    from planner.problem.inputs import load_inputs

    inputs = load_inputs("default")
    cfg = PlanConfig(max_range_m=12.0)
    model = default_model()
    dropped = run.make_plan(inputs, cfg, model, progress=False)
    kept_all = run.candidate_sites

    def no_range_drop(dem, config, **kw):
        return kept_all(dem, config.replace(max_range_m=100.0), **kw)

    monkeypatch.setattr(run, "candidate_sites", no_range_drop)
    full = run.make_plan(inputs, cfg, model, progress=False)
    assert dropped.candidates.dropped["out of range"] > 0
    assert len(full.candidates) > len(dropped.candidates)

    def chosen(outcome):
        xyz = outcome.problem.site_xyz[outcome.result.selected]
        return xyz[np.lexsort(xyz.T)]

    assert dropped.result.status == full.result.status
    np.testing.assert_array_equal(chosen(dropped), chosen(full))
