import numpy as np
import pytest

from markerplan.errors import DataError, InputFileError
from pipeline.scans.pointsets import read_points


def test_reads_tab_xyz_and_csv_header(tmp_path):
    f = tmp_path / "a.xyz"
    f.write_text("1\t2\t3\n4 5 6 99\n")
    np.testing.assert_allclose(read_points(f), [[1, 2, 3], [4, 5, 6]])
    g = tmp_path / "b.csv"
    g.write_text("id,z_m,y_m,x_m\n7,3,2,1\n")
    np.testing.assert_allclose(read_points(g), [[1, 2, 3]])


@pytest.mark.parametrize("text, err", [("", DataError), ("# only a comment\n", DataError),
                                       ("1 2\n", InputFileError), ("1 2 a\n", InputFileError)])
def test_bad_files_raise_one_line(tmp_path, text, err):
    f = tmp_path / "bad.xyz"
    f.write_text(text)
    with pytest.raises(err) as exc:
        read_points(f)
    assert "\n" not in str(exc.value)


def test_missing_and_binary_file(tmp_path):
    with pytest.raises(InputFileError, match="does not exist"):
        read_points(tmp_path / "nope.xyz")
    f = tmp_path / "bin.xyz"
    f.write_bytes(b"\xff\xfe\x00\x81" * 10)
    with pytest.raises(InputFileError):
        read_points(f)
