#!/usr/bin/env python3
"""Peer of hapcal's kinematic identification for `cargo xtask bench --peers`.

Solves the same problem as `crates/identify/examples/scale.rs solve`, on the same data file,
with SciPy's `least_squares` and an analytic Jacobian, and prints one JSON object (wall
times, evaluation counts, estimates by name). Shares no code with hapcal: it reads the D-H
table of fixtures/reference-device/device.toml and the CSV that hapcal wrote.

    python scipy_peer.py --data poses-200.csv --method lm --free da0,da1,... --repeat 10

Problem (docs/design.md §2): standard D-H chain A_i = Rz(theta_i + dtheta_i + q_i) Tz(d_i + dd_i)
Tx(a_i + da_i) Rx(alpha_i + dalpha_i), rows 0..7 (row 0 fixed), residual per pose
r = (|P| - distance_m) / sigma_m with sigma_m = 2 pi 0.015 (2 pi / 20000 / 3) m; unknowns: the
deviations named by --free (the others held at 0); start x = 0.
"""

import argparse
import json
import math
import pathlib
import time
import tomllib

import numpy as np
import scipy
from scipy.optimize import least_squares

ROOT = pathlib.Path(__file__).resolve().parents[2]
SIGMA_E = 2.0 * math.pi / 20000.0 / 3.0
SIGMA_M = 2.0 * math.pi * 0.015 * SIGMA_E


def load(data):
    with open(ROOT / "fixtures/reference-device/device.toml", "rb") as f:
        rows = tomllib.load(f)["dh"]
    nominal = np.array([[r["a_m"], r["alpha_rad"], r["d_m"], r["theta_rad"]] for r in rows])
    table = np.loadtxt(data, delimiter=",", skiprows=1)
    return nominal, table[:, :7], table[:, 7]


def make_problem(nominal, q, dist, free):
    n_rows = nominal.shape[0]
    n = q.shape[0]
    index = {name: k for k, name in enumerate(free)}

    def deviations(x):
        dev = np.zeros((n_rows, 4))  # da, dalpha, dd, dtheta
        for i in range(n_rows):
            for c, kind in enumerate(("da", "dalpha", "dd", "dtheta")):
                k = index.get(f"{kind}{i}")
                if k is not None:
                    dev[i, c] = x[k]
        return dev

    def frames(x):
        """End points P (n, 3) and, per row, the world frame pieces the Jacobian needs."""
        dev = deviations(x)
        R = np.broadcast_to(np.eye(3), (n, 3, 3)).copy()
        p = np.zeros((n, 3))
        per_row = []
        for i in range(n_rows):
            a = nominal[i, 0] + dev[i, 0]
            alpha = nominal[i, 1] + dev[i, 1]
            d = nominal[i, 2] + dev[i, 2]
            theta = nominal[i, 3] + dev[i, 3] + (q[:, i - 1] if i >= 1 else 0.0)
            theta = theta * np.ones(n)
            ct, st = np.cos(theta), np.sin(theta)
            ca, sa = math.cos(alpha), math.sin(alpha)
            z = R[:, :, 2].copy()  # axis of theta and d, world frame
            o_theta = p.copy()
            xr = R[:, :, 0] * ct[:, None] + R[:, :, 1] * st[:, None]  # x after Rz: a, alpha axis
            yr = -R[:, :, 0] * st[:, None] + R[:, :, 1] * ct[:, None]
            p = p + z * d + xr * a
            o_alpha = p.copy()
            R = np.stack([xr, yr * ca + z * sa, -yr * sa + z * ca], axis=2)
            per_row.append((z, o_theta, xr, o_alpha))
        return p, per_row

    def residuals(x):
        p, _ = frames(x)
        return (np.linalg.norm(p, axis=1) - dist) / SIGMA_M

    def jacobian(x):
        p, per_row = frames(x)
        norm = np.linalg.norm(p, axis=1)
        u = p / norm[:, None]
        J = np.zeros((n, len(free)))
        for i, (z, o_theta, xr, o_alpha) in enumerate(per_row):
            cols = {
                f"da{i}": xr,
                f"dalpha{i}": np.cross(xr, p - o_alpha),
                f"dd{i}": z,
                f"dtheta{i}": np.cross(z, p - o_theta),
            }
            for name, col in cols.items():
                k = index.get(name)
                if k is not None:
                    J[:, k] = np.einsum("ni,ni->n", u, col) / SIGMA_M
        return J

    return residuals, jacobian


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", required=True)
    ap.add_argument("--method", choices=("lm", "trf"), required=True)
    ap.add_argument("--free", required=True, help="comma-separated parameter names, in order")
    ap.add_argument("--tol", type=float, default=1e-12)
    ap.add_argument("--repeat", type=int, default=1)
    args = ap.parse_args()
    free = args.free.split(",")
    nominal, q, dist = load(args.data)
    residuals, jacobian = make_problem(nominal, q, dist, free)
    x0 = np.zeros(len(free))
    times = []
    sol = None
    for _ in range(args.repeat):
        t = time.perf_counter()
        sol = least_squares(
            residuals, x0, jac=jacobian, method=args.method, x_scale="jac",
            ftol=args.tol, xtol=args.tol, gtol=args.tol, max_nfev=200,
        )
        times.append(time.perf_counter() - t)
    times.sort()
    print(json.dumps({
        "method": args.method,
        "scipy": scipy.__version__,
        "numpy": np.__version__,
        "n_poses": int(q.shape[0]),
        "min_s": times[0],
        "median_s": times[len(times) // 2],
        "status": int(sol.status),
        "message": sol.message,
        "nfev": int(sol.nfev),
        "njev": int(sol.njev) if sol.njev is not None else None,
        "cost": float(sol.cost),
        "x": {name: float(v) for name, v in zip(free, sol.x)},
    }))


if __name__ == "__main__":
    main()
