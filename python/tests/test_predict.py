"""`hapcal.predict`: the UR10 calibrated on the bundled poses, predicted at its own rows
(against the runtime robot and an error computed here), and a reading outside the region of
a hand-written record."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import hapcal

from conftest import UR10_CSV, UR10_TIP, UR10_URDF

ARM = """<?xml version="1.0"?>
<robot name="arm">
  <link name="base"/><link name="upper"/><link name="fore"/><link name="tip"/>
  <joint name="joint1" type="revolute"><parent link="base"/><child link="upper"/>
    <origin xyz="0 0 0.1" rpy="0 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="joint2" type="revolute"><parent link="upper"/><child link="fore"/>
    <origin xyz="0.5 0 0" rpy="0 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="tip_joint" type="fixed"><parent link="fore"/><child link="tip"/>
    <origin xyz="0.4 0 0" rpy="0 0 0"/></joint>
</robot>
"""

RECORD = """schema_version = 1
model = "compliance"
tips = ["tip"]

[torque]
source = "lumped-unit-weights"
gravity_direction = [0.0, 0.0, -1.0]
gravity_m_s2 = 9.80665
tips = ["tip"]

[region]
rows = 40
joint = [
  { name = "joint1", min = -0.5, max = 0.5, unit = "rad" },
  { name = "joint2", min = 0.2, max = 1.2, unit = "rad" },
]

[values]
"compliance.joint2" = { value = 2e-3, std = 4e-4, unit = "rad/m" }

[covariance]
names = ["compliance.joint2"]
lower = [1.6e-7]
"""


def test_predictions_at_the_training_rows(tmp_path: Path) -> None:
    out = tmp_path / "ur10.urdf"
    cal = hapcal.calibrate(
        hapcal.Device.from_urdf(UR10_URDF, tip=UR10_TIP),
        hapcal.Measurements.from_csv(UR10_CSV),
        model="geometric",
    )
    cal.to_urdf(out)
    p = hapcal.predict(out, UR10_TIP, UR10_CSV)
    assert p.positions.shape == (23, 1, 3)
    robot = hapcal.RuntimeRobot(str(out), [UR10_TIP])
    data = np.genfromtxt(UR10_CSV, delimiter=",", names=True)
    q = np.column_stack([data[j] for j in robot.joint_names])
    for row, position in zip(q, p.positions[:, 0]):
        (pose,) = robot.tip_poses(list(row))
        assert np.allclose(position, np.asarray(pose)[:3, 3], rtol=0, atol=1e-12)
    # In the instrument frame, the position error against x1, y1, z1 computed here.
    m = hapcal.predict(out, UR10_TIP, UR10_CSV, instrument_frame=True)
    measured = np.column_stack([data["x1"], data["y1"], data["z1"]])
    rms = np.sqrt(np.mean(np.sum((m.positions[:, 0] - measured) ** 2, axis=1)))
    assert m.errors is not None
    assert m.errors["position_m"]["rms"] == pytest.approx(rms, rel=1e-9)
    assert m.errors["position_m"]["count"] == 23


def test_a_reading_outside_the_region_is_flagged(tmp_path: Path) -> None:
    urdf = tmp_path / "arm.urdf"
    urdf.write_text(ARM)
    (tmp_path / "arm.calibration.toml").write_text(RECORD)
    readings = tmp_path / "readings.csv"
    readings.write_text("joint1,joint2\n0.1,0.7\n0.2,1.5\n")
    p = hapcal.predict(urdf, "tip", readings)
    assert list(p.outside_region) == [False, True]
    assert p.region_joint == [None, "joint2"]
    assert p.region_past[1] == pytest.approx(0.3, abs=1e-12)
    assert p.uncertainty == "covariance"
    assert np.all(p.sigma_m > 0)


def test_bad_readings_name_file_line_and_column(tmp_path: Path) -> None:
    urdf = tmp_path / "arm.urdf"
    urdf.write_text(ARM)
    readings = tmp_path / "readings.csv"
    readings.write_text("joint1,joint2\n0.1,abc\n")
    with pytest.raises(hapcal.HapcalError, match=r"readings\.csv:2:2"):
        hapcal.predict(urdf, "tip", readings)


# The rungs the ladder can choose on the UR10 data (no published link masses, URDF placements
# with rotation deviations), and two models asked for by name.
LADDER = ["frames-only", "joint-offsets", "geometric", "compliance", "transversal-compliance"]


@pytest.mark.parametrize("model", LADDER + ["harmonic", "compliance-harmonic"])
def test_the_runtime_robot_reproduces_the_library_positions(tmp_path: Path, model: str) -> None:
    """Every row's marker position from the written files (`RuntimeRobot`: the instrument
    frame · the deflected tip · marker1) equals the calibration library's (the model the
    report's errors come from) to 1e-9 m; and the calibration's own training error equals the
    error of `hapcal.predict`'s predictions from the files."""
    out = tmp_path / "ur10.urdf"
    device = hapcal.Device.from_urdf(UR10_URDF, tip=UR10_TIP)
    cal = hapcal.calibrate(device, hapcal.Measurements.from_csv(UR10_CSV), model=model)
    cal.to_urdf(out)
    data = np.genfromtxt(UR10_CSV, delimiter=",", names=True)
    q = np.column_stack([data[j] for j in device.joint_names])
    library = cal.predicted_positions(q)
    assert library.shape == (23, 1, 3)
    robot = hapcal.RuntimeRobot(str(out), [UR10_TIP])
    assert robot.joint_names == device.joint_names
    instrument = np.asarray(robot.frame("instrument"))
    marker = robot.frame("marker1")
    marker = np.eye(4) if marker is None else np.asarray(marker)
    assert robot.frame("marker9") is None
    gap, moved = 0.0, 0.0
    for row, position in zip(q, library[:, 0]):
        (tip,) = robot.tip_poses(list(row))
        (rigid,) = robot.tip_poses(list(row), deflected=False)
        runtime = (instrument @ np.asarray(tip) @ marker)[:3, 3]
        gap = max(gap, float(np.max(np.abs(runtime - position))))
        moved = max(moved, float(np.max(np.abs((instrument @ np.asarray(rigid) @ marker)[:3, 3]
                                                 - position))))
    assert gap <= 1e-9, f"{model}: runtime and library differ by {gap:.3e} m"
    if "compliance" in model:
        # The deflection matters: the rigid robot misses the library's positions.
        assert moved > 1e-7, f"{model}: {moved:.3e} m"
    # The library's positions are those the report's errors come from: their RMS against
    # x1, y1, z1 is the report's, and so is that of the runtime's predictions.
    measured = np.column_stack([data["x1"], data["y1"], data["z1"]])
    rms = float(np.sqrt(np.mean(np.sum((library[:, 0] - measured) ** 2, axis=1))))
    train = cal.figures[0]["after"]["pose"]
    assert rms == pytest.approx(train["position_rms_m"], abs=1e-12)
    p = hapcal.predict(out, UR10_TIP, UR10_CSV, instrument_frame=True)
    assert p.errors is not None
    # Mean and RMS over 23 positions of millimetres: a gap of 1e-9 m in every prediction
    # would move them by about 1e-9 m; rounding leaves them equal to 1e-12 m.
    assert p.errors["position_m"]["rms"] == pytest.approx(train["position_rms_m"], abs=1e-12)
    assert p.errors["position_m"]["mean"] == pytest.approx(train["position_mean_m"], abs=1e-12)


def test_the_runtime_model_reproduces_the_library_positions(tmp_path: Path) -> None:
    """The reference device calibrated with its handle's gravity compliance: every row's end
    point from the written device file (`RuntimeModel`) equals the calibration library's to
    1e-9 m, and the library's distances give the report's distance RMS."""
    device = hapcal.Device.from_toml("fixtures/reference-device/device.toml")
    log = "fixtures/reference-device/log.csv"
    cal = hapcal.calibrate(device, hapcal.Measurements.from_csv(log), model="compliance")
    assert cal.model == "compliance"
    out = tmp_path / "calibrated.toml"
    cal.to_toml(out)
    data = np.genfromtxt(log, delimiter=",", names=True)
    theta = np.column_stack([data[f"q{j}"] for j in range(1, device.n_joints + 1)])
    library = cal.predicted_positions(theta)
    assert library.shape == (len(theta), 1, 3)
    model = hapcal.RuntimeModel(out)
    gap = 0.0
    for row, position in zip(theta, library[:, 0]):
        pose = np.asarray(model.evaluate(list(row), [0.0] * 6)["pose"])
        gap = max(gap, float(np.max(np.abs(pose[:3, 3] - position))))
    assert gap <= 1e-9, f"runtime and library differ by {gap:.3e} m"
    residual = np.linalg.norm(library[:, 0], axis=1) - data["distance_m"]
    rms = float(np.sqrt(np.mean(residual**2)))
    assert rms == pytest.approx(cal.figures[0]["after"]["distance_rms_m"], abs=1e-12)
