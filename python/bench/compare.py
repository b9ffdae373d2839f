#!/usr/bin/env python3
"""Python overhead of the hapcal bindings, and hapcal beside figaroh on the UR10 recording.

Reproduces docs/results/python.md. Run from anywhere, with the package installed
(`pip install ./python`) and the release command line built
(`cargo build --release -p hapcal`, binary in $CARGO_TARGET_DIR/release/hapcal):

    python python/bench/compare.py                 # both parts, 20 runs each
    python python/bench/compare.py --skip-figaroh  # part 1 only
    python python/bench/compare.py --runs 5 --rows 200 --seed 1

Part 1 (overhead): simulated KUKA iiwa 14 positions (random joint readings within 0.8 x the
URDF limits, forward kinematics of the URDF in NumPy, 0.1 mm Gaussian noise per coordinate),
calibrated with the geometric model through the command line (`--json`: its `elapsed_s` is the
in-process time, from reading the device to the report) and through `hapcal.calibrate` from
the CSV and from NumPy arrays. Overhead = Python median wall time / CLI median `elapsed_s` - 1.

Part 2 (figaroh): UR10 camera + checkerboard poses, first 16 rows train, last 7 test; hapcal
(CLI and Python, `--test-last 0.3`, model auto and geometric) and, if it is installed, figaroh's
geometric calibration (its calibration tools, base and tool frames unknown, Levenberg-Marquardt).

Prints Markdown tables.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

REPO_DEFAULT = Path(__file__).resolve().parents[2]


# ---------------------------------------------------------------- machine


def machine() -> str:
    model, cores = platform.processor() or "?", os.cpu_count()
    try:
        out = subprocess.run(["lscpu"], capture_output=True, text=True, check=True).stdout
        for line in out.splitlines():
            if line.startswith("Model name:"):
                model = line.split(":", 1)[1].strip()
    except (OSError, subprocess.CalledProcessError):
        pass
    return f"{model}, {cores} logical cores, {platform.system()} {platform.release()}, Python {platform.python_version()}"


# ---------------------------------------------------------------- URDF forward kinematics


def _rpy(r: float, p: float, y: float) -> np.ndarray:
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1.0]])
    ry = np.array([[cp, 0, sp], [0, 1.0, 0], [-sp, 0, cp]])
    rx = np.array([[1.0, 0, 0], [0, cr, -sr], [0, sr, cr]])
    return rz @ ry @ rx


def _axis_angle(axis: np.ndarray, a: float) -> np.ndarray:
    k = axis / np.linalg.norm(axis)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(a) * kx + (1 - math.cos(a)) * kx @ kx


class UrdfChain:
    """Serial chain of a URDF from its root to `tip` (revolute / continuous / prismatic / fixed)."""

    def __init__(self, path: Path, tip: str):
        root = ET.parse(path).getroot()
        by_child = {j.find("child").get("link"): j for j in root.findall("joint")}
        chain = []
        link = tip
        while link in by_child:
            j = by_child[link]
            chain.append(j)
            link = j.find("parent").get("link")
        self.joints = []
        for j in reversed(chain):
            o = j.find("origin")
            xyz = [float(v) for v in (o.get("xyz", "0 0 0") if o is not None else "0 0 0").split()]
            rpy = [float(v) for v in (o.get("rpy", "0 0 0") if o is not None else "0 0 0").split()]
            t = np.eye(4)
            t[:3, :3], t[:3, 3] = _rpy(*rpy), xyz
            kind = j.get("type")
            ax = j.find("axis")
            axis = np.array([float(v) for v in (ax.get("xyz") if ax is not None else "1 0 0").split()])
            lim = j.find("limit")
            limits = (float(lim.get("lower")), float(lim.get("upper"))) if lim is not None else (-math.pi, math.pi)
            self.joints.append((j.get("name"), kind, t, axis, limits))
        self.movable = [(n, lim) for n, k, _, _, lim in self.joints if k != "fixed"]

    def position(self, q: np.ndarray) -> np.ndarray:
        t = np.eye(4)
        i = 0
        for _, kind, origin, axis, _ in self.joints:
            t = t @ origin
            if kind in ("revolute", "continuous"):
                m = np.eye(4)
                m[:3, :3] = _axis_angle(axis, q[i])
                t = t @ m
                i += 1
            elif kind == "prismatic":
                m = np.eye(4)
                m[:3, 3] = axis / np.linalg.norm(axis) * q[i]
                t = t @ m
                i += 1
        return t[:3, 3]


def simulate_iiwa(repo: Path, rows: int, seed: int, noise_m: float, out: Path):
    chain = UrdfChain(repo / "fixtures/mukca/urdf/iiwa14.urdf", "ball_link")
    rng = np.random.default_rng(seed)
    lo = np.array([l for _, (l, _) in chain.movable]) * 0.8
    hi = np.array([h for _, (_, h) in chain.movable]) * 0.8
    q = rng.uniform(lo, hi, size=(rows, len(chain.movable)))
    p = np.array([chain.position(r) for r in q]) + rng.normal(0.0, noise_m, size=(rows, 3))
    names = [n for n, _ in chain.movable]
    with open(out, "w") as f:
        f.write(",".join(names + ["x", "y", "z"]) + "\n")
        for qi, pi in zip(q, p):
            f.write(",".join(repr(float(v)) for v in list(qi) + list(pi)) + "\n")
    return q, p, names


# ---------------------------------------------------------------- timing helpers


def median_ms(xs) -> float:
    return statistics.median(xs) * 1e3


def time_cli(cmd, runs: int, cwd: Path):
    subprocess.run(cmd, cwd=cwd, capture_output=True, check=True)  # warm the page cache
    walls, inproc = [], []
    report = None
    for _ in range(runs):
        t0 = time.perf_counter()
        r = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, check=True)
        walls.append(time.perf_counter() - t0)
        report = json.loads(r.stdout)
        inproc.append(report["elapsed_s"])
    return walls, inproc, report


def time_py(fn, runs: int):
    res = fn()  # warm-up
    walls, inproc = [], []
    for _ in range(runs):
        t0 = time.perf_counter()
        res = fn()
        walls.append(time.perf_counter() - t0)
        inproc.append(res.report["elapsed_s"])
    return walls, inproc, res


# ---------------------------------------------------------------- part 1


def part_overhead(args, repo: Path, bin_: Path, work: Path):
    import hapcal

    csv = work / "iiwa14_rows.csv"
    q, p, names = simulate_iiwa(repo, args.rows, args.seed, args.noise_m, csv)
    urdf = repo / "fixtures/mukca/urdf/iiwa14.urdf"
    cmd = [str(bin_), "calibrate", "--device", str(urdf), "--tip", "ball_link",
           "--data", str(csv), "--model", "geometric", "--json"]
    cli_wall, cli_in, cli_rep = time_cli(cmd, args.runs, repo)
    dev = hapcal.Device.from_urdf(str(urdf), tip="ball_link")

    def from_csv():
        return hapcal.calibrate(dev, hapcal.Measurements.from_csv(str(csv)), model="geometric")

    def from_arrays():
        m = hapcal.Measurements.from_arrays(q, positions=p, joint_names=names)
        return hapcal.calibrate(dev, m, model="geometric")

    csv_wall, csv_in, csv_res = time_py(from_csv, args.runs)
    arr_wall, arr_in, arr_res = time_py(from_arrays, args.runs)
    base = statistics.median(cli_in)

    def rms_after(rep):
        s = [f for f in rep.get("placements", []) if f.get("role") == "train"]
        try:
            return s[0]["after"]["pose"]["position_rms_m"] * 1e3
        except (IndexError, KeyError, TypeError):
            return float("nan")

    print(f"\n### Python overhead, {args.rows} rows, KUKA iiwa 14, model geometric (median of {args.runs} runs)\n")
    print(f"Data: `{csv}` (seed {args.seed}, noise {args.noise_m * 1e3:g} mm per coordinate).\n")
    print("| path | wall time (ms) | in-process `elapsed_s` (ms) | wall / CLI `elapsed_s` − 1 | wall / own `elapsed_s` − 1 | train position RMS after (mm) |")
    print("|---|---|---|---|---|---|")
    rows = [
        ("CLI `hapcal calibrate … --json` (process)", cli_wall, cli_in, cli_rep),
        ("Python `calibrate(dev, Measurements.from_csv(path))`", csv_wall, csv_in, csv_res.report),
        ("Python `calibrate(dev, Measurements.from_arrays(q, positions=p))`", arr_wall, arr_in, arr_res.report),
    ]
    for name, w, i, rep in rows:
        own = statistics.median(w) / statistics.median(i) - 1
        print(f"| {name} | {median_ms(w):.2f} | {median_ms(i):.2f} | {100 * (statistics.median(w) / base - 1):+.1f} % | {100 * own:+.1f} % | {rms_after(rep):.4f} |")
    print(f"\nCLI command: `{' '.join(cmd)}`")
    return {"cli_in": base, "csv": statistics.median(csv_wall), "arr": statistics.median(arr_wall)}


# ---------------------------------------------------------------- part 2


def errors_mm_deg(p_pred, p_meas, r_pred=None, r_meas=None):
    e = np.linalg.norm(p_pred - p_meas, axis=1) * 1e3
    pos = (e.mean(), math.sqrt((e ** 2).mean()), e.max())
    if r_pred is None:
        return pos, None
    ang = []
    for a, b in zip(r_pred, r_meas):
        c = (np.trace(a.T @ b) - 1) / 2
        ang.append(math.degrees(math.acos(max(-1.0, min(1.0, c)))))
    ang = np.array(ang)
    return pos, (ang.mean(), math.sqrt((ang ** 2).mean()), ang.max())


def fmt3(t):
    return "–" if t is None else " / ".join(f"{v:.2f}" for v in t)


def hapcal_test_figures(report):
    """(position mean/RMS/max mm, orientation mean/RMS/max deg) on the test set, after."""
    for s in report["placements"]:
        if s.get("role") == "test":
            a = s["after"]["pose"]
            pos = (a["position_mean_m"] * 1e3, a["position_rms_m"] * 1e3, a["position_max_m"] * 1e3)
            ori = None
            if a.get("orientation_rms_rad") is not None:
                ori = tuple(math.degrees(a[k]) for k in ("orientation_mean_rad", "orientation_rms_rad", "orientation_max_rad"))
            return pos, ori
    return None, None


def part_figaroh(args, repo: Path, bin_: Path):
    import hapcal

    d = repo / "fixtures/figaroh/ur10"
    urdf, csv = d / "ur10_robot.urdf", d / "calibration.csv"
    print(f"\n### UR10 (figaroh-examples), first 16 rows train, last 7 test (median of {args.runs} runs)\n")
    print("| tool, model | test position mean / RMS / max (mm) | test orientation mean / RMS / max (°) | wall time (ms) | in-process (ms) |")
    print("|---|---|---|---|---|")
    dev = hapcal.Device.from_urdf(str(urdf), tip="wrist_3_link")
    for model in ("auto", "geometric"):
        cmd = [str(bin_), "calibrate", "--device", str(urdf), "--tip", "wrist_3_link",
               "--data", str(csv), "--test-last", "0.3", "--json"] + (["--model", model] if model != "auto" else [])
        w, i, rep = time_cli(cmd, args.runs, repo)
        pos, ori = hapcal_test_figures(rep)
        print(f"| hapcal CLI, {model} (chosen: {rep.get('model', '?')}) | {fmt3(pos)} | {fmt3(ori)} | {median_ms(w):.1f} | {median_ms(i):.1f} |")
        pw, pi, res = time_py(lambda: hapcal.calibrate(dev, hapcal.Measurements.from_csv(str(csv)), model=model, test_last=0.3), args.runs)
        pos, ori = hapcal_test_figures(res.report)
        print(f"| hapcal Python, {model} | {fmt3(pos)} | {fmt3(ori)} | {median_ms(pw):.1f} | {median_ms(pi):.1f} |")
    if args.skip_figaroh:
        return
    try:
        out = figaroh_ur10(d, args.runs)
    except Exception as e:  # noqa: BLE001 - report whatever stopped it
        print(f"| figaroh | failed: {type(e).__name__}: {e} | | | |")
        return
    for name, (pos, ori, t) in out.items():
        print(f"| {name} | {fmt3(pos)} | {fmt3(ori)} | {t:.1f} | |")


# figaroh ---------------------------------------------------------------


def figaroh_ur10(d: Path, runs: int):
    """figaroh's geometric calibration of the UR10 on rows 0..15, evaluated on rows 16..22.

    figaroh 1.0.2 reads only its unified config format: the data set's legacy ur10_config.yaml
    is converted with figaroh.utils.config_migration (the "extends" template dropped), with the
    training rows as `source_file` and the test rows as `validation_data_file`. Base and tool
    frames unknown (`known_baseframe` / `known_tipframe` False), `calib_level: full_params`,
    outlier threshold 0.02 m, `solve()` defaults (LM, up to 3 fits with outlier removal).
    Two cost functions: "example" = figaroh-examples' UR10Calibration (measured − estimated
    poses, weights 1.0 position / 0.5 orientation; its regularisation term is dropped, as
    figaroh 1.0 removed coeff_regularize), "log-map" = BaseCalibration's documented recipe (SE3
    log-map residuals, body frame, default weighting). Test errors from figaroh's own validation
    residuals: per-row norm of the position part (= Euclidean position error) and of the
    rotation vector (= rotation angle).
    """
    import contextlib
    import io
    import logging
    import warnings

    import pinocchio as pin
    import yaml
    from figaroh.calibration import BaseCalibration
    from figaroh.calibration.base_calibration import _by_component
    from figaroh.calibration.calibration_tools import calc_updated_fkm
    from figaroh.utils.config_migration import convert_legacy_to_unified

    logging.disable(logging.WARNING)
    warnings.filterwarnings("ignore")
    work = Path(tempfile.mkdtemp(prefix="figaroh-ur10-"))
    lines = (d / "calibration.csv").read_text().splitlines()
    n = len(lines) - 1
    k = round(0.7 * n)
    (work / "train.csv").write_text("\n".join([lines[0]] + lines[1 : 1 + k]) + "\n")
    (work / "test.csv").write_text("\n".join([lines[0]] + lines[1 + k :]) + "\n")
    legacy = yaml.safe_load((d / "ur10_config.yaml").read_text())["calibration"]
    legacy["data_file"] = str(work / "train.csv")
    legacy["nb_sample"] = k
    uni = convert_legacy_to_unified({"calibration": legacy})
    uni.pop("extends", None)
    uni["tasks"]["calibration"]["data"]["validation_data_file"] = str(work / "test.csv")
    cfg = work / "ur10_unified.yaml"
    cfg.write_text(yaml.safe_dump(uni))
    model = pin.buildModelFromUrdf(str(d / "ur10_robot.urdf"))

    class Example(BaseCalibration):
        def cost_function(self, var):
            est = calc_updated_fkm(self.model, self.data, var, self.q_measured, self.calib_config)
            return self.apply_measurement_weighting(self.PEE_measured - est, pos_weight=1.0, orient_weight=0.5)

    class LogMap(BaseCalibration):
        def cost_function(self, var):
            est = calc_updated_fkm(self.model, self.data, var, self.q_measured, self.calib_config)
            r = self._compute_logmap_residuals(self.PEE_measured, est, position_frame="body")
            return self.apply_measurement_weighting(r)

    def stats(resid, c, n_val):
        a = _by_component(resid, c.calib_config, n_val)
        pos = np.linalg.norm(a[0:3], axis=0) * 1e3
        ang = np.degrees(np.linalg.norm(a[3:6], axis=0))
        f = lambda e: (e.mean(), math.sqrt((e ** 2).mean()), e.max())  # noqa: E731
        return f(pos), f(ang)

    out = {}
    for name, cls in (("example", Example), ("log-map", LogMap)):
        times, c = [], None
        for i in range(runs + 1):
            t0 = time.perf_counter()
            with contextlib.redirect_stdout(io.StringIO()):
                c = cls(pin.RobotWrapper(model), str(cfg))
                c.calib_config["known_baseframe"] = False
                c.calib_config["known_tipframe"] = False
                c.initialize()
                c.solve(enable_logging=False)
            if i:  # first run: warm-up
                times.append(time.perf_counter() - t0)
        v = c._compute_validation_metrics()
        n_val = v["n_val_samples"]
        pos, ang = stats(v["residuals_calibrated"], c, n_val)
        out[f"figaroh 1.0.2, full_params, cost {name} ({len(c.LM_result.x)} parameters)"] = (pos, ang, median_ms(times))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repo", type=Path, default=REPO_DEFAULT, help="hapcal checkout (default: this script's)")
    ap.add_argument("--hapcal", type=Path, default=None,
                    help="release binary (default: $CARGO_TARGET_DIR/release/hapcal, else <repo>/target/release/hapcal)")
    ap.add_argument("--runs", type=int, default=20)
    ap.add_argument("--rows", type=int, default=200)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--noise-m", type=float, default=1e-4)
    ap.add_argument("--work", type=Path, default=None, help="folder for the simulated CSV (default: a temporary one)")
    ap.add_argument("--skip-overhead", action="store_true")
    ap.add_argument("--skip-figaroh", action="store_true", help="hapcal's UR10 figures only")
    args = ap.parse_args()
    repo = args.repo.resolve()
    bin_ = args.hapcal or Path(os.environ.get("CARGO_TARGET_DIR", repo / "target")) / "release" / "hapcal"
    import hapcal

    print(f"Machine: {machine()}; hapcal {hapcal.__version__}; binary `{bin_}`.")
    work = args.work or Path(tempfile.mkdtemp(prefix="hapcal-bench-"))
    work.mkdir(parents=True, exist_ok=True)
    if not args.skip_overhead:
        part_overhead(args, repo, bin_, work)
    part_figaroh(args, repo, bin_)


if __name__ == "__main__":
    sys.exit(main())
