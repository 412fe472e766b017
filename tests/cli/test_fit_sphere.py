import json

import numpy as np
import pytest

from tests.cli.invoke import run_cli
from tests.pipeline.test_sphere_fit import _nist_reference, noisy_cap


@pytest.mark.parametrize("method", ["fixed-radius", "hemisphere-icp"])
def test_fit_sphere_json_on_synthetic_cap(tmp_path, capsys, method):
    pts = noisy_cap([1.0, 4.0, 0.5], 0.1, (1, 0, 0), 500, 0.002, np.random.default_rng(3))
    f = tmp_path / "cap.xyz"
    np.savetxt(f, pts, delimiter="\t")
    code, out, _ = run_cli(capsys, ["fit-sphere", str(f), "--marker-radius-m", "0.1", "--sensor",
                                    "1,0,0", "--estimator", method, "--json"])
    assert code == 0
    res = json.loads(out)
    assert np.linalg.norm(np.array(res["centre_m"]) - [1.0, 4.0, 0.5]) < 1.5e-3
    assert res["n_used"] > 100 and res["method"] == method


@pytest.mark.realdata
def test_fit_sphere_on_all_nist_scans(real_data, capsys):
    files = sorted((real_data / "nist_spheres").glob("SPH*.xyz"))
    assert len(files) == 11
    for f in files:
        code, out, _ = run_cli(capsys, ["fit-sphere", str(f), "--marker-radius-m", "0.05",
                                        "--json"])
        assert code == 0
        centre = np.array(json.loads(out)["centre_m"])
        ref = _nist_reference(np.loadtxt(f), 0.05)
        assert np.linalg.norm(centre - ref) < 1e-3, f.name


@pytest.mark.parametrize("args, content, needle", [
    (["--marker-radius-m", "0.1"], "", "no points"),
    (["--marker-radius-m", "0.1"], "1 2 x\n", "three numbers"),
])
def test_bad_input_one_line_error(tmp_path, capsys, args, content, needle):
    f = tmp_path / "p.xyz"
    f.write_text(content)
    code, out, err = run_cli(capsys, ["fit-sphere", str(f), *args])
    assert code == 1 and out == ""
    assert err.startswith("error:") and err.count("\n") == 1 and needle in err


def test_missing_file(tmp_path, capsys):
    code, _, err = run_cli(capsys, ["fit-sphere", str(tmp_path / "none.xyz"),
                                    "--marker-radius-m", "0.1"])
    assert code == 1 and "does not exist" in err
