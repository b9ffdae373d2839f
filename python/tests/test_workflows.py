"""simulate, plan_poses and diagnose from Python give the command line's numbers and errors."""

from __future__ import annotations

import csv
import json
import math
import subprocess
from pathlib import Path
from typing import Dict, List

import numpy as np
import pytest

import hapcal
from conftest import ROOT, UR10_TIP, UR10_URDF, _cli_command, assert_close, cli

TRUTH = "fixtures/reference-device/truth.toml"
DEVICE = "fixtures/reference-device/device.toml"


def cli_error(*args: str) -> str:
    """The message of a failing `hapcal ARGS` (stderr without `hapcal: error: `)."""
    out = subprocess.run(_cli_command() + list(args), cwd=ROOT, capture_output=True, text=True)
    assert out.returncode == 2, out
    line = out.stderr.strip().splitlines()[-1]
    assert line.startswith("hapcal: error: "), line
    return line[len("hapcal: error: "):]


def read_csv(path: Path) -> Dict[str, List[float]]:
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    header, body = rows[0], rows[1:]
    return {h: [float(r[i]) if r[i] else math.nan for r in body] for i, h in enumerate(header)}


def assert_columns_close(got: Dict[str, np.ndarray], want: Dict[str, List[float]]) -> None:
    assert list(got) == list(want)
    for name, values in want.items():
        np.testing.assert_allclose(got[name], values, rtol=1e-12, atol=1e-12, err_msg=name)


# --- simulate -------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "args, kwargs",
    [
        (["--poses", "60", "--seed", "3"], dict(poses=60, seed=3)),
        (
            ["--poses", "40", "--seed", "5", "--noise", "arc-length", "--effect",
             "backlash:j2=1e-3", "--period-s", "0.25"],
            dict(poses=40, seed=5, noise="arc-length", effects=["backlash:j2=1e-3"],
                 period_s=0.25),
        ),
        (["--poses", "30", "--motion"], dict(poses=30, motion=True)),
    ],
)
def test_simulate_equals_cli(tmp_path: Path, args: List[str], kwargs: dict) -> None:
    cli("simulate", "--truth", TRUTH, *args, "--out", str(tmp_path / "cli.csv"))
    log = hapcal.simulate(TRUTH, path=tmp_path / "py.csv", **kwargs)
    assert (tmp_path / "py.csv").read_bytes() == (tmp_path / "cli.csv").read_bytes()
    want = read_csv(tmp_path / "cli.csv")
    assert_columns_close(log, want)
    assert all(a.dtype == np.float64 and a.shape == (kwargs["poses"],) for a in log.values())
    assert ("t_s" in log) == bool(kwargs.get("motion") or kwargs.get("effects"))
    # Without a path: the same columns, nothing written.
    assert_columns_close(hapcal.simulate(TRUTH, **kwargs), want)


def test_simulate_defaults_equal_cli(tmp_path: Path) -> None:
    # No truth: the nominal reference device; seed 1, 200 poses, paper noise as the CLI.
    cli("simulate", "--out", str(tmp_path / "cli.csv"))
    assert_columns_close(hapcal.simulate(), read_csv(tmp_path / "cli.csv"))


def test_simulate_feeds_calibrate_and_diagnose(tmp_path: Path) -> None:
    out = tmp_path / "log.csv"
    log = hapcal.simulate(TRUTH, poses=80, seed=2, path=out)
    pd = pytest.importorskip("pandas")
    assert list(pd.DataFrame(log).columns) == list(log)
    data = hapcal.Measurements.from_csv(out)
    assert hapcal.diagnose(hapcal.Device.from_toml(DEVICE), data).report["n_samples"] == 80


def test_simulate_errors(tmp_path: Path) -> None:
    msg = cli_error("simulate", "--truth", TRUTH, "--effect", "nope:x=1",
                    "--out", str(tmp_path / "a.csv"))
    with pytest.raises(hapcal.HapcalError) as e:
        hapcal.simulate(TRUTH, effects=["nope:x=1"])
    assert str(e.value) == msg
    with pytest.raises(hapcal.HapcalError, match="noise must be `paper` or `arc-length`"):
        hapcal.simulate(TRUTH, noise="loud")
    with pytest.raises(hapcal.HapcalError, match=r"missing\.toml"):
        hapcal.simulate(tmp_path / "missing.toml")
    with pytest.raises(hapcal.HapcalError, match=r"cannot write .*\.toml: the simulated log"):
        hapcal.simulate(TRUTH, path=tmp_path / "log.toml")
    with pytest.raises(hapcal.HapcalError, match="poses"):
        hapcal.simulate(TRUTH, poses=0)
    assert not list(tmp_path.iterdir())


# --- plan_poses -----------------------------------------------------------------------------


def test_plan_poses_equals_cli(tmp_path: Path) -> None:
    cli("plan-poses", "--device", DEVICE, "--count", "60", "--candidates", "300", "--seed", "2",
        "--out", str(tmp_path / "cli.csv"))
    dev = hapcal.Device.from_toml(DEVICE)
    q = hapcal.plan_poses(dev, count=60, candidates=300, seed=2, path=tmp_path / "py.csv")
    assert q.shape == (60, dev.n_joints) and q.dtype == np.float64
    assert (tmp_path / "py.csv").read_bytes() == (tmp_path / "cli.csv").read_bytes()
    want = read_csv(tmp_path / "cli.csv")
    assert list(want) == dev.joint_names
    # The CLI writes 9 decimals; the array is full precision: equal once rounded as the CLI.
    rounded = np.vectorize(lambda v: float(f"{v:.9f}"))(q)
    np.testing.assert_allclose(rounded, np.column_stack(list(want.values())), rtol=1e-12,
                               atol=1e-12)
    np.testing.assert_allclose(q, rounded, rtol=0, atol=5e-10)
    lo, hi = np.array(dev.joint_limits).T
    assert np.all((q >= lo) & (q <= hi))


@pytest.mark.parametrize("model", ["geometric", "compliance"])
def test_plan_poses_urdf_position_equals_cli(tmp_path: Path, model: str) -> None:
    cli("plan-poses", "--device", UR10_URDF, "--tip", UR10_TIP, "--measurement", "position",
        "--count", "20", "--candidates", "200", "--criterion", "o3", "--model", model, "--out",
        str(tmp_path / "cli.csv"))
    dev = hapcal.Device.from_urdf(UR10_URDF, tip=UR10_TIP)
    hapcal.plan_poses(dev, "position", 20, "o3", candidates=200, path=tmp_path / "py.csv",
                      model=model)
    assert (tmp_path / "py.csv").read_bytes() == (tmp_path / "cli.csv").read_bytes()


def test_plan_poses_errors(tmp_path: Path) -> None:
    dev = hapcal.Device.from_toml(DEVICE)
    msg = cli_error("plan-poses", "--device", DEVICE, "--count", "12", "--candidates", "200",
                    "--out", str(tmp_path / "a.csv"))
    with pytest.raises(hapcal.HapcalError) as e:
        hapcal.plan_poses(dev, count=12, candidates=200)
    assert str(e.value) == msg
    assert "cannot determine" in msg
    with pytest.raises(hapcal.HapcalError, match="criterion: unknown criterion"):
        hapcal.plan_poses(dev, criterion="best")
    with pytest.raises(hapcal.HapcalError, match="measurement: expected distance or position"):
        hapcal.plan_poses(dev, measurement="angle")
    with pytest.raises(hapcal.HapcalError, match="sigma_m must be a positive length"):
        hapcal.plan_poses(dev, sigma_m=-1.0)
    with pytest.raises(hapcal.HapcalError, match="--model auto: the poses are planned for one"):
        hapcal.plan_poses(dev, model="auto")
    with pytest.raises(hapcal.HapcalError, match=r"device\.toml: the planned poses is written as \.csv"):
        hapcal.plan_poses(dev, path=ROOT / DEVICE)
    assert not list(tmp_path.iterdir())


# --- diagnose -------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def effect_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("diag") / "log.csv"
    hapcal.simulate(TRUTH, poses=60, seed=3, effects=["backlash:j2=1e-3"], path=path)
    return path


@pytest.mark.parametrize("baseline, folds", [("transmissions", 5), ("geometric", 4)])
def test_diagnose_equals_cli(tmp_path: Path, effect_log: Path, baseline: str, folds: int) -> None:
    text = cli("diagnose", "--device", DEVICE, "--data", str(effect_log), "--baseline", baseline,
               "--folds", str(folds), "--json", "--svg", str(tmp_path / "maps.svg"))
    d = hapcal.diagnose(hapcal.Device.from_toml(DEVICE), effect_log, baseline=baseline,
                        folds=folds)
    assert_close(d.report, json.loads(text))
    assert d.to_json() + "\n" == text
    assert d.verdict == d.report["verdict"] and d.report["baseline"] == baseline
    assert d.warnings == []
    # A Measurements read from the file is the same log.
    same = hapcal.diagnose(hapcal.Device.from_toml(DEVICE),
                           hapcal.Measurements.from_csv(effect_log), baseline, folds)
    assert same.to_json() == d.to_json()


def test_diagnose_reference_log_equals_cli(tmp_path: Path) -> None:
    log = "fixtures/reference-device/log.csv"
    text = cli("diagnose", "--device", DEVICE, "--data", log, "--json", "--svg",
               str(tmp_path / "maps.svg"))
    d = hapcal.diagnose(hapcal.Device.from_toml(DEVICE), log)
    assert_close(d.report, json.loads(text))


def test_diagnose_errors(tmp_path: Path, effect_log: Path) -> None:
    dev = hapcal.Device.from_toml(DEVICE)
    msg = cli_error("diagnose", "--device", DEVICE, "--data", str(effect_log), "--baseline",
                    "everything", "--svg", str(tmp_path / "m.svg"))
    with pytest.raises(hapcal.HapcalError) as e:
        hapcal.diagnose(dev, effect_log, baseline="everything")
    assert str(e.value) == msg
    missing = tmp_path / "missing.csv"
    msg = cli_error("diagnose", "--device", DEVICE, "--data", str(missing), "--svg",
                    str(tmp_path / "m.svg"))
    with pytest.raises(hapcal.HapcalError) as e:
        hapcal.diagnose(dev, missing)
    assert str(e.value) == msg and "reading log" in msg
    with pytest.raises(hapcal.HapcalError, match="folds must be at least 2"):
        hapcal.diagnose(dev, effect_log, folds=1)
    with pytest.raises(hapcal.HapcalError, match="diagnose reads a log file"):
        hapcal.diagnose(dev, hapcal.Measurements.from_arrays(np.zeros((3, 7)),
                                                             distances=np.ones(3)))
    with pytest.raises(hapcal.HapcalError, match="m and rad"):
        hapcal.diagnose(dev, hapcal.Measurements.from_csv(effect_log, length_unit="mm"))


# --- diagnose, serial arms --------------------------------------------------------------------


def test_diagnose_arm_poses_equal_cli(tmp_path: Path) -> None:
    text = cli("diagnose", "--device", UR10_URDF, "--tip", UR10_TIP, "--data",
               "fixtures/figaroh/ur10/calibration.csv", "--test-last", "0.3", "--json", "--svg",
               str(tmp_path / "m.svg"))
    d = hapcal.diagnose(hapcal.Device.from_urdf(UR10_URDF, tip=UR10_TIP),
                        "fixtures/figaroh/ur10/calibration.csv", test_last=0.3)
    assert_close(d.report, json.loads(text))
    assert d.to_json() + "\n" == text


def test_diagnose_arm_sockets_equal_cli(tmp_path: Path) -> None:
    urdf = "fixtures/mukca/urdf/iiwa14.urdf"
    front = "fixtures/mukca/data/kuka_14/front"
    back = "fixtures/mukca/data/kuka_14/left_back"
    text = cli("diagnose", "--device", urdf, "--data", front, "--test", back, "--json", "--svg",
               str(tmp_path / "m.svg"))
    d = hapcal.diagnose(hapcal.Device.from_urdf(urdf, tip="ball_link"),
                        hapcal.Measurements.from_csv(front), test=back)
    assert_close(d.report, json.loads(text))
    assert d.verdict == json.loads(text)["verdict"]


def test_diagnose_arm_options(tmp_path: Path) -> None:
    dev = hapcal.Device.from_urdf(UR10_URDF, tip=UR10_TIP)
    with pytest.raises(hapcal.HapcalError, match="diagnosed on its geometric calibration"):
        hapcal.diagnose(dev, "fixtures/figaroh/ur10/calibration.csv", baseline="kinematics")
    with pytest.raises(hapcal.HapcalError, match="test, sigma_m and test_last"):
        hapcal.diagnose(hapcal.Device.from_toml(DEVICE), "fixtures/reference-device/log.csv",
                        test_last=0.3)


def test_diagnose_runs_the_setup_check(tmp_path: Path) -> None:
    """Cable distances in centimetres read as metres: `hapcal diagnose` exits 2 naming the
    mistake, so does Python; told to go on, the verdict is `setup`, as the command line's."""
    log = ROOT / "fixtures/reference-device/log.csv"
    lines = log.read_text().splitlines()
    k = lines[0].split(",").index("distance_m")
    out = [lines[0]]
    for line in lines[1:]:
        cells = line.split(",")
        cells[k] = repr(float(cells[k]) * 100.0)
        out.append(",".join(cells))
    cm = tmp_path / "log_cm.csv"
    cm.write_text("\n".join(out) + "\n")
    msg = cli_error("diagnose", "--device", DEVICE, "--data", str(cm), "--svg",
                    str(tmp_path / "m.svg"))
    dev = hapcal.Device.from_toml(DEVICE)
    with pytest.raises(hapcal.HapcalError) as e:
        hapcal.diagnose(dev, cm)
    # The same words, with the option as Python spells it.
    assert msg.replace("--accept-setup", "accept_setup=True") in str(e.value)
    d = hapcal.diagnose(dev, cm, accept_setup=True)
    text = cli("diagnose", "--device", DEVICE, "--data", str(cm), "--accept-setup",
               "--json", "--svg", str(tmp_path / "n.svg"))
    assert d.verdict == "setup" == json.loads(text)["verdict"]
