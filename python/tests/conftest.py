"""Shared helpers of the Python tests: the repository, the CLI binary, the shared data."""

import os
import pathlib
import subprocess

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
SAMPLES = ROOT / "svg-samples"


def cli() -> pathlib.Path:
    """The command-line binary built by `cargo build --release` (python/test.sh builds it)."""
    b = pathlib.Path(os.environ.get("DIFFSVG_BIN", ROOT / "target" / "release" / "diffsvg"))
    if not b.exists():
        pytest.fail(f"{b} not found: run `cargo build --release` first (python/test.sh does)")
    return b


def run_cli(*args, check=True) -> subprocess.CompletedProcess:
    return subprocess.run([str(cli()), *map(str, args)], capture_output=True, text=True,
                          check=check)


def shared_data(test: str):
    """`../shared/data` beside the checkout (or `$DIFFSVG_DATA`): skips with the reason
    when missing, or fails when DIFFSVG_REQUIRE_DATA=1 (as the Rust tests do)."""
    d = pathlib.Path(os.environ.get("DIFFSVG_DATA", ROOT.parent / "shared" / "data"))
    if not d.is_dir():
        reason = f"{d} not found (set DIFFSVG_DATA)"
        if os.environ.get("DIFFSVG_REQUIRE_DATA") == "1":
            pytest.fail(f"{test}: {reason}, and DIFFSVG_REQUIRE_DATA=1 forbids skipping")
        print(f"SKIPPED {test}: {reason}")
        pytest.skip(reason)
    return d
