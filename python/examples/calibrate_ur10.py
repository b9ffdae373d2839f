"""Calibrate figaroh's UR10 recording (camera + checkerboard poses) from Python and plot the
residuals of every pose before and after calibration, and the held-out errors of every rung of
the model ladder against frames only.

    pip install ./python matplotlib pandas
    python python/examples/calibrate_ur10.py    # writes ur10_residuals.png, ur10_ladder.png

The first 70 % of the rows train, the last 30 % test (``test_last=0.3``), as in
docs/results/real-data.md. ``model="auto"`` lets cross-validation choose the rung; the plot also
shows each rung forced, so the choice can be checked by eye.
"""

from pathlib import Path

import hapcal

ROOT = Path(__file__).resolve().parents[2]
UR10 = ROOT / "fixtures" / "figaroh" / "ur10"
RUNGS = ["frames-only", "joint-offsets", "geometric", "compliance"]


def test_figures(calibration):
    """(position RMS mm, orientation RMS deg) of the test rows, frames only and calibrated."""
    test = next(s for s in calibration.figures if s["role"] == "test")
    out = []
    for side in ("before", "after"):
        pose = test[side]["pose"]
        out.append((pose["position_rms_m"] * 1e3, pose["orientation_rms_rad"] * 57.29577951308232))
    return out


def main():
    robot = hapcal.Device.from_urdf(str(UR10 / "ur10_robot.urdf"), tip="wrist_3_link")
    data = hapcal.Measurements.from_csv(str(UR10 / "calibration.csv"))
    auto = hapcal.calibrate(robot, data, test_last=0.3)
    print(f"chosen by cross-validation: {auto.model}")
    for w in auto.warnings:
        print(f"warning: {w}")
    print(auto.parameters)

    rows = []
    for rung in RUNGS:
        (p0, o0), (p1, o1) = test_figures(hapcal.calibrate(robot, data, test_last=0.3, model=rung))
        rows.append((rung, p1, o1))
        print(f"{rung:<14} test position RMS {p1:.3f} mm, orientation RMS {o1:.3f} deg")

    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib is not installed: no plot")
        return
    # Residuals of every pose, frames only and the geometric model (forced), train then test.
    geometric = hapcal.calibrate(robot, data, test_last=0.3, model="geometric")
    fig, ax = plt.subplots(figsize=(9, 3.5))
    start = 0
    for s in geometric.figures:
        before = [e * 1e3 for e in s["errors"]["position_before_m"]]
        after = [e * 1e3 for e in s["errors"]["position_after_m"]]
        x = range(start, start + len(before))
        ax.plot(x, before, "o", color="tab:gray", label="frames only" if start == 0 else None)
        ax.plot(x, after, "o", color="tab:blue", label="geometric" if start == 0 else None)
        start += len(before)
        if s["role"] == "train":
            ax.axvline(start - 0.5, color="k", lw=0.8, ls=":")
    ax.set_xlabel("pose (file order; dotted line: end of the training rows)")
    ax.set_ylabel("3-D position error (mm)")
    ax.legend()
    fig.tight_layout()
    fig.savefig("ur10_residuals.png", dpi=120)
    print("wrote ur10_residuals.png")

    fig, (ax_p, ax_o) = plt.subplots(1, 2, figsize=(9, 3.5))
    names = [r[0] for r in rows]
    ax_p.bar(names, [r[1] for r in rows], color="tab:blue")
    ax_p.axhline(rows[0][1], color="k", lw=0.8, ls="--", label="frames only")
    ax_p.set_ylabel("test position RMS (mm)")
    ax_o.bar(names, [r[2] for r in rows], color="tab:orange")
    ax_o.axhline(rows[0][2], color="k", lw=0.8, ls="--")
    ax_o.set_ylabel("test orientation RMS (deg)")
    for ax in (ax_p, ax_o):
        ax.tick_params(axis="x", rotation=30)
    ax_p.legend()
    fig.suptitle(f"UR10, last 30 % held out; cross-validation chose {auto.model}")
    fig.tight_layout()
    fig.savefig("ur10_ladder.png", dpi=120)
    print("wrote ur10_ladder.png")


if __name__ == "__main__":
    main()
