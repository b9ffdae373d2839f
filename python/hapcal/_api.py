"""The implementation of the ``hapcal`` package: its public names are re-exported by
``hapcal/__init__.py``, which is all a user imports. Module-level imports live here, under
this private module, so that ``hapcal``'s namespace holds only its own names.
"""

from __future__ import annotations

import json
import os
import warnings
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np

from . import _hapcal
from ._hapcal import Device, HapcalError

#: Model names accepted by :func:`calibrate` (``_`` and ``-`` are interchangeable): the
#: command line's ``--model`` values, from the compiled core's one definition of the model choice.
MODELS: Tuple[str, ...] = tuple(_hapcal.MODELS)

PathLike = Union[str, "os.PathLike[str]"]


def _float_array(name: str, value: Any) -> np.ndarray:
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise HapcalError(f"{name}: expected an array of numbers: {e}") from None
    return a


def _flat(a: np.ndarray) -> List[float]:
    return np.ascontiguousarray(a, dtype=np.float64).ravel().tolist()


class Measurements:
    """Measurements of one data set: joint readings with marker positions / orientations of an
    external instrument (laser tracker, motion capture, camera) or distances from an anchor,
    or a hapcal log or MUKCa recording read from a file or folder.

    Build one with :meth:`from_csv`, :meth:`from_arrays` or :meth:`from_dataframe`.
    """

    __slots__ = ("_inner",)

    def __init__(self, inner: "_hapcal._Measurements") -> None:
        self._inner = inner

    @classmethod
    def from_csv(
        cls,
        path: PathLike,
        length_unit: str = "m",
        angle_unit: str = "rad",
        column_units: Optional[Dict[str, str]] = None,
        column_signs: Optional[Sequence[str]] = None,
        column_offsets: Optional[Dict[str, float]] = None,
        column_scales: Optional[Dict[str, float]] = None,
        column_couplings: Optional[Dict[str, str]] = None,
    ) -> "Measurements":
        """A measurement file (CSV with a header row, or industrial_calibration's YAML), a
        hapcal log CSV, or a MUKCa placement / run folder, read when calibrating (its joint
        columns are matched to the device's joints then).

        ``length_unit``: ``"m"``, ``"mm"``, ``"cm"``, ``"in"`` or ``"ft"`` (positions,
        distances; prismatic joint readings stay in m, the robot's own unit);
        ``angle_unit``: ``"rad"``, ``"deg"``, ``"grad"`` or ``"rev"`` (revolute joints,
        ``phix, phiy, phiz``);
        ``column_units``: the unit of some columns, as ``--column-unit`` gives it, e.g.
        ``{"q3": "deg", "x2,y2,z2": "mm"}`` (columns as the header spells them, or ``q1..qn``);
        ``column_signs``, ``column_offsets``, ``column_scales``, ``column_couplings``: the
        corrections ``--column-sign``, ``--column-offset``, ``--column-scale`` and
        ``--column-coupling`` make, which the setup check's findings name: ``["q3"]`` (the
        column counts the other way), ``{"q2": -1.5708}`` (rad, m for a length, added after
        the unit), ``{"q3": 0.01}`` (a reading on the motor side of a 100:1 gear),
        ``{"q6": "-0.5*q5"}`` (q5's share taken out of q6).

        Raises :class:`HapcalError` for a missing file or a unit it does not know; a column the
        file lacks is reported when the file is read.
        """
        def items(d: Optional[Dict[str, Any]]) -> Optional[List[Tuple[str, Any]]]:
            return list(d.items()) if d else None

        return cls(
            _hapcal._Measurements.from_path(
                os.fspath(path),
                length_unit,
                angle_unit,
                items(column_units),
                list(column_signs) if column_signs else None,
                items(column_offsets),
                items(column_scales),
                items(column_couplings),
            )
        )

    @classmethod
    def from_arrays(
        cls,
        q: Any,
        positions: Any = None,
        quaternions: Any = None,
        distances: Any = None,
        joint_names: Optional[Sequence[str]] = None,
        *,
        rpy: Any = None,
        t: Any = None,
        name: str = "arrays",
        length_unit: str = "m",
        angle_unit: str = "rad",
        ignored_columns: Optional[Sequence[str]] = None,
        ignore_unknown_joints: bool = False,
    ) -> "Measurements":
        """Measurements from arrays (NumPy or anything ``np.asarray`` takes).

        - ``q``: joint readings, shape ``(n, n_joints)``, rad (m for a prismatic joint);
          columns in chain order (``Device.joint_names``), or named by ``joint_names`` (device
          joint names or ``q1..qn``, any order).
        - ``positions``: marker positions in the instrument's frame, m: ``(n, 3)`` for one
          marker or ``(n, k, 3)`` for k markers; a marker whose values in a row are all NaN
          was not seen there.
        - ``quaternions``: marker orientations, unit quaternions ``(w, x, y, z)``: ``(n, 4)``
          or ``(n, k, 4)``. Or ``rpy``: figaroh's roll, pitch, yaw ``(n, 3)`` / ``(n, k, 3)``
          with R = Rz(yaw)·Ry(pitch)·Rx(roll), rad.
        - ``distances``: ``(n,)``, m, from an anchor (cable encoder, ballbar) to the first
          marker's frame; NaN: no distance in that row.
        - ``t``: ``(n,)`` time, s, non-decreasing.
        - ``name``: the data set's name in the report.
        - ``length_unit`` / ``angle_unit``: units of the values given (as in a CSV file).
        - ``ignored_columns``: column names reported as ignored (for :meth:`from_dataframe`).
        - ``ignore_unknown_joints``: columns of ``q`` whose ``joint_names`` entry is no joint of
          the device are ignored and reported (as a CSV file's extra columns) instead of an
          error.

        Raises :class:`HapcalError` (a ``ValueError``) for wrong shapes or values.
        """
        qa = _float_array("q", q)
        if qa.ndim != 2:
            raise HapcalError(f"q: expected shape (n, n_joints), found {qa.shape}")
        n, nj = qa.shape
        if n == 0:
            raise HapcalError("q: no rows")

        def markers(label: str, value: Any, width: int) -> Optional[np.ndarray]:
            if value is None:
                return None
            a = _float_array(label, value)
            if a.ndim == 2:
                a = a[:, None, :]
            if a.ndim != 3 or a.shape[0] != n or a.shape[2] != width:
                raise HapcalError(
                    f"{label}: expected shape ({n}, {width}) or ({n}, k, {width}), found "
                    f"{np.shape(value)}"
                )
            return a

        pos = markers("positions", positions, 3)
        quat = markers("quaternions", quaternions, 4)
        eul = markers("rpy", rpy, 3)
        k = 0 if pos is None else pos.shape[1]
        for label, a in (("quaternions", quat), ("rpy", eul)):
            if a is not None and (pos is None or a.shape[1] != k):
                raise HapcalError(
                    f"{label}: expected one orientation per marker of positions "
                    f"({k} markers), found shape {a.shape}"
                )

        def column(label: str, value: Any) -> Optional[List[float]]:
            if value is None:
                return None
            a = _float_array(label, value)
            if a.shape != (n,):
                raise HapcalError(f"{label}: expected shape ({n},), found {a.shape}")
            return a.tolist()

        if joint_names is not None:
            joint_names = [str(j) for j in joint_names]
            if len(joint_names) != nj:
                raise HapcalError(
                    f"joint_names: {len(joint_names)} names for the {nj} columns of q"
                )
        inner = _hapcal._Measurements.from_flat(
            name,
            n,
            nj,
            _flat(qa),
            k,
            None if pos is None else _flat(pos),
            None if quat is None else _flat(quat),
            None if eul is None else _flat(eul),
            column("distances", distances),
            column("t", t),
            joint_names,
            length_unit,
            angle_unit,
            list(ignored_columns or []),
            bool(ignore_unknown_joints),
        )
        return cls(inner)

    @classmethod
    def from_dataframe(
        cls,
        df: Any,
        joint_names: Optional[Sequence[str]] = None,
        *,
        name: str = "dataframe",
        length_unit: str = "m",
        angle_unit: str = "rad",
    ) -> "Measurements":
        """Measurements from a pandas DataFrame whose columns follow the measurement CSV's
        conventions (see the README):

        - joints: ``q1..qn`` (chain order), or the device's joint names given as
          ``joint_names`` (without it, the columns that are not measurements are taken as
          joints, in order);
        - markers: ``x, y, z`` or ``x1, y1, z1, x2, …`` (m); orientation ``qw, qx, qy, qz``
          (``qw1, …``) or ``phix, phiy, phiz`` (``phix1, …``); NaN cells: marker not seen;
        - ``distance_m`` / ``distance`` / ``d`` (m); ``t`` / ``t_s`` (s).

        Columns that match nothing are reported as ignored, as for a CSV file.
        """
        columns = [str(c) for c in df.columns]
        used: set = set()

        def col(c: str) -> np.ndarray:
            used.add(c)
            return df[c].to_numpy(dtype=np.float64, na_value=np.nan)

        def numbered(stem: str, k: int, unnumbered: bool) -> str:
            return stem if unnumbered else f"{stem}{k + 1}"

        unnumbered = "x" in columns
        k = 0
        while numbered("x", k, unnumbered) in columns and not (unnumbered and k > 0):
            k += 1
        for stem in ("y", "z"):
            for m in range(k):
                if numbered(stem, m, unnumbered) not in columns:
                    raise HapcalError(
                        f"marker {m + 1}: column {numbered(stem, m, unnumbered)!r} missing "
                        f"(columns: {', '.join(columns)})"
                    )

        def stack(stems: Sequence[str]) -> Optional[np.ndarray]:
            names = [[numbered(s, m, unnumbered) for s in stems] for m in range(k)]
            present = [c in columns for row in names for c in row]
            if not any(present):
                return None
            if not all(present):
                missing = [c for row in names for c in row if c not in columns]
                raise HapcalError(f"orientation columns missing: {', '.join(missing)}")
            return np.stack([np.stack([col(c) for c in row], axis=-1) for row in names], axis=1)

        positions = stack(("x", "y", "z")) if k else None
        quaternions = stack(("qw", "qx", "qy", "qz")) if k else None
        rpy = stack(("phix", "phiy", "phiz")) if k else None
        distances = None
        for c in ("distance_m", "distance", "d"):
            if c in columns:
                distances = col(c)
                break
        t = None
        for c in ("t", "t_s"):
            if c in columns:
                t = col(c)
                break
        qs: List[str] = []
        if joint_names is not None:
            joints = [str(j) for j in joint_names]
            missing = [j for j in joints if j not in columns]
            if missing:
                raise HapcalError(
                    f"joint columns missing: {', '.join(missing)}; the columns are "
                    f"{', '.join(columns)}"
                )
        else:
            qs = [c for c in columns if c[:1] == "q" and c[1:].isdigit() and c[1:2] != "0"]
            joints = sorted(qs, key=lambda c: int(c[1:])) if qs else [
                c
                for c in columns
                if c not in used and not _measurement_column(c) and _numeric(df[c])
            ]
        if not joints:
            raise HapcalError(f"no joint columns; the columns are {', '.join(columns)}")
        q = np.stack([col(c) for c in joints], axis=-1)
        ignored = [c for c in columns if c not in used]
        return cls.from_arrays(
            q,
            positions=positions,
            quaternions=quaternions,
            distances=distances,
            joint_names=joints,
            rpy=rpy,
            t=t,
            name=name,
            length_unit=length_unit,
            angle_unit=angle_unit,
            ignored_columns=ignored,
            ignore_unknown_joints=joint_names is None and not qs,
        )

    @property
    def n_rows(self) -> Optional[int]:
        """Number of rows (``None`` for a file, read when calibrating)."""
        return self._inner.n_rows

    @property
    def path(self) -> Optional[str]:
        """The file or folder these measurements come from, if any."""
        p = self._inner.path
        return None if p is None else os.fspath(p)

    @property
    def name(self) -> str:
        """Name of the data set in the report."""
        return self._inner.name

    def __repr__(self) -> str:
        if self.path is not None:
            return f"Measurements.from_csv({self.path!r})"
        return f"Measurements({self.name!r}, n_rows={self.n_rows})"


def _numeric(series: Any) -> bool:
    """Whether a data frame column holds numbers (a text column is no joint)."""
    try:
        series.to_numpy(dtype=np.float64, na_value=np.nan)
    except (TypeError, ValueError):
        return False
    return True


def _measurement_column(c: str) -> bool:
    import re

    return bool(
        re.fullmatch(r"(x|y|z|qw|qx|qy|qz|phix|phiy|phiz)([1-9][0-9]*)?", c)
        or c in ("distance_m", "distance", "d", "t", "t_s")
    )


class Calibration:
    """The result of :func:`calibrate`: the report and the calibrated model."""

    __slots__ = ("_inner", "_report")

    def __init__(self, inner: "_hapcal._Calibration") -> None:
        self._inner = inner
        self._report: Dict[str, Any] = json.loads(inner.to_json())

    @property
    def report(self) -> Dict[str, Any]:
        """The report as a dict: exactly what ``hapcal calibrate --json`` prints."""
        return self._report

    def to_json(self) -> str:
        """The report as JSON, byte for byte what ``hapcal calibrate --json`` prints (without
        the final newline)."""
        return self._inner.to_json()

    @property
    def model(self) -> str:
        """The model identified (chosen by cross-validation for ``model="auto"``)."""
        return self._report["model"]

    @property
    def parameters(self) -> Any:
        """Identified parameters (deviations from nominal): name, value, std, unit (m or
        rad). A pandas DataFrame when pandas is importable, else a list of dicts."""
        rows = [dict(p) for p in self._report["parameters"]]
        try:
            import pandas as pd
        except ImportError:
            return rows
        return pd.DataFrame(rows, columns=["name", "value", "std", "unit"])

    @property
    def figures(self) -> List[Dict[str, Any]]:
        """Per data set (training first): name, role (train / test), n_rows, and the figures
        of merit before (nominal model) and after calibration, m and rad."""
        return self._report["placements"]

    @property
    def frames(self) -> List[Dict[str, Any]]:
        """Marker data: the identified instrument and marker frames (xyz_m, rpy_rad)."""
        return self._report.get("frames", [])

    @property
    def warnings(self) -> List[str]:
        """Plain-language warnings about what the data cannot support."""
        return self._report["warnings"]

    def to_urdf(self, path: PathLike) -> List[str]:
        """Writes a copy of the source URDF with the calibrated joint origins (and
        ``<path>.calibration.toml`` beside it for what a URDF cannot hold). The files are read
        back first as ``hapcal predict`` reads them: nothing is written unless they give the
        calibration's marker positions within 1 µm (an error says where they part). Returns the
        paths written."""
        return [os.fspath(p) for p in self._inner.write_outputs(os.fspath(path))]

    def to_toml(self, path: PathLike) -> List[str]:
        """Writes a device file with a ``[calibration]`` table, read back first as
        :meth:`to_urdf`'s files are. Returns the paths written."""
        return [os.fspath(p) for p in self._inner.write_outputs(os.fspath(path))]

    def predicted_positions(self, q: Any) -> np.ndarray:
        """The calibration library's predicted positions at joint readings ``q`` (n_rows,
        n_joints; rad, m for a prismatic joint; the device's joints in order), m, shape
        (n_rows, n_markers, 3): for a robot, each marker in the instrument frame (marker k on
        tip min(k, last)), from the model the report's errors come from; for a haptic device
        (n_markers = 1), its end point with the readings through the identified
        transmissions and handle compliance. What the written files must reproduce in
        :class:`RuntimeRobot` and :class:`RuntimeModel`. Raises HapcalError."""
        a = _float_array("q", q)
        if a.ndim != 2:
            raise HapcalError(
                f"q: expected a 2-D array (n_rows, n_joints), found {a.ndim} dimension(s)"
            )
        rows = [list(map(float, r)) for r in a]
        if not rows:
            return np.zeros((0, 0, 3))
        return np.asarray(self._inner.predicted_positions(rows), dtype=np.float64).reshape(
            len(rows), -1, 3
        )

    def __repr__(self) -> str:
        return (
            f"Calibration(model={self.model!r}, parameters={len(self._report['parameters'])}, "
            f"warnings={len(self.warnings)})"
        )


MeasurementsLike = Union[Measurements, Sequence[Measurements], PathLike]


def _as_list(what: str, value: Any) -> List[Any]:
    if value is None:
        return []
    if isinstance(value, (str, os.PathLike)):
        value = Measurements.from_csv(value)
    items = [value] if isinstance(value, Measurements) else list(value)
    out = []
    for m in items:
        if isinstance(m, (str, os.PathLike)):
            m = Measurements.from_csv(m)
        if not isinstance(m, Measurements):
            raise TypeError(f"{what}: expected Measurements, found {type(m).__name__}")
        out.append(m._inner)
    return out


def calibrate(
    device: Device,
    train: MeasurementsLike,
    test: Optional[MeasurementsLike] = None,
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
    """Calibrates ``device`` from ``train`` and evaluates on ``test`` (never fitted).

    - ``train`` / ``test``: :class:`Measurements`, a list of them, or paths.
    - ``model``: one of :data:`MODELS`; ``"auto"`` chooses by blocked cross-validation on the
      training data (marker data: the ladder frames-only → joint-offsets → geometric →
      compliance).
    - ``sigma_m`` / ``sigma_rad``: measurement noise, m / rad, if known (else estimated).
    - ``test_last``: hold out this fraction of each training set's last rows as a test set.
    - ``folds``: cross-validation folds (≥ 2).
    - ``socket_distance_m``: MUKCa recordings: distance between the two sockets, m.
    - ``joint``: haptic device: transmissions and kinematics in one problem.
    - ``accept_setup``: calibrate files even when the setup check (``hapcal check``) finds a
      mistake (millimetres read as metres, swapped joint columns, another tip link, …), or when
      the fit moves a length by more than a real device's manufacturing leaves (the data are
      another device's); without it such a mistake raises :class:`HapcalError`, as
      ``hapcal calibrate`` exits. The check's warnings are issued as :class:`UserWarning`
      (the command line prints them).

    Measurements read from files with the same units run exactly the command line's
    ``hapcal calibrate``; arrays go through the marker workflow (``measured::run_tables``).
    The GIL is released while solving. Raises :class:`HapcalError` on any error.
    """
    if isinstance(folds, bool) or int(folds) != folds or folds < 0:
        raise HapcalError(f"folds: expected a whole number ≥ 2, found {folds!r}")
    inner = _hapcal._calibrate(
        device,
        _as_list("train", train),
        _as_list("test", test),
        str(model),
        None if sigma_m is None else float(sigma_m),
        None if sigma_rad is None else float(sigma_rad),
        None if test_last is None else float(test_last),
        int(folds),
        float(socket_distance_m),
        bool(joint),
        bool(accept_setup),
    )
    for w in inner.setup_warnings:
        warnings.warn(w, UserWarning, stacklevel=2)
    return Calibration(inner)


#: Values of :func:`plan_poses`'s ``criterion``.
CRITERIA = ("d-optimal", "o1", "o3", "o4", "o5", "i-optimal")


def _optional_path(path: Optional[PathLike]) -> Optional[str]:
    return None if path is None else os.fspath(path)


def _count(what: str, value: Any, least: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < least:
        raise HapcalError(f"{what}: expected a whole number ≥ {least}, found {value!r}")
    return int(value)


def simulate(
    truth: Optional[PathLike] = None,
    seed: int = 1,
    poses: int = 200,
    motion: bool = False,
    noise: str = "paper",
    effects: Optional[Sequence[str]] = None,
    *,
    device: Optional[PathLike] = None,
    period_s: float = 0.5,
    path: Optional[PathLike] = None,
) -> Dict[str, np.ndarray]:
    """Simulates a measurement log of a haptic device, as ``hapcal simulate`` does (the same
    ``hapcal_sim`` calls, so the same seed gives the same log, bit for bit).

    - ``truth``: truth file (TOML: the nominal device file, deviations, transmission
      parameters); ``None``: the nominal device (``device``, else the bundled reference
      device).
    - ``seed``: random seed; ``poses``: number of poses (≥ 1).
    - ``motion``: a time-ordered motion (``t_s`` column, every joint in both directions, one
      sample every ``period_s`` s) instead of independent random poses.
    - ``noise``: cable noise, ``"paper"`` (σ_m = 2π·R_d·σ_e) or ``"arc-length"`` (R_d·σ_e).
    - ``effects``: unmodelled effects to inject, e.g. ``["backlash:j2=1e-3",
      "cable_angle:k=2e-4"]``; implies ``motion``.
    - ``device``: nominal device file (TOML), instead of the one the truth names.
    - ``path``: also write the log CSV there (atomically; never over an input), byte for byte
      what ``hapcal simulate --out`` writes. Read it back with :meth:`Measurements.from_csv`.

    Returns the log's columns, in the CSV's order, as a dict of 1-D float arrays of length
    ``poses``: ``q1..qn`` joint readings, rad (m for a prismatic joint); ``distance_m`` the
    cable distance, m; ``ext1..ext4`` the external encoders' output angles, rad (the columns
    the device has; NaN where a row has none); ``t_s`` time, s (motion only).
    ``pandas.DataFrame(log)`` makes a data frame of it. The GIL is released while simulating.

    Raises :class:`HapcalError` on any error (unreadable truth or device, a device without a
    cable encoder, an unknown effect or noise model, an output path that cannot be written).
    """
    names, columns = _hapcal._simulate(
        _optional_path(truth),
        _optional_path(device),
        _count("seed", seed, 0),
        _count("poses", poses, 1),
        str(noise),
        [str(e) for e in (effects or [])],
        bool(motion),
        float(period_s),
        _optional_path(path),
    )
    return {n: np.asarray(c, dtype=np.float64) for n, c in zip(names, columns)}


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
    path: Optional[PathLike] = None,
    model: str = "geometric",
) -> np.ndarray:
    """Chooses the poses to measure, as ``hapcal plan-poses`` does (``plan::plan_poses``):
    from ``candidates`` poses sampled uniformly within the joint limits (seed ``seed``), the
    ``count`` that maximise ``criterion`` of the identification Jacobian at the nominal model
    (greedy start + DETMAX exchange).

    - ``measurement``: what the rig measures, ``"distance"`` (cable encoder) or
      ``"position"`` (tracker).
    - ``criterion``: one of :data:`CRITERIA` (``"d-optimal"`` = o1 for a fixed count).
    - ``sigma_m``: measurement noise σ, m (default: the paper's σ_m of the cable encoder, else
      10 µm).
    - ``separate_transmission_run``: the transmissions are identified from a separate
      external-encoder run: plan the measurement poses alone.
    - ``refine``: refine the chosen poses by coordinate exchange over the joint box.
    - ``path``: also write the poses CSV there (atomically), byte for byte what
      ``hapcal plan-poses --out`` writes (joint names, readings to 9 decimals).
    - ``model``: the model the poses are planned for, one of :data:`MODELS` (``"geometric"``,
      or a richer one you will calibrate: ``"compliance"``, ``"harmonic"``, …; not
      ``"auto"``, ``"frames-only"`` or ``"joint-offsets"``).

    Returns the joint readings, shape ``(count, n_joints)``, rad (m for a prismatic joint),
    columns in chain order (``device.joint_names``), full precision. The GIL is released
    while planning. Raises :class:`HapcalError` on any error.
    """
    if not isinstance(device, Device):
        raise TypeError(f"device: expected hapcal.Device, found {type(device).__name__}")
    _names, readings = _hapcal._plan_poses(
        device,
        str(measurement),
        _count("count", count, 1),
        _count("candidates", candidates, 1),
        _count("seed", seed, 0),
        str(criterion),
        None if sigma_m is None else float(sigma_m),
        bool(separate_transmission_run),
        bool(refine),
        _optional_path(path),
        str(model),
    )
    return np.asarray(readings, dtype=np.float64).reshape(len(readings), device.n_joints)


class Diagnosis:
    """The result of :func:`diagnose`: how far the calibrated model's held-out residual lies
    above the noise floor, where, which unmodelled effect explains it and how far it
    shrinks."""

    __slots__ = ("_json", "_report", "_warnings")

    def __init__(self, text: str, warnings: List[str]) -> None:
        self._json = text
        self._report: Dict[str, Any] = json.loads(text)
        self._warnings = list(warnings)

    @property
    def report(self) -> Dict[str, Any]:
        """The diagnosis as a dict: exactly what ``hapcal diagnose --json`` prints (lengths in
        m, angles in rad)."""
        return self._report

    def to_json(self) -> str:
        """The diagnosis as JSON, byte for byte what ``hapcal diagnose --json`` prints
        (without the final newline)."""
        return self._json

    @property
    def verdict(self) -> str:
        """The effects named, joined by ``+``; ``"none"``; or ``"setup"`` when the setup check
        found a mistake and ``accept_setup`` went on (no physical effect is named then)."""
        return self._report["verdict"]

    @property
    def warnings(self) -> List[str]:
        """The setup check's warnings, then the data's (unknown columns ignored,
        ``file:line:column: …``); the command line prints them on standard error."""
        return self._warnings

    def __repr__(self) -> str:
        r = self._report
        return f"Diagnosis(verdict={r.get('verdict')!r})"


def diagnose(
    device: Device,
    data: MeasurementsLike,
    baseline: Optional[str] = None,
    folds: int = 5,
    *,
    test: Optional[MeasurementsLike] = None,
    sigma_m: Optional[float] = None,
    test_last: Optional[float] = None,
    accept_setup: bool = False,
) -> Diagnosis:
    """Diagnoses the sim-to-real gap, as ``hapcal diagnose`` does.

    - ``device``: a haptic device with transmissions (:meth:`Device.from_toml`): its own
      log is diagnosed (``hapcal_diagnose::diagnose``); any other robot
      (:meth:`Device.from_urdf`, a D-H device file): everything :func:`calibrate` reads —
      sockets, distances, markers, poses — on its geometric calibration
      (``hapcal_diagnose::arm``).
    - ``data``: :class:`Measurements`, a list of them, or paths (a haptic device: one log,
      ``q1..qn, distance_m, ext1..ext4, t_s``, in m and rad).
    - ``baseline``: the model the gap is measured against, by its :data:`MODELS` name. A
      haptic device: ``"transmissions"`` (the paper's full calibration; the default) or
      ``"geometric"`` (the kinematic deviations alone; the transmission models then join the
      candidates), ``"full"`` and ``"kinematics"`` being read as these; a robot:
      ``"geometric"`` (the default).
    - ``folds``: cross-validation folds (time-contiguous blocks, ≥ 2).
    - ``test``, ``sigma_m``, ``test_last``: a robot only: held-out sets, the instrument's σ
      (m, the noise floor), the share of each training set's last rows held out.
    - ``accept_setup``: diagnose files even when the setup check finds a mistake; the verdict
      is then ``setup`` (no physical effect is named on data set up wrong) and the notes give
      the finding. Without it the mistake raises :class:`HapcalError`, as the command line
      exits; the check's warnings join :attr:`Diagnosis.warnings`.

    The residual-map SVG of the command line is not written. The GIL is released while
    diagnosing. Raises :class:`HapcalError` on any error (unreadable files with
    file:line:column, a bad baseline or fold count, a failed baseline fit).
    """
    if not isinstance(device, Device):
        raise TypeError(f"device: expected hapcal.Device, found {type(device).__name__}")
    if isinstance(folds, bool) or not isinstance(folds, (int, np.integer)):
        raise HapcalError(f"folds: expected a whole number ≥ 2, found {folds!r}")
    # Paths are read by the diagnosis itself, which names a missing file in its own words.
    def items(what: str, value: Any) -> List[Any]:
        if isinstance(value, (str, os.PathLike)):
            return [_hapcal._Measurements.from_path_unchecked(os.fspath(value))]
        if isinstance(value, (list, tuple)):
            return [
                _hapcal._Measurements.from_path_unchecked(os.fspath(v))
                if isinstance(v, (str, os.PathLike))
                else _as_list(what, v)[0]
                for v in value
            ]
        return _as_list(what, value)

    text, warnings = _hapcal._diagnose(
        device,
        items("data", data),
        items("test", test) if test is not None else [],
        None if baseline is None else str(baseline),
        max(int(folds), 0),
        None if sigma_m is None else float(sigma_m),
        None if test_last is None else float(test_last),
        bool(accept_setup),
    )
    return Diagnosis(text, warnings)


class SetupCheck:
    """The result of :func:`check`: what ``hapcal check`` finds in the data before a
    calibration (units, quaternion and Euler order, mirrored or swapped axes, joint column
    order, rows out of step, frozen joints, the tip link, the order of the tips).

    A failing check is a result, not an error: :attr:`exit_code` says what the command line
    exits with, :attr:`error` the message it stops with.
    """

    __slots__ = ("_json", "_report", "_error")

    def __init__(self, text: str, error: Optional[str]) -> None:
        self._json = text
        self._report: Dict[str, Any] = json.loads(text)
        self._error = error

    @property
    def report(self) -> Dict[str, Any]:
        """The check as a dict: exactly what ``hapcal check --json`` prints (``n_rows``,
        ``as_given`` residual, ``n_hypotheses``, ``closest`` hypothesis, ``findings``;
        lengths in m, angles in rad)."""
        return self._report

    def to_json(self) -> str:
        """The check as JSON, byte for byte what ``hapcal check --json`` prints (without the
        final newline)."""
        return self._json

    @property
    def findings(self) -> List[Dict[str, Any]]:
        """What the check found, errors first; each a dict with ``class`` (the kind of
        mistake: ``"length-unit"``, ``"angle-unit"``, ``"joint-order"``, ``"tip-link"``, …),
        ``severity`` (``"error"``: the data show it overwhelmingly; ``"warning"``: worth a
        look), ``message`` (what was found, in words), ``fix`` (the command line's option or
        the edit of the files that applies: ``--length-unit mm`` is ``length_unit="mm"``
        here, ``--tip`` a tip of :meth:`Device.from_urdf`), and the residual ``before`` and,
        read with the fix, ``after`` (``length_rms_m``, ``orientation_rms_rad``). Empty when
        the data fit the robot as they are."""
        return self._report["findings"]

    @property
    def exit_code(self) -> int:
        """What ``hapcal check`` exits with for these data: 0, nothing found or only
        warnings; 2, a mistake the data show overwhelmingly (:attr:`error` names the fix)."""
        return 0 if self._error is None else 2

    @property
    def error(self) -> Optional[str]:
        """The message ``hapcal check`` stops with (``setup check [length-unit]: …; fix:
        …``) when :attr:`exit_code` is 2, else ``None``."""
        return self._error

    def __repr__(self) -> str:
        classes = [f["class"] for f in self.findings]
        return f"SetupCheck(exit_code={self.exit_code}, findings={classes!r})"


def check(
    device: Device,
    data: MeasurementsLike,
    *,
    length_unit: str = "m",
    angle_unit: str = "rad",
    socket_distance_m: float = 0.05,
) -> SetupCheck:
    """Checks the setup of measurement files before calibrating, as ``hapcal check`` does
    (``hapcal_calibrate::setup::check_plan``): fits the frames only (socket folders: the
    scatter of the nominal tip about each socket) under each hypothesis of a mistake and
    compares the residual with the data as given.

    - ``device``: a URDF with its tip link(s) (:meth:`Device.from_urdf`, the command line's
      ``--tip``) or a device file (:meth:`Device.from_toml`).
    - ``data``: measurement files (marker positions, poses, distances), a haptic device's
      logs, or MUKCa socket folders: paths, :class:`Measurements` read with
      :meth:`Measurements.from_csv`, or a list of them. Arrays are not checked (the check
      reads files).
    - ``length_unit`` (``"m"`` or ``"mm"``) / ``angle_unit`` (``"rad"`` or ``"deg"``): how
      the files given as paths are read (the command line's ``--length-unit`` /
      ``--angle-unit``); a :class:`Measurements` keeps its own. Every file of one check is
      read in the same units.
    - ``socket_distance_m``: socket folders: the known distance between a placement's two
      sockets, m.

    Returns a :class:`SetupCheck`; a mistake found is in its ``findings`` and ``exit_code``,
    never raised. The GIL is released while checking. Raises :class:`HapcalError` for input
    the check cannot read (a missing file, a unit it does not know, arrays, data of no kind
    it checks), as ``hapcal check`` exits 2 on bad input.
    """
    if not isinstance(device, Device):
        raise TypeError(f"device: expected hapcal.Device, found {type(device).__name__}")

    def read(value: Any) -> Any:
        if isinstance(value, (str, os.PathLike)):
            return Measurements.from_csv(value, length_unit, angle_unit)
        return value

    one = isinstance(data, (str, os.PathLike, Measurements))
    items = [read(v) for v in ([data] if one else list(data))]
    text, error = _hapcal._check(device, _as_list("data", items), float(socket_distance_m))
    return SetupCheck(text, error)


def import_urdf(
    urdf: PathLike,
    tips: Union[str, Sequence[str]],
    *,
    path: Optional[PathLike] = None,
) -> str:
    """Imports a URDF chain as a hapcal device file, as ``hapcal import-urdf`` does
    (``hapcal_io::import_urdf_tree``, ``hapcal_io::write_device``): the fixed and moving
    joints from the root link to the tip as URDF placements, the joints' limits, and for a
    tree one branch table per further tip.

    - ``urdf``: the URDF file.
    - ``tips``: the tip link (e.g. ``"ball_link"``), or a list of them for a tree.
    - ``path``: also write the device file there (``.toml``; atomically, never over the
      URDF).

    Returns the device file's text (TOML), byte for byte what ``hapcal import-urdf`` prints;
    :meth:`Device.from_toml` reads it back from a file. Raises :class:`HapcalError` for an
    unreadable URDF, an unknown link, or an output path that cannot be written.
    """
    tip_list = [tips] if isinstance(tips, str) else [str(t) for t in tips]
    return _hapcal._import_urdf(os.fspath(urdf), tip_list, _optional_path(path))


class Prediction:
    """The result of :func:`predict`: the calibrated model's tip positions (or poses) at the
    joint readings of a measurement file, each with its 1σ uncertainty and whether the
    readings lie outside the region the calibration was fitted on; with measured columns, the
    errors against them (no refit). What ``hapcal predict`` prints."""

    __slots__ = (
        "lines", "positions", "quaternions", "sigma_m", "sigma_rad", "region_joint",
        "region_past", "errors", "uncertainty", "uncertainty_note", "n_values", "warnings",
        "tips", "frame",
    )

    def __init__(self, raw: Tuple[Any, ...], tips: List[str], frame: str,
                 joint_names: List[str]) -> None:
        lines, poses, sigmas, region, errors, (basis, note, n_values), warnings = raw
        poses = np.asarray(poses, dtype=np.float64).reshape(len(lines), len(tips), 7)
        sig = np.asarray(sigmas, dtype=np.float64).reshape(len(lines), len(tips), 2)
        #: Line of each row in the data file, ``(n,)``.
        self.lines = np.asarray(lines, dtype=np.int64)
        #: Predicted positions, ``(n, n_tips, 3)``, m.
        self.positions = poses[:, :, :3]
        #: Predicted orientations, unit quaternions ``(w, x, y, z)``, ``(n, n_tips, 4)``.
        self.quaternions = poses[:, :, 3:]
        #: 1σ of each position (RMS length of its error), ``(n, n_tips)``, m; NaN without σ.
        self.sigma_m = sig[:, :, 0]
        #: 1σ of each orientation, ``(n, n_tips)``, rad; NaN without σ.
        self.sigma_rad = sig[:, :, 1]
        #: Per row, the joint farthest past its training range, or ``None`` inside the region.
        self.region_joint = [None if j < 0 else joint_names[j] for j, _ in region]
        #: Per row, how far past that joint's range (rad, m for a prismatic joint; positive
        #: above, negative below), NaN inside the region.
        self.region_past = np.asarray([p for _, p in region], dtype=np.float64)
        #: The errors against the measured columns: ``{"position_m": {"count", "mean",
        #: "rms", "max"}, "orientation_rad": …, "distance_m": …}`` (kinds without samples
        #: left out), or ``None`` for a file of joint readings alone.
        self.errors: Optional[Dict[str, Dict[str, float]]] = None
        if errors is not None:
            self.errors = {
                key: {"count": f[0], "mean": f[1], "rms": f[2], "max": f[3]}
                for key, f in zip(("position_m", "orientation_rad", "distance_m"), errors)
                if f is not None
            }
        #: What σ rests on: ``"covariance"``, ``"stds-only"`` (no covariance recorded: the
        #: values' standard deviations, correlations ignored) or ``"none"``.
        self.uncertainty: str = basis
        #: Why there is no σ, or what it leaves out, in words; ``None`` with a covariance.
        self.uncertainty_note: Optional[str] = note
        #: Number of recorded values σ propagates.
        self.n_values: int = n_values
        #: What the reader noticed (columns ignored, readings slightly past a limit).
        self.warnings: List[str] = list(warnings)
        #: The tips, in the order of the second axis.
        self.tips: List[str] = tips
        #: ``"root"`` (tip links in the root link frame) or ``"instrument"`` (markers in the
        #: calibration's instrument frame).
        self.frame: str = frame

    @property
    def outside_region(self) -> np.ndarray:
        """Whether each row lies outside the calibration's region, ``(n,)`` bool."""
        return np.asarray([j is not None for j in self.region_joint], dtype=bool)

    def __repr__(self) -> str:
        return (
            f"Prediction(rows={len(self.lines)}, tips={self.tips!r}, frame={self.frame!r}, "
            f"uncertainty={self.uncertainty!r}, outside_region={int(self.outside_region.sum())})"
        )


def predict(
    device: PathLike,
    tips: Union[str, Sequence[str]],
    data: PathLike,
    *,
    instrument_frame: bool = False,
    length_unit: str = "m",
    angle_unit: str = "rad",
) -> Prediction:
    """The calibrated model's predictions at new joint readings, as ``hapcal predict`` makes
    them (``hapcal_runtime::Predictor``).

    - ``device``: the calibrated URDF ``hapcal calibrate --out robot.urdf`` wrote; its sidecar
      ``robot.calibration.toml`` (values with σ, covariance, region, frames) is read beside it.
    - ``tips``: the tip link, or a list of them for a tree (the calibration's order).
    - ``data``: a measurement file as :func:`calibrate` reads it (CSV with the joints as
      ``q1..qn`` or by name, or industrial_calibration's YAML); measured columns (markers,
      orientations, distances), if present, are compared with the predictions.
    - ``instrument_frame``: predict the markers in the calibration's instrument frame (as the
      instrument measures them) instead of the tip links in the root link frame.
    - ``length_unit`` / ``angle_unit``: how the file is read (``"m"``/``"mm"``,
      ``"rad"``/``"deg"``).

    σ is first-order propagation of the record's covariance, ``√trace(G·Σ·Gᵀ)`` with ``G``
    the central-difference derivative of the position with respect to each recorded value;
    without a covariance the values' standard deviations stand for it
    (:attr:`Prediction.uncertainty` says which). The GIL is released while predicting.
    Raises :class:`HapcalError` for an unreadable robot or file (file:line:column).
    """
    tip_list = [tips] if isinstance(tips, str) else [str(t) for t in tips]
    raw = _hapcal._predict(
        os.fspath(device),
        tip_list,
        os.fspath(data),
        str(length_unit),
        str(angle_unit),
        bool(instrument_frame),
    )
    joint_names = _hapcal.RuntimeRobot(os.fspath(device), tip_list).joint_names
    return Prediction(raw, tip_list, "instrument" if instrument_frame else "root", joint_names)
