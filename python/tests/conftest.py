"""Shared helpers of the hapcal Python tests: the repository's fixtures and the CLI's report."""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
from pathlib import Path
from typing import Any, Iterable, List

import pytest

ROOT = Path(__file__).resolve().parents[2]
UR10_URDF = "fixtures/figaroh/ur10/ur10_robot.urdf"
UR10_TIP = "wrist_3_link"
UR10_CSV = "fixtures/figaroh/ur10/calibration.csv"
POSITIONER = "fixtures/industrial-calibration/two_axis_positioner.toml"
POSITIONER_YAML = "fixtures/industrial-calibration/measurements.yaml"


@pytest.fixture(autouse=True)
def _at_root(monkeypatch: pytest.MonkeyPatch) -> None:
    """Run every test from the repository root, so that paths in reports read as the CLI's."""
    monkeypatch.chdir(ROOT)


def _cli_command() -> List[str]:
    """`$HAPCAL_BIN`, else `cargo run --release -q -p hapcal --` (builds it when needed)."""
    exe = os.environ.get("HAPCAL_BIN")
    if exe:
        return [exe]
    if shutil.which("cargo") is None:
        pytest.skip("neither HAPCAL_BIN nor cargo: cannot run the hapcal CLI")
    return ["cargo", "run", "--release", "-q", "-p", "hapcal", "--"]


def cli_json(*args: str) -> str:
    """stdout of `hapcal calibrate ARGS --json`, run from the repository root."""
    out = subprocess.run(
        _cli_command() + ["calibrate", *args, "--json"],
        cwd=ROOT,
        check=True,
        capture_output=True,
        text=True,
    )
    return out.stdout


def cli(*args: str) -> str:
    """stdout of `hapcal ARGS`, run from the repository root."""
    out = subprocess.run(
        _cli_command() + list(args), cwd=ROOT, check=True, capture_output=True, text=True
    )
    return out.stdout


def assert_close(a: Any, b: Any, tol: float = 1e-12, ignore: Iterable[str] = (),
                 strings: bool = True, path: str = "$") -> None:
    """`a == b` as JSON trees, numbers to `tol` (relative, absolute below 1), skipping keys in
    `ignore`; strings compared only with `strings`."""
    ignore = set(ignore)
    if isinstance(a, dict):
        assert isinstance(b, dict), f"{path}: {type(b).__name__} is not an object"
        ka = {k for k in a if k not in ignore}
        kb = {k for k in b if k not in ignore}
        assert ka == kb, f"{path}: keys differ: {sorted(ka ^ kb)}"
        for k in sorted(ka):
            assert_close(a[k], b[k], tol, ignore, strings, f"{path}.{k}")
    elif isinstance(a, list):
        assert isinstance(b, list) and len(a) == len(b), f"{path}: lengths differ: {a!r} vs {b!r}"
        for i, (x, y) in enumerate(zip(a, b)):
            assert_close(x, y, tol, ignore, strings, f"{path}[{i}]")
    elif isinstance(a, bool) or a is None:
        assert a == b, f"{path}: {a!r} != {b!r}"
    elif isinstance(a, (int, float)):
        assert isinstance(b, (int, float)) and not isinstance(b, bool), f"{path}: {b!r}"
        assert math.isclose(a, b, rel_tol=tol, abs_tol=tol), f"{path}: {a!r} != {b!r}"
    elif strings:
        assert a == b, f"{path}: {a!r} != {b!r}"


def without_elapsed(text: str) -> str:
    """The report's JSON text without its `elapsed_s` line (wall time)."""
    return "\n".join(l for l in text.strip().splitlines() if '"elapsed_s"' not in l)


def report_of(text: str) -> Any:
    return json.loads(text)
