"""The runtime from Python: a calibrated iiwa 14 (the bundled URDF with a sidecar of
compliances), its tip poses rigid and deflected, and a compensated command."""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import pytest

import hapcal

from conftest import ROOT

IIWA = ROOT / "fixtures/mukca/urdf/iiwa14.urdf"
Q = [0.3, 0.7, -0.2, -1.2, 0.4, 0.9, 0.1]


def _calibrated(tmp_path: Path) -> Path:
    urdf = tmp_path / "robot.urdf"
    shutil.copy(IIWA, urdf)
    # A calibration record (schema 1) of joint compliances under the lumped unit weights (the
    # URDF has no masses), gravity along -z at the torque equilibrium.
    lines = [
        "schema_version = 1",
        'model = "compliance"',
        "",
        "[torque]",
        'source = "lumped-unit-weights"',
        "gravity_direction = [0.0, 0.0, -1.0]",
        "gravity_m_s2 = 9.80665",
        "equilibrium = true",
        "",
        "[region]",
        "rows = 100",
        "",
        "[values]",
    ]
    for j in range(1, 8):
        lines.append(
            f'"compliance.joint_a{j}" = {{ value = {2e-4 + 1e-4 * j!r}, std = 1e-5, unit = "rad/m" }}'
        )
    (tmp_path / "robot.calibration.toml").write_text("\n".join(lines) + "\n")
    return urdf


def _distance(a, b) -> float:
    return math.sqrt(sum((a[i][3] - b[i][3]) ** 2 for i in range(3)))


def test_deflection_and_compensation(tmp_path: Path) -> None:
    robot = hapcal.RuntimeRobot(str(_calibrated(tmp_path)), ["ball_link"])
    assert robot.joint_names == [f"joint_a{j}" for j in range(1, 8)]
    assert robot.tip_names == ["ball_link"]
    (rigid,) = robot.tip_poses(Q, deflected=False)
    (sagging,) = robot.tip_poses(Q)
    assert rigid[3] == [0.0, 0.0, 0.0, 1.0]
    # Compliances of 3e-4 to 9e-4 rad per metre of lumped lever arm sag the tip by
    # a fraction of a millimetre or more.
    assert _distance(rigid, sagging) > 1e-4
    # The command that puts the sagging tip where the rigid one was.
    c = robot.compensate([rigid[0][3], rigid[1][3], rigid[2][3]], Q)
    assert c["reached"] and c["position_error_m"] <= 1e-6
    (after,) = robot.tip_poses(c["q"])
    assert _distance(after, rigid) <= 1e-6
    far = robot.compensate([3.0, 0.0, 0.5], Q)
    assert not far["reached"] and far["position_error_m"] > 2.0


def test_errors_name_what_is_wrong(tmp_path: Path) -> None:
    with pytest.raises(hapcal.HapcalError, match="no_such_link"):
        hapcal.RuntimeRobot(str(_calibrated(tmp_path)), ["no_such_link"])
    robot = hapcal.RuntimeRobot(str(_calibrated(tmp_path)), ["ball_link"])
    with pytest.raises(hapcal.HapcalError, match="expected 7 values, found 6"):
        robot.tip_poses(Q[:6])
    with pytest.raises(hapcal.HapcalError, match="expected 3 values"):
        robot.compensate([0.1, 0.2], Q)


CALIBRATED_DEVICE = ROOT / "fixtures/reference-device/calibrated.toml"
THETA = [0.1, 0.5, -0.2, 1.0, 0.3, 0.6, -0.4]


def test_the_device_model_of_the_c_abi() -> None:
    """RuntimeModel is the object the C ABI's handle holds: its body Jacobian agrees with
    central differences of its own pose in the readings, and its motor torques are linear in
    the wrench."""
    model = hapcal.RuntimeModel(str(CALIBRATED_DEVICE))
    assert model.n_joints == 7
    e = model.evaluate(THETA, [0.0] * 6)
    assert e["motor_torques_nm"] == [0.0] * 7
    pose = e["pose"]
    rot = [row[:3] for row in pose[:3]]
    h = 1e-6
    for j in range(7):
        plus, minus = list(THETA), list(THETA)
        plus[j] += h
        minus[j] -= h
        pp = model.evaluate(plus, [0.0] * 6)["pose"]
        pm = model.evaluate(minus, [0.0] * 6)["pose"]
        # End-point velocity in the tip frame: Rᵀ·dp/dθ.
        dp = [(pp[i][3] - pm[i][3]) / (2 * h) for i in range(3)]
        v = [sum(rot[i][a] * dp[i] for i in range(3)) for a in range(3)]
        # Angular velocity in the tip frame: the skew part of Rᵀ·dR/dθ.
        d_rot = [[(pp[i][k] - pm[i][k]) / (2 * h) for k in range(3)] for i in range(3)]
        w_hat = [[sum(rot[i][a] * d_rot[i][b] for i in range(3)) for b in range(3)] for a in range(3)]
        w = [w_hat[2][1], w_hat[0][2], w_hat[1][0]]
        column = [e["body_jacobian"][r][j] * e["dq_dtheta"][j] for r in range(6)]
        # Central differences at h = 1e-6 on poses of order 0.1 m: truncation ~h², rounding
        # ~1e-16/h = 1e-10.
        for got, want in zip(column, v + w):
            assert abs(got - want) <= 1e-7 + 1e-6 * abs(want), (j, column, v + w)
    w1 = [1.5, -2.0, 0.5, 0.05, -0.02, 0.1]
    w2 = [0.0, 1.0, -3.0, 0.0, 0.2, 0.0]
    t1 = model.evaluate(THETA, w1)["motor_torques_nm"]
    t2 = model.evaluate(THETA, w2)["motor_torques_nm"]
    t12 = model.evaluate(THETA, [a + b for a, b in zip(w1, w2)])["motor_torques_nm"]
    for a, b, c in zip(t1, t2, t12):
        assert abs(a + b - c) <= 1e-12 * (1.0 + abs(c))
    assert any(abs(t) > 1e-6 for t in t1)
    with pytest.raises(hapcal.HapcalError, match="wrench: expected 6 values"):
        model.evaluate(THETA, [0.0] * 5)
    with pytest.raises(hapcal.HapcalError):
        model.evaluate(THETA[:6], [0.0] * 6)
