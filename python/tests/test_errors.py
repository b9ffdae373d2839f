"""Every failure is a HapcalError (a ValueError) whose message says what and where."""

from __future__ import annotations

import numpy as np
import pytest

import hapcal
from conftest import UR10_CSV, UR10_TIP, UR10_URDF


@pytest.fixture(scope="module")
def ur10() -> hapcal.Device:
    from conftest import ROOT

    return hapcal.Device.from_urdf(str(ROOT / UR10_URDF), tip=UR10_TIP)


def test_error_class() -> None:
    assert issubclass(hapcal.HapcalError, ValueError)
    assert hapcal.HapcalError.__module__ == "hapcal"


def test_missing_files(tmp_path) -> None:
    missing = tmp_path / "nope.csv"
    with pytest.raises(hapcal.HapcalError, match=r"nope\.csv.*No such file"):
        hapcal.Measurements.from_csv(missing)
    with pytest.raises(hapcal.HapcalError, match=r"importing .*nope\.urdf"):
        hapcal.Device.from_urdf(tmp_path / "nope.urdf", tip="tool0")
    with pytest.raises(hapcal.HapcalError, match=r"nope\.toml"):
        hapcal.Device.from_toml(tmp_path / "nope.toml")
    # Also a ValueError, for code that does not know hapcal.
    with pytest.raises(ValueError):
        hapcal.Measurements.from_csv(missing)


def test_unknown_tip() -> None:
    with pytest.raises(hapcal.HapcalError, match="no_such_link"):
        hapcal.Device.from_urdf(UR10_URDF, tip="no_such_link")


def test_bad_columns(tmp_path, ur10: hapcal.Device) -> None:
    bad = tmp_path / "bad.csv"
    bad.write_text("a,b,c,x,y,z\n1,2,3,0.1,0.2,0.3\n1,2,3,0.1,0.2,0.3\n")
    with pytest.raises(hapcal.HapcalError) as e:
        hapcal.calibrate(ur10, hapcal.Measurements.from_csv(bad))
    msg = str(e.value)
    assert "bad.csv" in msg
    # Names the joints expected and the columns found.
    assert "shoulder_pan_joint" in msg and "wrist_3_joint" in msg, msg
    assert "a, b, c, x, y, z" in msg, msg


def test_bad_cell_has_file_line_column(tmp_path, ur10: hapcal.Device) -> None:
    from conftest import ROOT

    lines = (ROOT / UR10_CSV).read_text().splitlines()
    cells = lines[3].split(",")
    cells[2] = "abc"
    lines[3] = ",".join(cells)
    bad = tmp_path / "cell.csv"
    bad.write_text("\n".join(lines) + "\n")
    with pytest.raises(hapcal.HapcalError, match=r"cell\.csv:4:3") as e:
        hapcal.calibrate(ur10, hapcal.Measurements.from_csv(bad))
    # The whole chain: the context and the cause.
    assert "reading measurements" in str(e.value)
    assert "abc" in str(e.value)


def test_bad_units_and_model(ur10: hapcal.Device) -> None:
    with pytest.raises(hapcal.HapcalError, match=r'length_unit: .*m, mm, cm.*"km"'):
        hapcal.Measurements.from_csv(UR10_CSV, length_unit="km")
    with pytest.raises(hapcal.HapcalError, match=r'angle_unit: .*rad, deg, grad.*"gon"'):
        hapcal.Measurements.from_csv(UR10_CSV, angle_unit="gon")
    with pytest.raises(hapcal.HapcalError, match="length_unit"):
        hapcal.Measurements.from_arrays(np.zeros((3, 6)), positions=np.zeros((3, 3)),
                                        length_unit="inch")
    with pytest.raises(hapcal.HapcalError, match=r"model: expected one of .*geometric"):
        hapcal.calibrate(ur10, hapcal.Measurements.from_csv(UR10_CSV), model="best")
    with pytest.raises(hapcal.HapcalError, match="--test-last must lie strictly between 0 and 1"):
        hapcal.calibrate(ur10, hapcal.Measurements.from_csv(UR10_CSV), test_last=1.5)
    with pytest.raises(hapcal.HapcalError, match="folds"):
        hapcal.calibrate(ur10, hapcal.Measurements.from_csv(UR10_CSV), folds=1)


def test_wrong_shapes(ur10: hapcal.Device) -> None:
    n = 10
    q = np.zeros((n, 6))
    pos = np.zeros((n, 3))
    with pytest.raises(hapcal.HapcalError, match=r"q: expected shape \(n, n_joints\)"):
        hapcal.Measurements.from_arrays(np.zeros(6), positions=pos)
    with pytest.raises(hapcal.HapcalError, match=r"positions: expected shape \(10, 3\)"):
        hapcal.Measurements.from_arrays(q, positions=np.zeros((n, 2)))
    with pytest.raises(hapcal.HapcalError, match=r"positions: expected shape"):
        hapcal.Measurements.from_arrays(q, positions=np.zeros((n + 1, 3)))
    with pytest.raises(hapcal.HapcalError, match=r"quaternions: expected shape"):
        hapcal.Measurements.from_arrays(q, positions=pos, quaternions=np.zeros((n, 3)))
    with pytest.raises(hapcal.HapcalError, match="one orientation per marker"):
        hapcal.Measurements.from_arrays(q, positions=pos, quaternions=np.zeros((n, 2, 4)))
    with pytest.raises(hapcal.HapcalError, match=r"distances: expected shape \(10,\)"):
        hapcal.Measurements.from_arrays(q, distances=np.zeros(n - 1))
    with pytest.raises(hapcal.HapcalError, match="no measurements"):
        hapcal.Measurements.from_arrays(q)
    with pytest.raises(hapcal.HapcalError, match="joint_names: 5 names"):
        hapcal.Measurements.from_arrays(q, positions=pos, joint_names=["a"] * 5)
    with pytest.raises(hapcal.HapcalError, match="unit quaternion"):
        quat = np.zeros((n, 4))
        quat[:, 0] = 2.0
        hapcal.Measurements.from_arrays(q, positions=pos, quaternions=quat)
    with pytest.raises(hapcal.HapcalError, match="NaN beside values"):
        p = pos.copy()
        p[3, 1] = np.nan
        hapcal.Measurements.from_arrays(q, positions=p)
    # The joint count is checked against the device when calibrating.
    m = hapcal.Measurements.from_arrays(np.zeros((n, 5)), positions=pos)
    with pytest.raises(hapcal.HapcalError, match=r"q has 5 columns, the device has 6 joints"):
        hapcal.calibrate(ur10, m)
    m = hapcal.Measurements.from_arrays(
        q, positions=pos, joint_names=["q1", "q2", "q3", "q4", "q5", "gripper"]
    )
    with pytest.raises(hapcal.HapcalError, match=r"missing wrist_3_joint.*gripper"):
        hapcal.calibrate(ur10, m)


def test_joint_out_of_range(ur10: hapcal.Device) -> None:
    q = np.zeros((10, 6))
    q[4, 1] = 100.0  # degrees given as radians
    m = hapcal.Measurements.from_arrays(q, positions=np.zeros((10, 3)))
    with pytest.raises(hapcal.HapcalError, match=r"row 5.*shoulder_lift_joint.*outside its range"):
        hapcal.calibrate(ur10, m)


def test_dataframe_errors(ur10: hapcal.Device) -> None:
    pd = pytest.importorskip("pandas")
    df = pd.DataFrame({"x": [0.1], "y": [0.2], "z": [0.3], "label": ["a"]})
    with pytest.raises(hapcal.HapcalError, match="no joint columns; the columns are x, y, z, label"):
        hapcal.Measurements.from_dataframe(df)
    df = pd.DataFrame({"q1": [0.0], "x": [0.1], "y": [0.2]})
    with pytest.raises(hapcal.HapcalError, match="column 'z' missing"):
        hapcal.Measurements.from_dataframe(df)
    df = pd.DataFrame({"q1": [0.0], "x": [0.1], "y": [0.2], "z": [0.3]})
    with pytest.raises(hapcal.HapcalError, match="joint columns missing: elbow"):
        hapcal.Measurements.from_dataframe(df, joint_names=["q1", "elbow"])
