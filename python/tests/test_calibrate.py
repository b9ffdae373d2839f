"""hapcal from Python gives the command line's report, whatever the input's form."""

from __future__ import annotations

import json
import subprocess

import numpy as np
import pytest

import hapcal
from conftest import (
    ROOT,
    POSITIONER,
    POSITIONER_YAML,
    UR10_CSV,
    UR10_TIP,
    UR10_URDF,
    _cli_command,
    assert_close,
    cli,
    cli_json,
    without_elapsed,
)


@pytest.fixture(scope="module")
def ur10() -> hapcal.Device:
    from conftest import ROOT

    return hapcal.Device.from_urdf(str(ROOT / UR10_URDF), tip=UR10_TIP)


def ur10_device() -> hapcal.Device:
    # Relative path, as the CLI is given it, so that the reports' `device` fields agree.
    return hapcal.Device.from_urdf(UR10_URDF, tip=UR10_TIP)


def test_device(ur10: hapcal.Device) -> None:
    assert ur10.joint_names == [
        "shoulder_pan_joint",
        "shoulder_lift_joint",
        "elbow_joint",
        "wrist_1_joint",
        "wrist_2_joint",
        "wrist_3_joint",
    ]
    assert ur10.n_joints == 6
    assert ur10.tips == [UR10_TIP]
    assert len(ur10.joint_limits) == 6
    assert issubclass(hapcal.HapcalError, ValueError)


@pytest.mark.parametrize("model", ["auto", "geometric"])
def test_ur10_report_equals_cli(model: str) -> None:
    cal = hapcal.calibrate(
        ur10_device(), hapcal.Measurements.from_csv(UR10_CSV), test_last=0.3, model=model
    )
    cli = cli_json(
        "--device", UR10_URDF, "--tip", UR10_TIP, "--data", UR10_CSV,
        "--test-last", "0.3", "--model", model,
    )
    assert_close(cal.report, json.loads(cli), ignore={"elapsed_s"})
    # The same bytes as the CLI prints, but for the wall time.
    assert without_elapsed(cal.to_json()) == without_elapsed(cli)
    assert json.loads(cal.to_json()) == cal.report
    assert cal.model == json.loads(cli)["model"]
    assert cal.figures == cal.report["placements"]
    assert cal.warnings == cal.report["warnings"]
    if model == "geometric":
        assert len(cal.report["parameters"]) > 0


def test_positioner_yaml_equals_cli() -> None:
    dev = hapcal.Device.from_toml(POSITIONER)
    assert dev.joint_names == ["q1", "q2"]
    cal = hapcal.calibrate(dev, hapcal.Measurements.from_csv(POSITIONER_YAML), test_last=0.3)
    cli = cli_json("--device", POSITIONER, "--data", POSITIONER_YAML, "--test-last", "0.3")
    assert_close(cal.report, json.loads(cli), ignore={"elapsed_s"})


def _arrays_from_csv(path: str):
    """The UR10 file's columns as arrays, read with the standard library's csv module."""
    import csv

    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    joints = ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint",
              "wrist_1_joint", "wrist_2_joint", "wrist_3_joint"]
    col = lambda c: np.array([float(r[c]) for r in rows])  # noqa: E731
    q = np.stack([col(j) for j in joints], axis=1)
    pos = np.stack([col(c) for c in ("x1", "y1", "z1")], axis=1)
    rpy = np.stack([col(c) for c in ("phix1", "phiy1", "phiz1")], axis=1)
    return q, pos, rpy, joints


def _rpy_to_quaternion(rpy: np.ndarray) -> np.ndarray:
    """figaroh's roll, pitch, yaw (R = Rz·Ry·Rx) as unit quaternions (w, x, y, z)."""
    r, p, y = (rpy[:, i] / 2 for i in range(3))
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.stack(
        [
            cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
        ],
        axis=1,
    )


@pytest.mark.parametrize("model", ["auto", "geometric"])
def test_arrays_equal_csv(ur10: hapcal.Device, model: str) -> None:
    from conftest import ROOT

    csv_cal = hapcal.calibrate(
        ur10, hapcal.Measurements.from_csv(ROOT / UR10_CSV), test_last=0.3, model=model
    )
    q, pos, rpy, joints = _arrays_from_csv(str(ROOT / UR10_CSV))
    ignore = {"elapsed_s", "name"}
    # Chain order, positions (n, 3), orientations as figaroh's roll, pitch, yaw.
    m = hapcal.Measurements.from_arrays(q, positions=pos, rpy=rpy, name="calibration")
    assert m.n_rows == 23
    cal = hapcal.calibrate(ur10, m, test_last=0.3, model=model)
    assert_close(cal.report, csv_cal.report, ignore={"elapsed_s"})
    # Named columns in another order, (n, k, 3) markers, quaternions (w, x, y, z).
    order = [5, 0, 3, 1, 4, 2]
    cal = hapcal.calibrate(
        ur10,
        hapcal.Measurements.from_arrays(
            q[:, order],
            positions=pos[:, None, :],
            quaternions=_rpy_to_quaternion(rpy)[:, None, :],
            joint_names=[joints[i] for i in order],
        ),
        test_last=0.3,
        model=model,
    )
    assert_close(cal.figures, csv_cal.figures, tol=1e-9, ignore=ignore)
    assert_close(cal.report["parameters"], csv_cal.report["parameters"], tol=1e-9)


@pytest.mark.parametrize("model", ["auto", "geometric"])
def test_dataframe_equals_csv(ur10: hapcal.Device, model: str) -> None:
    pd = pytest.importorskip("pandas")
    from conftest import ROOT

    csv_cal = hapcal.calibrate(
        ur10, hapcal.Measurements.from_csv(ROOT / UR10_CSV), test_last=0.3, model=model
    )
    df = pd.read_csv(ROOT / UR10_CSV)
    df["operator"] = "lab"  # a column hapcal ignores, as in a CSV file
    cal = hapcal.calibrate(
        ur10, hapcal.Measurements.from_dataframe(df, name="calibration"), test_last=0.3,
        model=model,
    )
    assert_close(cal.figures, csv_cal.figures)
    assert_close(cal.report["parameters"], csv_cal.report["parameters"])
    assert "columns ignored: operator" in cal.warnings
    assert_close(
        cal.report, csv_cal.report, ignore={"elapsed_s", "warnings"}
    )
    # q1..qn columns and an (n, k, 3)-style numbered marker work too.
    renamed = df.rename(columns={j: f"q{i + 1}" for i, j in enumerate(ur10.joint_names)})
    cal = hapcal.calibrate(ur10, hapcal.Measurements.from_dataframe(renamed), test_last=0.3,
                           model=model)
    assert_close(cal.figures, csv_cal.figures, ignore={"name"})
    params = cal.parameters
    assert list(params.columns) == ["name", "value", "std", "unit"]
    assert len(params) == len(csv_cal.report["parameters"])


def test_write_outputs(tmp_path, ur10: hapcal.Device) -> None:
    from conftest import ROOT

    cal = hapcal.calibrate(
        ur10, hapcal.Measurements.from_csv(ROOT / UR10_CSV), test_last=0.3, model="geometric"
    )
    written = cal.to_urdf(tmp_path / "ur10_calibrated.urdf")
    assert str(tmp_path / "ur10_calibrated.urdf") in written
    assert "<robot" in (tmp_path / "ur10_calibrated.urdf").read_text()
    written = cal.to_toml(tmp_path / "ur10_calibrated.toml")
    assert "[calibration" in (tmp_path / "ur10_calibrated.toml").read_text()
    # A calibrated URDF reads back as a device.
    again = hapcal.Device.from_urdf(tmp_path / "ur10_calibrated.urdf", tip=UR10_TIP)
    assert again.joint_names == ur10.joint_names


def test_unseen_marker_nan_equals_empty_cells(tmp_path, ur10: hapcal.Device) -> None:
    """Empty CSV cells (marker not seen) and NaN in arrays mean the same."""
    from conftest import ROOT

    lines = (ROOT / UR10_CSV).read_text().splitlines()
    cells = lines[5].split(",")
    lines[5] = ",".join([""] * 6 + cells[6:])  # x1..phiz1 of data row 5 empty
    path = tmp_path / "calibration.csv"
    path.write_text("\n".join(lines) + "\n")
    csv_cal = hapcal.calibrate(ur10, hapcal.Measurements.from_csv(path), test_last=0.3,
                               model="geometric")
    q, pos, rpy, _ = _arrays_from_csv(str(ROOT / UR10_CSV))
    pos[4] = np.nan
    rpy[4] = np.nan
    cal = hapcal.calibrate(
        ur10, hapcal.Measurements.from_arrays(q, positions=pos, rpy=rpy, name="calibration"),
        test_last=0.3, model="geometric",
    )
    assert_close(cal.report, csv_cal.report, ignore={"elapsed_s"})


def test_column_units_read_a_column_in_degrees(tmp_path, ur10: hapcal.Device) -> None:
    """``column_units={"q3": "deg"}`` on a copy with elbow_joint in degrees gives the
    calibration of the file in rad (the CLI's ``--column-unit q3=deg``)."""
    import math

    from conftest import ROOT

    lines = (ROOT / UR10_CSV).read_text().splitlines()
    column = lines[0].split(",").index("elbow_joint")
    for i in range(1, len(lines)):
        cells = lines[i].split(",")
        if len(cells) > column:
            cells[column] = repr(math.degrees(float(cells[column])))
            lines[i] = ",".join(cells)
    path = tmp_path / "calibration.csv"
    path.write_text("\n".join(lines) + "\n")
    si = hapcal.calibrate(ur10, hapcal.Measurements.from_csv(ROOT / UR10_CSV), model="geometric")
    deg = hapcal.calibrate(
        ur10, hapcal.Measurements.from_csv(path, column_units={"q3": "deg"}), model="geometric"
    )
    # The calibration (not the σ a pruned, unidentifiable parameter would have: rounding
    # decides that one).
    for key in ("model", "parameters", "frames", "sigma_m", "placements"):
        assert_close(deg.report[key], si.report[key], tol=1e-9, strings=False)
    with pytest.raises(hapcal.HapcalError, match='no column "q9"'):
        hapcal.calibrate(
            ur10, hapcal.Measurements.from_csv(path, column_units={"q9": "deg"}), model="geometric"
        )


def test_column_corrections_undo_what_the_setup_check_names(tmp_path, ur10: hapcal.Device) -> None:
    """A copy of the UR10 poses with elbow_joint read on the motor side of a 100:1 gear and
    wrist_1_joint counting the other way, read with ``column_scales={"q3": 0.01}`` and
    ``column_signs=["q4"]`` (the CLI's ``--column-scale q3=0.01 --column-sign q4``), gives
    the calibration of the file as it was."""
    from conftest import ROOT

    lines = (ROOT / UR10_CSV).read_text().splitlines()
    header = lines[0].split(",")
    elbow, wrist = header.index("elbow_joint"), header.index("wrist_1_joint")
    for i in range(1, len(lines)):
        cells = lines[i].split(",")
        if len(cells) > max(elbow, wrist):
            cells[elbow] = repr(100.0 * float(cells[elbow]))
            cells[wrist] = repr(-float(cells[wrist]))
            lines[i] = ",".join(cells)
    path = tmp_path / "calibration.csv"
    path.write_text("\n".join(lines) + "\n")
    as_was = hapcal.calibrate(
        ur10, hapcal.Measurements.from_csv(ROOT / UR10_CSV), model="geometric"
    )
    corrected = hapcal.calibrate(
        ur10,
        hapcal.Measurements.from_csv(path, column_scales={"q3": 0.01}, column_signs=["q4"]),
        model="geometric",
    )
    for key in ("model", "parameters", "frames", "sigma_m", "placements"):
        assert_close(corrected.report[key], as_was.report[key], tol=1e-9, strings=False)
    with pytest.raises(hapcal.HapcalError, match="column_scales"):
        hapcal.Measurements.from_csv(path, column_scales={"q3": 0.0})


def test_threads(ur10: hapcal.Device) -> None:
    """The solve releases the GIL: calibrations in threads agree with one another."""
    from concurrent.futures import ThreadPoolExecutor

    from conftest import ROOT

    m = hapcal.Measurements.from_csv(ROOT / UR10_CSV)
    with ThreadPoolExecutor(max_workers=2) as pool:
        reports = list(
            pool.map(lambda _: hapcal.calibrate(ur10, m, test_last=0.3).report, range(4))
        )
    for r in reports[1:]:
        assert_close(r, reports[0], tol=0.0, ignore={"elapsed_s"})


def test_mukca_folders_equal_cli() -> None:
    """Socket recordings (MUKCa placement folders): the CLI's workflow, cross-validated."""
    dev = hapcal.Device.from_urdf("fixtures/mukca/urdf/iiwa14.urdf", tip="ball_link")
    front, left_back = ("fixtures/mukca/data/kuka_14/" + p for p in ("front", "left_back"))
    cal = hapcal.calibrate(dev, hapcal.Measurements.from_csv(front), test=[left_back])
    cli = cli_json(
        "--device", "fixtures/mukca/urdf/iiwa14.urdf", "--tip", "ball_link",
        "--data", front, "--test", left_back,
    )
    assert without_elapsed(cal.to_json()) == without_elapsed(cli)
    assert cal.report["cross_validation"], "model auto cross-validates"


def test_haptic_log_equals_cli(tmp_path) -> None:
    """A haptic device's own log (transmissions, then kinematics): the CLI's workflow."""
    from conftest import cli

    log = tmp_path / "log.csv"
    cli("simulate", "--truth", "fixtures/reference-device/truth.toml", "--seed", "1",
        "--poses", "200", "--out", str(log))
    dev = hapcal.Device.from_toml("fixtures/reference-device/device.toml")
    cal = hapcal.calibrate(dev, hapcal.Measurements.from_csv(log))
    cli_out = cli_json("--device", "fixtures/reference-device/device.toml", "--data", str(log))
    assert_close(cal.report, json.loads(cli_out), ignore={"elapsed_s"})
    assert cal.model == "transmissions"
    out = tmp_path / "calibrated.toml"
    assert cal.to_toml(out) == [str(out)]
    assert hapcal.Device.from_toml(out).joint_names == dev.joint_names
    # Arrays carry an external instrument's measurements, not a haptic device's log.
    with pytest.raises(hapcal.HapcalError, match="haptic device"):
        hapcal.calibrate(
            dev, hapcal.Measurements.from_arrays(np.zeros((3, dev.n_joints)),
                                                 distances=np.ones(3)),
        )


def test_models_are_the_command_lines() -> None:
    """`hapcal.MODELS` is the command line's list of `--model` values, in its order."""
    help_text = cli("calibrate", "--help")
    listed = [
        line.strip()[2:].split(":")[0]
        for line in help_text.splitlines()
        if line.strip().startswith("- ") and ":" in line
    ]
    assert list(hapcal.MODELS) == listed[: len(hapcal.MODELS)]
    assert "transversal-compliance" in hapcal.MODELS
    assert "transversal-axes" in hapcal.MODELS


def test_the_setup_check_stops_a_mistake_as_the_command_line_does(tmp_path) -> None:
    """Centimetres read as metres: `hapcal calibrate` exits 2 naming the mistake; Python raises
    with the same words, and goes on (with the finding as a warning) when told to."""
    src = ROOT / UR10_CSV
    lines = src.read_text().splitlines()
    header = lines[0].split(",")
    xyz = [header.index(c) for c in ("x1", "y1", "z1")]
    out = [lines[0]]
    for line in lines[1:]:
        cells = line.split(",")
        for i in xyz:
            cells[i] = repr(float(cells[i]) * 1e2)
        out.append(",".join(cells))
    mm = tmp_path / "calibration_cm.csv"
    mm.write_text("\n".join(out) + "\n")
    run = subprocess.run(
        _cli_command() + ["calibrate", "--device", UR10_URDF, "--tip", UR10_TIP,
                          "--data", str(mm)],
        cwd=ROOT, capture_output=True, text=True)
    assert run.returncode == 2, run
    with pytest.raises(hapcal.HapcalError) as e:
        hapcal.calibrate(ur10_device(), hapcal.Measurements.from_csv(mm))
    last = run.stderr.strip().splitlines()[-1]
    assert last.startswith("hapcal: error: ")
    # The same words, with the option as Python spells it.
    expected = last[len("hapcal: error: "):].replace("--accept-setup", "accept_setup=True")
    assert expected in str(e.value)
    with pytest.warns(UserWarning):
        cal = hapcal.calibrate(ur10_device(), hapcal.Measurements.from_csv(mm), accept_setup=True)
    assert cal.model
