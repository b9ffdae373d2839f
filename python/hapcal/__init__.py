"""hapcal from Python: kinematic calibration of haptic devices and serial robots.

The numbers come from the same Rust library the ``hapcal`` command line runs
(``hapcal-calibrate``); this package adds NumPy and pandas inputs and Python objects for the
report.

Example::

    import hapcal
    dev = hapcal.Device.from_urdf("ur10_robot.urdf", tip="wrist_3_link")
    data = hapcal.Measurements.from_csv("calibration.csv")
    print(hapcal.check(dev, data).findings)   # units, column order, tip link, … ([] here)
    cal = hapcal.calibrate(dev, data, test_last=0.3)
    print(cal.parameters)        # name, value, std, unit (a DataFrame with pandas)
    cal.to_urdf("ur10_calibrated.urdf")

Also :func:`simulate` (a haptic device's log from a truth file), :func:`plan_poses` (which
poses to measure), :func:`diagnose` (the sim-to-real gap of a log), :func:`check` (the setup
of measurement files) and :func:`import_urdf` (a URDF as a device file), as the command
line's subcommands of the same names, and :func:`predict` (the calibrated model's tip
positions with their 1σ at new joint readings, ``hapcal predict``).

Units are SI throughout: metres, radians, seconds.

The namespace holds the names of ``__all__`` and nothing else public: the implementation
lives in the private module ``hapcal._api``, the compiled core in ``hapcal._hapcal``.
"""

from . import _hapcal
from ._api import (
    CRITERIA,
    MODELS,
    Calibration,
    Device,
    Diagnosis,
    HapcalError,
    Measurements,
    Prediction,
    SetupCheck,
    calibrate,
    check,
    diagnose,
    import_urdf,
    plan_poses,
    predict,
    simulate,
)
from ._hapcal import RuntimeModel, RuntimeRobot

__all__ = [
    "Calibration",
    "Device",
    "HapcalError",
    "RuntimeModel",
    "RuntimeRobot",
    "Measurements",
    "MODELS",
    "CRITERIA",
    "Diagnosis",
    "SetupCheck",
    "Prediction",
    "calibrate",
    "check",
    "diagnose",
    "import_urdf",
    "plan_poses",
    "predict",
    "simulate",
]
__version__: str = _hapcal.__version__

# The classes and functions defined in Python say they are hapcal's (as the compiled ones do),
# not the private module's, in their repr and in help().
for _obj in (Calibration, Diagnosis, Measurements, Prediction, SetupCheck, calibrate, check,
             diagnose, import_urdf, plan_poses, predict, simulate):
    _obj.__module__ = __name__
del _obj
