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
    lines = ["[values]"]
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
