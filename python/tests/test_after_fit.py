"""The setup check after the fit: Python's `calibrate` stops where `hapcal calibrate` does."""

from __future__ import annotations

import subprocess

import pytest

import hapcal
from conftest import ROOT, UR10_CSV, UR10_TIP, UR10_URDF, _cli_command

# The UR10's upper arm (shoulder to elbow) in its URDF, m, and the error put into it: 60 mm,
# over twice the 25 mm a real robot's manufacturing leaves, which the recording (23 poses,
# about 1 mm of noise) determines to far better than the check's 10 standard deviations.
UPPER_ARM = 'xyz="-0.6127 0 0"'
LONGER = 'xyz="-0.6727 0 0"'


def _longer_arm(tmp_path) -> str:
    text = (ROOT / UR10_URDF).read_text()
    assert text.count(UPPER_ARM) == 1, "the UR10 description changed: pick another link"
    urdf = tmp_path / "ur10_longer_arm.urdf"
    urdf.write_text(text.replace(UPPER_ARM, LONGER))
    return str(urdf)


def test_a_link_60_mm_off_stops_python_as_the_command_line(tmp_path) -> None:
    urdf = _longer_arm(tmp_path)
    run = subprocess.run(
        _cli_command() + ["calibrate", "--device", urdf, "--tip", UR10_TIP,
                          "--data", UR10_CSV, "--model", "geometric"],
        cwd=ROOT, capture_output=True, text=True)
    assert run.returncode != 0, run
    last = run.stderr.strip().splitlines()[-1]
    assert last.startswith("hapcal: error: setup check [another-device]: "), last
    device = hapcal.Device.from_urdf(urdf, tip=UR10_TIP)
    data = hapcal.Measurements.from_csv(UR10_CSV)
    with pytest.raises(hapcal.HapcalError) as e:
        hapcal.calibrate(device, data, model="geometric")
    # The command line's words, with the option as Python spells it.
    expected = last[len("hapcal: error: "):].replace("--accept-setup", "accept_setup=True")
    assert str(e.value) == expected
    # Accepted: the calibration goes on, the finding a warning, the arm's error in the result.
    with pytest.warns(UserWarning, match=r"setup check \(accepted with accept_setup=True\) "
                                         r"\[another-device\]"):
        cal = hapcal.calibrate(device, data, model="geometric", accept_setup=True)
    assert cal.model == "geometric"
