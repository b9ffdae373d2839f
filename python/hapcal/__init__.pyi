"""Type stubs of hapcal (Python bindings of the hapcal Rust crates). Units: m, rad, s."""

import os
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

_PathLike = Union[str, os.PathLike[str]]
_ArrayLike = npt.ArrayLike

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

__version__: str
MODELS: Tuple[str, ...]

class HapcalError(ValueError):
    """Any error reported by hapcal; the message is the whole chain of causes, with
    file:line:column where there is one."""

class Device:
    """A robot or haptic device: a serial URDF with tip link(s), or a hapcal device file."""

    @staticmethod
    def from_urdf(path: _PathLike, tip: str, tips: Optional[Sequence[str]] = None) -> Device:
        """URDF with the tool on link ``tip``; ``tips``: further tip links of a tree (marker
        k+1 on the k-th of ``[tip, *tips]``)."""
    @staticmethod
    def from_toml(path: _PathLike) -> Device:
        """hapcal device file: D-H / modified D-H table, URDF placements, or a haptic device."""
    @property
    def joint_names(self) -> List[str]:
        """Joint names, chain order (the columns ``q1..qn`` in order)."""
    @property
    def n_joints(self) -> int: ...
    @property
    def joint_limits(self) -> List[Tuple[float, float]]:
        """``(lower, upper)`` per joint, rad (m for a prismatic joint)."""
    @property
    def path(self) -> str: ...
    @property
    def tips(self) -> List[str]: ...

class RuntimeModel:
    """A calibrated haptic device in a control loop (hapcal-runtime; the object the C ABI's
    handle holds): the device file ``hapcal calibrate`` writes."""

    def __init__(self, path: _PathLike) -> None: ...
    @property
    def n_joints(self) -> int: ...
    def evaluate(self, theta: Sequence[float], wrench: Sequence[float]) -> Dict[str, Any]:
        """For joint readings ``theta`` (rad) and a wrench in the tip frame (N, N·m):
        ``q_rad``, ``dq_dtheta``, ``pose`` (4 × 4, m), ``body_jacobian`` (6 × n: linear,
        then angular) and ``motor_torques_nm``. Raises HapcalError."""

class RuntimeRobot:
    """A calibrated robot in a control loop (hapcal-runtime): the URDF and its sidecar
    ``<stem>.calibration.toml`` that ``hapcal calibrate --out robot.urdf`` writes."""

    def __init__(self, urdf: _PathLike, tips: Sequence[str]) -> None: ...
    @property
    def joint_names(self) -> List[str]: ...
    @property
    def tip_names(self) -> List[str]: ...
    def frame(self, name: str) -> Optional[List[List[float]]]:
        """Identified frame (4 × 4, m): ``"instrument"`` (root link in the instrument frame)
        or ``"marker1"``, … (marker in its tip link's frame); None if not identified."""
    def tip_poses(self, q: Sequence[float], deflected: bool = True) -> List[List[List[float]]]:
        """4 × 4 pose (m) of each tip at joint angles ``q`` (rad), deflected under the robot's
        own weight unless ``deflected=False``. Raises HapcalError."""
    def compensate(
        self,
        target: Sequence[float],
        start: Sequence[float],
        tip: int = 0,
        tolerance_m: float = 1e-6,
        tolerance_rad: float = 1e-6,
        max_iterations: int = 50,
    ) -> Dict[str, Any]:
        """Joint command at which the deflected tip reaches ``target`` (x, y, z m, or with
        qw, qx, qy, qz), from ``start``: ``q``, ``reached``, ``position_error_m``,
        ``orientation_error_rad``, ``iterations``. Raises HapcalError."""

class Measurements:
    """One data set of joint readings with marker poses or distances."""

    @classmethod
    def from_csv(
        cls,
        path: _PathLike,
        length_unit: str = "m",
        angle_unit: str = "rad",
        column_units: Optional[Dict[str, str]] = None,
        column_signs: Optional[Sequence[str]] = None,
        column_offsets: Optional[Dict[str, float]] = None,
        column_scales: Optional[Dict[str, float]] = None,
        column_couplings: Optional[Dict[str, str]] = None,
    ) -> Measurements:
        """Measurement CSV / industrial_calibration YAML / hapcal log / MUKCa folder, read when
        calibrating. ``length_unit``: "m" | "mm" | "cm" | "in" | "ft"; ``angle_unit``: "rad" |
        "deg" | "grad" | "rev"; ``column_units``: {"q3": "deg", "x2,y2,z2": "mm"};
        ``column_signs``: ["q3"]; ``column_offsets``: {"q2": -1.5708}; ``column_scales``:
        {"q3": 0.01}; ``column_couplings``: {"q6": "-0.5*q5"} (the CLI's --column-* options)."""
    @classmethod
    def from_arrays(
        cls,
        q: _ArrayLike,
        positions: Optional[_ArrayLike] = None,
        quaternions: Optional[_ArrayLike] = None,
        distances: Optional[_ArrayLike] = None,
        joint_names: Optional[Sequence[str]] = None,
        *,
        rpy: Optional[_ArrayLike] = None,
        t: Optional[_ArrayLike] = None,
        name: str = "arrays",
        length_unit: str = "m",
        angle_unit: str = "rad",
        ignored_columns: Optional[Sequence[str]] = None,
        ignore_unknown_joints: bool = False,
    ) -> Measurements:
        """``q`` (n, n_joints) rad/m; ``positions`` (n, 3) | (n, k, 3) m, all-NaN marker: not
        seen; ``quaternions`` (n, 4) | (n, k, 4) w, x, y, z, or ``rpy`` (n, 3) | (n, k, 3)
        R = Rz·Ry·Rx, rad; ``distances`` (n,) m, NaN: none; ``t`` (n,) s."""
    @classmethod
    def from_dataframe(
        cls,
        df: Any,
        joint_names: Optional[Sequence[str]] = None,
        *,
        name: str = "dataframe",
        length_unit: str = "m",
        angle_unit: str = "rad",
    ) -> Measurements:
        """pandas DataFrame with the measurement CSV's column names."""
    @property
    def n_rows(self) -> Optional[int]: ...
    @property
    def path(self) -> Optional[str]: ...
    @property
    def name(self) -> str: ...

class Calibration:
    """Result of :func:`calibrate`."""

    @property
    def report(self) -> Dict[str, Any]:
        """``hapcal calibrate --json``'s document as a dict."""
    def to_json(self) -> str:
        """``hapcal calibrate --json``'s document, byte for byte (no final newline)."""
    @property
    def model(self) -> str: ...
    @property
    def parameters(self) -> Any:
        """name, value, std, unit per identified parameter: a pandas DataFrame, or a list of
        dicts without pandas."""
    @property
    def figures(self) -> List[Dict[str, Any]]:
        """Per data set: name, role, n_rows, before / after figures (m, rad)."""
    @property
    def frames(self) -> List[Dict[str, Any]]: ...
    @property
    def warnings(self) -> List[str]: ...
    def to_urdf(self, path: _PathLike) -> List[str]:
        """Calibrated copy of the source URDF (+ ``<path>.calibration.toml``); paths written."""
    def to_toml(self, path: _PathLike) -> List[str]:
        """Device file with a ``[calibration]`` table; paths written."""
    def predicted_positions(self, q: _ArrayLike) -> npt.NDArray[np.float64]:
        """The calibration library's positions (m) at joint readings ``q`` (n_rows, n_joints;
        rad, m prismatic), shape (n_rows, n_markers, 3): a robot's markers in the instrument
        frame (marker k on tip min(k, last)); a haptic device's end point (n_markers = 1),
        readings through its transmissions and handle compliance. Raises HapcalError."""

_MeasurementsLike = Union[Measurements, Sequence[Union[Measurements, _PathLike]], _PathLike]

def calibrate(
    device: Device,
    train: _MeasurementsLike,
    test: Optional[_MeasurementsLike] = None,
    model: str = "auto",
    sigma_m: Optional[float] = None,
    sigma_rad: Optional[float] = None,
    test_last: Optional[float] = None,
    folds: int = 5,
    *,
    socket_distance_m: float = 0.05,
    joint: bool = False,
    accept_setup: bool = False,
) -> Calibration:
    """Identify the model (``model="auto"``: chosen by blocked cross-validation on ``train``)
    and report figures before / after on ``train`` and ``test``. Raises HapcalError."""

CRITERIA: Tuple[str, ...]

def simulate(
    truth: Optional[_PathLike] = None,
    seed: int = 1,
    poses: int = 200,
    motion: bool = False,
    noise: str = "paper",
    effects: Optional[Sequence[str]] = None,
    *,
    device: Optional[_PathLike] = None,
    period_s: float = 0.5,
    path: Optional[_PathLike] = None,
) -> Dict[str, npt.NDArray[np.float64]]:
    """``hapcal simulate``: the log's columns in CSV order, each ``(poses,)``: ``q1..qn`` rad
    (m prismatic), ``distance_m`` m, ``ext1..ext4`` rad (NaN: none), ``t_s`` s (motion).
    ``noise``: "paper" | "arc-length"; ``effects``: e.g. ``"backlash:j2=1e-3"`` (implies
    motion); ``path``: also write the CSV (atomically). Raises HapcalError."""

def plan_poses(
    device: Device,
    measurement: str = "distance",
    count: int = 30,
    criterion: str = "d-optimal",
    seed: int = 1,
    candidates: int = 1000,
    *,
    sigma_m: Optional[float] = None,
    separate_transmission_run: bool = False,
    refine: bool = False,
    path: Optional[_PathLike] = None,
    model: str = "geometric",
) -> npt.NDArray[np.float64]:
    """``hapcal plan-poses``: joint readings ``(count, n_joints)``, rad (m prismatic), chain
    order, full precision. ``measurement``: "distance" | "position"; ``criterion``: one of
    :data:`CRITERIA`; ``sigma_m`` m; ``path``: also write the CSV (9 decimals, atomically).
    Raises HapcalError."""

class Diagnosis:
    """Result of :func:`diagnose`."""

    @property
    def report(self) -> Dict[str, Any]:
        """``hapcal diagnose --json``'s document as a dict (m, rad)."""
    def to_json(self) -> str:
        """``hapcal diagnose --json``'s document, byte for byte (no final newline)."""
    @property
    def verdict(self) -> str:
        """Accepted effects joined by ``+``, ``"none"``, or ``"setup"`` (a mistake accepted)."""
    @property
    def warnings(self) -> List[str]:
        """The setup check's warnings, then the data's (``file:line:column: …``)."""

def diagnose(
    device: Device,
    data: Union[Measurements, _PathLike, Sequence[Union[Measurements, _PathLike]]],
    baseline: Optional[str] = None,
    folds: int = 5,
    *,
    test: Optional[Union[Measurements, _PathLike, Sequence[Union[Measurements, _PathLike]]]] = None,
    sigma_m: Optional[float] = None,
    test_last: Optional[float] = None,
    accept_setup: bool = False,
) -> Diagnosis:
    """``hapcal diagnose``: ``data`` a log CSV path or ``Measurements.from_csv`` of one;
    ``baseline``: a haptic device: "transmissions" (default) | "geometric" ("full" |
    "kinematics" read as these); a robot: "geometric" (default, the only one); ``folds`` ≥ 2;
    ``accept_setup``: go on past a setup mistake (verdict "setup"). Raises HapcalError."""

class SetupCheck:
    """Result of :func:`check`; a failing check is a result, not an error."""

    @property
    def report(self) -> Dict[str, Any]:
        """``hapcal check --json``'s document as a dict (m, rad)."""
    def to_json(self) -> str:
        """``hapcal check --json``'s document, byte for byte (no final newline)."""
    @property
    def findings(self) -> List[Dict[str, Any]]:
        """Errors first: ``class`` ("length-unit", "joint-order", …), ``severity`` ("error" |
        "warning"), ``message``, ``fix`` (the command line's option or the edit of the files),
        ``before`` / ``after`` residuals (m, rad)."""
    @property
    def exit_code(self) -> int:
        """``hapcal check``'s exit code: 0 nothing found or only warnings, 2 a mistake the
        data show overwhelmingly."""
    @property
    def error(self) -> Optional[str]:
        """The message ``hapcal check`` stops with when ``exit_code`` is 2, else None."""

def check(
    device: Device,
    data: Union[Measurements, _PathLike, Sequence[Union[Measurements, _PathLike]]],
    *,
    length_unit: str = "m",
    angle_unit: str = "rad",
    socket_distance_m: float = 0.05,
) -> SetupCheck:
    """``hapcal check``: the setup of measurement files, a haptic device's logs or socket
    folders (files only); ``length_unit`` "m" | "mm" and ``angle_unit`` "rad" | "deg" for
    paths. Raises HapcalError only for input it cannot read."""

def import_urdf(
    urdf: _PathLike, tips: Union[str, Sequence[str]], *, path: Optional[_PathLike] = None
) -> str:
    """``hapcal import-urdf``: the device file's TOML text for the URDF chain to ``tips`` (a
    tree: one branch per further tip); ``path``: also write it (``.toml``, atomically, never
    over the URDF). Raises HapcalError."""

class Prediction:
    """Result of :func:`predict`: positions (m), σ (m, rad), region flags, errors."""

    lines: npt.NDArray[np.int64]
    positions: npt.NDArray[np.float64]
    quaternions: npt.NDArray[np.float64]
    sigma_m: npt.NDArray[np.float64]
    sigma_rad: npt.NDArray[np.float64]
    region_joint: List[Optional[str]]
    region_past: npt.NDArray[np.float64]
    errors: Optional[Dict[str, Dict[str, float]]]
    uncertainty: str
    uncertainty_note: Optional[str]
    n_values: int
    warnings: List[str]
    tips: List[str]
    frame: str
    @property
    def outside_region(self) -> npt.NDArray[np.bool_]:
        """Whether each row lies outside the calibration's region."""

def predict(
    device: _PathLike,
    tips: Union[str, Sequence[str]],
    data: _PathLike,
    *,
    instrument_frame: bool = False,
    length_unit: str = "m",
    angle_unit: str = "rad",
) -> Prediction:
    """``hapcal predict``: the calibrated URDF's tip positions (or, with
    ``instrument_frame``, its markers in the instrument frame) at the joint readings of
    ``data``, with 1σ from the calibration record, the region flag and the errors against
    measured columns. Raises HapcalError."""
