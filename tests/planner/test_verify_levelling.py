"""``verify --network --body``: the simulated rover levels itself to a curved body's vertical, and
the adjustment's plane prior shows the ``D^2 / 2R`` bias that the curved prior removes.

A short noise-free traverse on a small sphere (R 20 km: the bias of 381 m on the Moon at 40 m)
through the real chain (:func:`planner.verify.network.scan_plan` and
:func:`~planner.verify.network.verify_scan`), with few turntable frames
(``benchmarks/curvature_verify.py``, which runs the Moon at 380 m).
"""

import importlib.util
import sys
from pathlib import Path

import pytest

from markerplan.errors import ConfigError
from pipeline.network.body import Body
from planner.outputs.plan_file import load_plan
from planner.verify.levelling import levelled_tilts
from planner.verify.network import NetworkVerifySettings

SPHERE = Body("sphere", 20_000.0)


def _benchmark():
    path = Path(__file__).parents[2] / "benchmarks" / "curvature_verify.py"
    spec = importlib.util.spec_from_file_location("curvature_verify", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclass looks its module up
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def traverse(tmp_path_factory):
    bench = _benchmark()
    return bench, bench.traverse_plan(tmp_path_factory.mktemp("curved"), 3, 20.0)


def test_stations_level_to_the_vertical_about_the_datum(traverse):
    plan = load_plan(traverse[1])
    assert levelled_tilts(plan, Body()) is None
    tilt = levelled_tilts(plan, SPHERE)
    # heading along +x: pitch d / R, no roll; the datum S01 is the tangent point
    assert tilt["S01"] == (0.0, 0.0)
    assert tilt["S03"][1] == pytest.approx(40.0 / SPHERE.radius_m, rel=1e-3)
    assert abs(tilt["S03"][0]) < 1e-12
    about_s02 = levelled_tilts(plan, SPHERE, "S02")
    assert about_s02["S02"] == (0.0, 0.0) and about_s02["S01"][1] < 0.0
    with pytest.raises(ConfigError, match="not among the stations verified"):
        levelled_tilts(plan, SPHERE, "S03", ["S01", "S02"])


def test_plane_prior_shows_the_sagitta_and_the_curved_prior_removes_it(traverse):
    bench, plan_path = traverse
    figures = bench.verify_curved(plan_path, SPHERE, {"plane": Body(), "curved": SPHERE},
                                  frames_per_turn=100)
    sagitta = 40.0 ** 2 / (2 * SPHERE.radius_m)  # 40 mm
    plane, curved = figures["plane"], figures["curved"]
    # the truth records the tilt the rover levelled to
    truth = figures["truth_tilt_rad"]
    assert truth["S01"] == [0.0, 0.0]
    assert truth["S03"][1] == pytest.approx(40.0 / SPHERE.radius_m, rel=1e-3)
    assert plane["body"] == "plane" and curved["body"] == "sphere"
    assert plane["far_marker_dz_m"] == pytest.approx(sagitta, rel=0.15)
    assert abs(curved["far_marker_dz_m"]) < 0.1 * sagitta
    assert curved["far_station_error_m"] < 0.1 * plane["far_station_error_m"]


def test_the_settings_record_the_body_unless_plane():
    assert "body" not in NetworkVerifySettings().record()
    assert NetworkVerifySettings(body=SPHERE).record()["body"] == SPHERE.to_dict()
    with pytest.raises(ConfigError, match="`body` must be a Body"):
        NetworkVerifySettings(body="moon")
