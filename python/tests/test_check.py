"""`hapcal.check` and `hapcal.import_urdf` give what `hapcal check --json` and `hapcal
import-urdf` print; a failing check is a result with the command line's exit code, not an
exception."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

import hapcal
from conftest import ROOT, UR10_CSV, UR10_TIP, UR10_URDF, _cli_command, cli


def ur10() -> hapcal.Device:
    return hapcal.Device.from_urdf(UR10_URDF, tip=UR10_TIP)


TIAGO_URDF = "fixtures/figaroh/tiago/tiago.urdf"
TIAGO_TIP = "arm_7_link"
TIAGO_CSV = "fixtures/figaroh/tiago/qualysis_base_hand_calibration.csv"


def tiago() -> hapcal.Device:
    return hapcal.Device.from_urdf(TIAGO_URDF, tip=TIAGO_TIP)


def in_millimetres(tmp_path: Path) -> Path:
    """The TIAGo motion-capture recording with its marker positions in mm (joints as they
    are): every position lies within a metre of the instrument, so within the ±1000 m a
    length read in m may take."""
    lines = (ROOT / TIAGO_CSV).read_text().splitlines()
    header = lines[0].split(",")
    xyz = [i for i, c in enumerate(header) if c[:1] in ("x", "y", "z")]
    assert len(xyz) == 12
    out = [lines[0]]
    for line in lines[1:]:
        cells = line.split(",")
        for i in xyz:
            cells[i] = repr(float(cells[i]) * 1e3)
        out.append(",".join(cells))
    path = tmp_path / "tiago_mm.csv"
    path.write_text("\n".join(out) + "\n")
    return path


def cli_check(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(_cli_command() + ["check", *args, "--json"], cwd=ROOT,
                          capture_output=True, text=True)


def test_check_passes_on_right_data_as_the_command_line() -> None:
    c = hapcal.check(ur10(), UR10_CSV)
    assert c.exit_code == 0 and c.error is None
    assert [f for f in c.findings if f["severity"] == "error"] == []
    # 23 rows in the file; a UR10's manufacturing deviations leave millimetres, not more.
    assert c.report["n_rows"] == 23
    assert 0.0 < c.report["as_given"]["length_rms_m"] < 0.01
    run = cli_check("--device", UR10_URDF, "--tip", UR10_TIP, "--data", UR10_CSV)
    assert run.returncode == 0, run.stderr
    assert c.to_json() == run.stdout.rstrip("\n")


def test_check_names_the_unit_fix_without_raising(tmp_path: Path) -> None:
    """Millimetres read as metres: the check's result names the mistake and its fix with exit
    code 2, as `hapcal check` exits, and raises nothing; read in mm, the file is the original
    recording again (its residual to float rounding)."""
    mm = in_millimetres(tmp_path)
    c = hapcal.check(tiago(), mm)
    assert c.exit_code == 2
    first = c.findings[0]
    assert (first["class"], first["severity"]) == ("length-unit", "error")
    assert "millimetres, read as metres" in first["message"]
    assert "--length-unit mm" in first["fix"]
    assert c.error is not None and c.error.startswith("setup check [length-unit]: ")
    run = cli_check("--device", TIAGO_URDF, "--tip", TIAGO_TIP, "--data", str(mm))
    assert run.returncode == 2
    assert run.stderr.strip().splitlines()[-1] == f"hapcal: error: {c.error}"
    assert c.to_json() == run.stdout.rstrip("\n")

    # The original recording leaves millimetres; read as given, the mm file a thousand times
    # more. The fix's residual is the original's: the hypothesis's own refit (equal to the
    # solver's convergence), and the file read in mm the same numbers but for the rounding of
    # ×1e3 and ×1e-3.
    right = hapcal.check(tiago(), TIAGO_CSV)
    assert right.exit_code == 0, right.error
    rms = right.report["as_given"]["length_rms_m"]
    assert 0.0 < rms < 0.02
    assert first["before"]["length_rms_m"] > 100 * rms
    assert first["after"]["length_rms_m"] == pytest.approx(rms, rel=1e-9)
    for fixed in (hapcal.check(tiago(), mm, length_unit="mm"),
                  hapcal.check(tiago(), hapcal.Measurements.from_csv(mm, length_unit="mm"))):
        assert fixed.exit_code == 0, fixed.error
        assert fixed.report["as_given"]["length_rms_m"] == pytest.approx(rms, rel=1e-12)


def test_check_names_metres_read_as_millimetres() -> None:
    """The bundled UR10 recording (metres) read in mm: the reverse fix."""
    c = hapcal.check(ur10(), hapcal.Measurements.from_csv(UR10_CSV, length_unit="mm"))
    assert c.exit_code == 2
    assert [(f["class"], f["severity"]) for f in c.findings][:1] == [("length-unit", "error")]
    assert c.findings[0]["fix"] == "--length-unit m"


def test_check_refuses_what_it_cannot_read(tmp_path: Path) -> None:
    with pytest.raises(hapcal.HapcalError, match="same length_unit and angle_unit"):
        hapcal.check(ur10(), [hapcal.Measurements.from_csv(UR10_CSV, length_unit="mm"),
                              UR10_CSV])
    with pytest.raises(hapcal.HapcalError, match="check reads files"):
        hapcal.check(ur10(), hapcal.Measurements.from_arrays([[0.0] * 6], positions=[[0, 0, 1]]))
    with pytest.raises(hapcal.HapcalError, match="missing.csv"):
        hapcal.check(ur10(), tmp_path / "missing.csv")
    with pytest.raises(hapcal.HapcalError, match="length_unit"):
        hapcal.check(ur10(), UR10_CSV, length_unit="inch")


def test_import_urdf_is_the_command_lines_device_file(tmp_path: Path) -> None:
    urdf = ROOT / UR10_URDF  # the device file names it: absolute, to be read from anywhere
    text = hapcal.import_urdf(urdf, UR10_TIP)
    assert text == cli("import-urdf", str(urdf), "--tip", UR10_TIP)
    out = tmp_path / "ur10.toml"
    assert hapcal.import_urdf(str(urdf), [UR10_TIP], path=out) == text
    assert out.read_text() == text
    # The device file is the URDF's chain: the same joints, and the same frames-only residual
    # on the recording (its placements are written in the shortest decimal form that reads
    # back to the same float).
    imported = hapcal.Device.from_toml(out)
    assert imported.joint_names == ur10().joint_names
    as_toml = hapcal.check(imported, UR10_CSV).report["as_given"]["length_rms_m"]
    as_urdf = hapcal.check(ur10(), UR10_CSV).report["as_given"]["length_rms_m"]
    assert as_toml == pytest.approx(as_urdf, rel=1e-12)


def test_import_urdf_refuses_bad_tips_and_outputs(tmp_path: Path) -> None:
    urdf = tmp_path / "ur10.urdf"
    urdf.write_bytes((ROOT / UR10_URDF).read_bytes())
    before = urdf.read_bytes()
    with pytest.raises(hapcal.HapcalError, match="written as .toml"):
        hapcal.import_urdf(urdf, UR10_TIP, path=urdf)
    assert urdf.read_bytes() == before
    with pytest.raises(hapcal.HapcalError, match="no_such_link"):
        hapcal.import_urdf(urdf, "no_such_link")
    with pytest.raises(hapcal.HapcalError, match="tips"):
        hapcal.import_urdf(urdf, [])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ur10.urdf"]
