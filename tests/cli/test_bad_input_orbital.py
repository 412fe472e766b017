"""Terrain known only from orbit: a bad height error, ``--terrain orbital`` with ``--dem`` or on
a preset without one, and a ``--truth-dem`` that is unreadable or does not cover the plan, each
refused in one line before any work (:func:`tests.cli.bad_input.check_refused`)."""

from pathlib import Path

import numpy as np
import pytest

from tests.cli.bad_input import Case, check_refused

PLAN = ["plan", "--out", "out"]
VERIFY = ["verify", "{inputs}/plan/plan.json", "--out", "out"]
ON_DEM = ["--dem", "{inputs}/dem.npz", "--stations", "{inputs}/stations.csv"]
#: click's verdict on a value of --dem-height-error.
BAD_VALUE = "invalid value for '--dem-height-error'"


def _small_dem(cwd: Path, inputs: Path) -> None:
    """Setup: a 10 m x 10 m flat DEM around the origin (the default site's plan spans
    +-20 m): ``small.npz``."""
    from visibility.dem import DEM, write_dem

    write_dem(cwd / "small.npz", DEM(np.zeros((101, 101)), (-5.0, -5.0), 0.1))


CASES = [
    Case("height-error-negative", PLAN + ["--terrain", "orbital", "--dem-height-error", "-0.1"],
         f"{BAD_VALUE}: height error RMS -0.1 m is outside [0, 50] m", code=2),
    Case("height-error-nan", PLAN + ["--terrain", "orbital", "--dem-height-error", "nan"],
         f"{BAD_VALUE}: height error RMS 'nan' is not a finite number", code=2),
    Case("height-error-absurd", PLAN + ["--terrain", "orbital", "--dem-height-error", "80"],
         "height error RMS 80 m is outside [0, 50] m; give the DEM's 1-sigma", code=2),
    Case("height-error-inf", PLAN + ["--terrain", "orbital", "--dem-height-error", "inf,10"],
         "is not a finite number", code=2),
    Case("height-error-correlation-zero",
         PLAN + ["--terrain", "orbital", "--dem-height-error", "0.3,0"],
         "correlation length 0 m is outside (0, 10000] m", code=2),
    Case("height-error-correlation-negative",
         PLAN + ["--terrain", "orbital", "--dem-height-error", "0.3,-4"],
         "correlation length -4 m is outside", code=2),
    Case("height-error-correlation-text",
         PLAN + ["--terrain", "orbital", "--dem-height-error", "0.3,far"],
         "'far' is not a finite number", code=2),
    Case("height-error-three-numbers",
         PLAN + ["--terrain", "orbital", "--dem-height-error", "0.3,10,2"],
         "give RMS_M or RMS_M,CORRELATION_M", code=2),
    Case("height-error-on-exact-truth", PLAN + ["--dem-height-error", "0.3"],
         "--dem-height-error declares the error of a --dem FILE or of --terrain orbital"),
    Case("terrain-orbital-with-dem", PLAN + ["--terrain", "orbital"] + ON_DEM,
         "--terrain orbital is a site preset's planning DEM and --dem"),
    Case("terrain-unknown", PLAN + ["--terrain", "lidar"], "invalid value for '--terrain'",
         code=2),
    Case("terrain-orbital-km", PLAN + ["--site", "km", "--terrain", "orbital"],
         "site preset 'km' has no orbital planning DEM"),
    Case("truth-dem-not-covering", VERIFY + ["--truth-dem", "small.npz"],
         "--truth-dem small.npz does not cover S2, S3", setup=_small_dem),
    Case("truth-dem-unreadable", VERIFY + ["--truth-dem", "junk.tif"], "--truth-dem junk.tif",
         files={"junk.tif": b"not a raster at all"}),
    Case("truth-dem-missing", VERIFY + ["--truth-dem", "none.tif"], "--truth-dem none.tif"),
]


@pytest.mark.parametrize("case", CASES, ids=str)
def test_refused(case, capsys, monkeypatch, tmp_path, valid_inputs):
    check_refused(case, capsys, monkeypatch, tmp_path, valid_inputs)
