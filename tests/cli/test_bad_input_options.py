"""Options outside their documented bounds, and inputs given twice: refused before any work."""

import importlib
import math

import click
import pytest

from tests.cli.bad_input import Case, check_refused

SIM = ["simulate", "--station-ids", "S1", "--frames", "4", "--out", "out"]
RANGE = ["range-study", "--frames", "4", "--replicates", "1", "--out", "out"]
SCAN = "{inputs}/scan/station_S1.scan.npz"
PROCESS = ["process", SCAN, "--out", "out"]
PLAN = ["plan", "--out", "out"]
#: Points of a 0.1 m sphere's near half, 5 m along +x (a valid fit-sphere input).
SPHERE_POINTS = "".join(f"{5 - 0.1 * math.cos(a) * math.cos(b):.6f} "
                        f"{0.1 * math.sin(a) * math.cos(b):.6f} {0.1 * math.sin(b):.6f}\n"
                        for a in (-1.0, -0.5, 0.0, 0.5, 1.0) for b in (-1.0, -0.5, 0.0, 0.5, 1.0))
#: A sensor profile file with one block filled in by ``%``.
PROFILE = '{"format": "markerplan-sensor-profile", "format_version": 1, "name": "bad", %s}'


def usage(name, args, option, **files):
    """A click usage error (exit code 2) that names ``option`` (``files``: as :class:`Case`)."""
    return Case(name, args, option, code=2, **files)


CASES = [
    usage("simulate-negative-seed", SIM + ["--seed", "-1"], "--seed"),
    usage("simulate-negative-site-seed", SIM + ["--site-seed", "-1"], "--site-seed"),
    usage("simulate-float-seed", SIM + ["--seed", "1.5"], "--seed"),
    usage("simulate-frames-2e9", SIM + ["--frames", "2000000000"], "--frames"),
    usage("simulate-frames-2e9-float", SIM + ["--frames", "2e9"], "--frames"),
    usage("simulate-frames-zero", SIM + ["--frames", "0"], "--frames"),
    usage("simulate-range-noise-1e6", SIM + ["--range-noise-mm", "1e6"], "--range-noise-mm"),
    usage("simulate-range-noise-negative", SIM + ["--range-noise-mm", "-1"], "--range-noise-mm"),
    usage("simulate-range-noise-nan", SIM + ["--range-noise-mm", "nan"], "--range-noise-mm"),
    usage("simulate-incidence-noise-1e6", SIM + ["--incidence-noise-mm", "1e6"],
          "--incidence-noise-mm"),
    usage("simulate-rpm-5000", SIM + ["--rpm", "5000"], "--rpm"),
    usage("simulate-dropout-one", SIM + ["--dropout", "1"], "--dropout"),
    usage("simulate-lidar-height-zero", SIM + ["--lidar-height-m", "0"], "--lidar-height-m"),
    usage("simulate-lidar-height-inf", SIM + ["--lidar-height-m", "inf"], "--lidar-height-m"),
    usage("simulate-axis-error-90", SIM + ["--vertical-axis-error-deg", "90"],
          "--vertical-axis-error-deg"),
    usage("simulate-lframe-tilt-nan", SIM + ["--lframe-tilt-deg", "nan"], "--lframe-tilt-deg"),
    usage("range-study-replicates-zero", RANGE + ["--replicates", "0"], "--replicates"),
    usage("range-study-replicates-1e6", RANGE + ["--replicates", "1000000"], "--replicates"),
    usage("range-study-noise-1e6", RANGE + ["--range-noise-mm", "1e6"], "--range-noise-mm"),
    usage("range-study-max-distance-1e6", RANGE + ["--max-distance-m", "1e6"], "--max-distance-m"),
    usage("range-study-max-distance-zero", RANGE + ["--max-distance-m", "0"], "--max-distance-m"),
    usage("range-study-negative-seed", RANGE + ["--seed", "-3"], "--seed"),
    usage("range-study-lidar-height-zero", RANGE + ["--lidar-height-m", "0"], "--lidar-height-m"),
    usage("range-study-lidar-height-10", RANGE + ["--lidar-height-m", "10"], "--lidar-height-m"),
    usage("range-study-slope-60", RANGE + ["--slope-deg", "60"], "--slope-deg"),
    usage("range-study-slope-nan", RANGE + ["--slope-deg", "nan"], "--slope-deg"),
    Case("range-study-missing-profile", RANGE + ["--sensor-profile", "nosuch.json"],
         "nosuch.json"),
    usage("verify-negative-seed", ["verify", "{inputs}/plan/plan.json", "--seed", "-1",
                                   "--out", "out"], "--seed"),
    usage("verify-without-out", ["verify", "{inputs}/plan/plan.json"], "--out"),
    usage("plan-negative-site-seed", ["plan", "--site-seed", "-1", "--out", "out"], "--site-seed"),
    usage("plan-budget-zero", ["plan", "--budget", "0", "--out", "out"], "--budget"),
    usage("plan-time-limit-zero", ["plan", "--time-limit-s", "0", "--out", "out"],
          "--time-limit-s"),
    usage("plan-time-limit-1e9", ["plan", "--time-limit-s", "1e9", "--out", "out"],
          "--time-limit-s"),
    usage("reduce-negative-seed", ["reduce", "as-built", "--verify", "--seed", "-1",
                                   "--out", "out"], "--seed"),
    usage("reduce-k-min-zero", ["reduce", "as-built", "--k-min", "0", "--out", "out"],
          "--k-min"),
    usage("fit-error-model-negative-seed", ["fit-error-model", "{inputs}/markers.csv", "--seed",
                                            "-1", "--out", "out"], "--seed"),
    usage("fit-error-model-bootstrap-1e6", ["fit-error-model", "{inputs}/markers.csv",
                                            "--bootstrap", "1000000", "--out", "out"],
          "--bootstrap"),
    usage("process-radius-zero", PROCESS + ["--marker-radius-m", "0"], "--marker-radius-m"),
    usage("process-radius-nan", PROCESS + ["--marker-radius-m", "nan"], "--marker-radius-m"),
    usage("process-min-points-zero", PROCESS + ["--min-points", "0"], "--min-points"),
    usage("process-max-rms-zero", PROCESS + ["--max-rms-m", "0"], "--max-rms-m"),
    usage("process-visible-fraction-2", PROCESS + ["--min-visible-fraction", "2"],
          "--min-visible-fraction"),
    Case("process-same-scan-twice", ["process", SCAN, SCAN, "--out", "out"], "given twice"),
    Case("process-same-scan-twice-other-path",
         ["process", SCAN, "{inputs}/scan/../scan/station_S1.scan.npz", "--out", "out"],
         "given twice"),
    usage("fit-sphere-radius-nan", ["fit-sphere", "p.xyz", "--marker-radius-m", "nan"],
          "--marker-radius-m"),
    usage("fit-sphere-sensor-two-numbers", ["fit-sphere", "p.xyz", "--marker-radius-m", "0.1",
                                            "--sensor", "1,2"], "--sensor"),
    Case("simulate-profile-missing-file", SIM + ["--sensor-profile", "nope.json"],
         "neither a shipped profile"),
    Case("simulate-profile-unknown-field", SIM + ["--sensor-profile", "p.json"],
         "has no field 'beam_width'", files={"p.json": PROFILE % '"sensor": {"beam_width": 2}'}),
    Case("simulate-profile-negative-sigma", SIM + ["--sensor-profile", "p.json"],
         "range_noise_m must be a number >= 0",
         files={"p.json": PROFILE % '"sensor": {"range_noise_m": -0.01}'}),
    Case("simulate-profile-negative-encoder", SIM + ["--sensor-profile", "p.json"],
         "encoder_noise_rad must be a number >= 0",
         files={"p.json": PROFILE % '"turntable": {"encoder_noise_rad": -1e-4}'}),
    Case("simulate-profile-not-a-profile", SIM + ["--sensor-profile", "p.json"],
         "not a sensor profile", files={"p.json": '{"format": "other"}'}),
    Case("verify-profile-missing-file", ["verify", "{inputs}/plan/plan.json", "--sensor-profile",
                                         "nope.json", "--out", "out"], "neither a shipped profile"),
    usage("simulate-axis-offset-one-number", SIM + ["--axis-offset-mm", "5"], "--axis-offset-mm"),
    usage("simulate-axis-offset-nan", SIM + ["--axis-offset-mm", "nan,0"], "--axis-offset-mm"),
    usage("reduce-axis-offset-one-number", ["reduce", "as-built", "--verify", "--axis-offset-mm",
                                            "15", "--out", "out"], "--axis-offset-mm"),
    usage("process-estimator-unknown", PROCESS + ["--estimator", "magic"], "--estimator"),
    # --reference-station: only in network mode, a station of the plan, the plan's own datum
    Case("plan-reference-station-without-network", ["plan", "--reference-station", "S2",
                                                    "--out", "out"], "add --network"),
    Case("reduce-reference-station-without-network", ["reduce", "as-built",
                                                      "--reference-station", "S2", "--out",
                                                      "out"], "add --network"),
    Case("verify-reference-station-without-network", ["verify", "{inputs}/plan/plan.json",
                                                      "--reference-station", "S2", "--out",
                                                      "out"], "add --network"),
    Case("reduce-reference-station-unknown", ["reduce", "as-built", "--network",
                                              "--station-ids", "S1,S2", "--reference-station",
                                              "S9", "--out", "out"],
         "--reference-station 'S9' is not a station of the network; valid ids are S1, S2"),
    Case("verify-network-reference-station-unknown", ["verify", "{inputs}/plan/plan.json",
                                                      "--network", "--reference-station", "S9",
                                                      "--out", "out"],
         "--reference-station 'S9' is not a station of the network"),
    # --body (adjust's option): network mode only, a known body, crs only with a CRS
    Case("verify-body-without-network", ["verify", "{inputs}/plan/plan.json", "--body", "moon",
                                         "--out", "out"],
         "--body moon levels the simulated stations of network mode"),
    usage("verify-body-unknown", ["verify", "{inputs}/plan/plan.json", "--network", "--body",
                                  "mars", "--out", "out"], "--body"),
    Case("verify-body-crs-without-a-crs", ["verify", "{inputs}/plan/plan.json", "--network",
                                           "--body", "crs", "--out", "out"],
         "--body crs takes the body from the ellipsoid of PLAN's CRS"),
    Case("reduce-network-verify", ["reduce", "as-built", "--network", "--verify", "--out",
                                   "out"], "markerplan verify PLAN --network"),
    # --scheduler/--workers place --verify's station tasks: refused without --verify
    Case("reduce-scheduler-without-verify", ["reduce", "as-built", "--scheduler", "none",
                                             "--out", "out"],
         "--scheduler set where --verify's station tasks run, and nothing else in reduce runs "
         "there; add --verify or drop it"),
    Case("reduce-scheduler-and-workers-without-verify", ["reduce", "as-built", "--scheduler",
                                                         "local", "--workers", "1", "--out",
                                                         "out"],
         "--scheduler and --workers set where --verify's station tasks run, and nothing else "
         "in reduce runs there; add --verify or drop them"),
    usage("fit-error-model-estimator-unknown", ["fit-error-model", "{inputs}/markers.csv",
                                                "--estimator", "magic", "--out", "out"],
          "--estimator"),
    # every float option is bounded and refuses NaN (FiniteRange); the bound keeps its use
    # from overflowing
    usage("plan-stand-map-cell-nan", PLAN + ["--stand-map-cell-m", "nan"], "--stand-map-cell-m"),
    usage("plan-stand-map-cell-old-spelling-nan", PLAN + ["--stand-map-cell", "nan"],
          "--stand-map-cell"),
    usage("plan-stand-map-cell-1e308", PLAN + ["--stand-map-cell-m", "1e308"],
          "--stand-map-cell-m"),
    usage("fit-sphere-sensor-1e300", ["fit-sphere", "p.xyz", "--marker-radius-m", "0.1",
                                      "--sensor-m", "1e300,0,0"], "--sensor-m",
          files={"p.xyz": SPHERE_POINTS}),
    # worker processes: at most one per core this process may use
    Case("range-study-workers-beyond-the-machine", RANGE + ["--workers", "100000"],
         "--workers 100000 is more worker processes than this machine runs"),
    # calibrate-sensor simulates full turns: too few frames is its own option's bound
    usage("calibrate-sensor-one-frame", ["calibrate-sensor", "--frames", "1", "--out", "out"],
          "--frames"),
    # three --fit parameters, one of them a field prior: too many, not "fixed and fitted"
    Case("calibrate-sensor-three-fits-one-a-prior",
         ["calibrate-sensor", "--frames", "100", "--fit", "sensor.range_noise_m=0:0.05",
          "--fit", "sensor.incidence_noise_m=0:0.01", "--fit",
          "turntable.periodic_error_rad=0:0.003", "--out", "out"],
         "give one or two free parameters (--fit), got 3"),
    # --reproject resamples a --dem; without one it was ignored
    Case("plan-reproject-without-dem", PLAN + ["--reproject"],
         "no --dem was given (a site preset's terrain is metric already); add --dem FILE or "
         "drop --reproject"),
    Case("simulate-reproject-without-dem", SIM + ["--reproject"], "no --dem was given"),
    Case("reduce-reproject-without-dem", ["reduce", "as-built", "--reproject", "--out", "out"],
         "no --dem was given"),
    # mounting offsets: a rig, not a LiDAR a million km off its turntable
    usage("simulate-axis-offset-1e9", SIM + ["--axis-offset-mm", "1e9,0"], "--axis-offset-mm"),
    usage("process-axis-offset-2000", PROCESS + ["--axis-offset-mm", "0,2000"],
          "between -1000 and 1000"),
    usage("verify-axis-offset-1e300", ["verify", "{inputs}/plan/plan.json", "--axis-offset-mm",
                                       "1e300,0", "--out", "out"], "--axis-offset-mm"),
]


@pytest.mark.parametrize("case", CASES, ids=str)
def test_refused(case, capsys, monkeypatch, tmp_path, valid_inputs):
    check_refused(case, capsys, monkeypatch, tmp_path, valid_inputs)


#: Numeric options bounded elsewhere than in their type, and where.
BOUNDED_ELSEWHERE = {"--workers": "by the machine: planner.distributed.check_local_workers"}


def test_every_numeric_option_is_bounded_and_refuses_nan():
    """Every float option of every command is a FiniteRange (both bounds, no NaN) and every
    integer option an IntRange with both bounds: a one-sided range lets 1e308 or 10**9
    through, and the work the value sizes overflows or runs away."""
    from planner.cli import COMMANDS
    from planner.cli._common import FiniteRange

    loose = []
    for name, module in COMMANDS.items():
        for param in importlib.import_module(f"planner.cli.{module}").command.params:
            kind = param.type
            if param.opts[0] in BOUNDED_ELSEWHERE:
                continue
            if isinstance(kind, click.types.FloatParamType):
                bounded = isinstance(kind, FiniteRange) and None not in (kind.min, kind.max)
            elif isinstance(kind, click.types.IntParamType):
                bounded = isinstance(kind, click.IntRange) and None not in (kind.min, kind.max)
            else:
                continue
            if not bounded:
                loose.append(f"{name} {param.opts[0]}")
    assert loose == []
    with pytest.raises(TypeError, match="both bounds"):
        FiniteRange(0.0, None)
