"""Helpers of the Python package's tests: the repository's data, and the command line
(the release binary, or $SYSID_BIN) to compare with."""

import json
import os
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[3]
DATA = REPO / "crates" / "sysid-cli" / "tests" / "data"
OSCILLATOR = REPO / "examples" / "models" / "oscillator.toml"


def binary():
    return os.environ.get("SYSID_BIN", str(REPO / "target" / "release" / "sysid"))


def bench_binary():
    return os.environ.get("SYSID_BENCH_BIN", str(REPO / "target" / "release" / "sysid-bench"))


def cli(*args, check=True):
    """Runs the command line; its completed process."""
    run = subprocess.run([binary(), *map(str, args)], capture_output=True, text=True)
    if check and run.returncode != 0:
        raise AssertionError(f"sysid {' '.join(map(str, args))} failed: {run.stderr}")
    return run


def cli_json(*args):
    """Runs the command line with --json: its summary."""
    return json.loads(cli(*args, "--json").stdout)


@pytest.fixture(scope="session")
def oscillator_record(tmp_path_factory):
    """150 steps simulated from the guide's oscillator by the command line (seed 5)."""
    path = tmp_path_factory.mktemp("osc") / "osc.csv"
    cli("simulate", "--model", OSCILLATOR, "--steps", 150, "--seed", 5, "--out", path)
    return path


@pytest.fixture(scope="session")
def tour_record(tmp_path_factory):
    """The README tour's record: `sysid simulate lti2x2 --steps 200 --seed 1`."""
    path = tmp_path_factory.mktemp("tour") / "d.csv"
    cli("simulate", "lti2x2", "--steps", 200, "--seed", 1, "--out", path)
    return path


@pytest.fixture(scope="session")
def fitted_oscillator(tmp_path_factory, oscillator_record):
    """The oscillator fitted by the command line (40 robust iterations): the guide's
    start for PMMH."""
    path = tmp_path_factory.mktemp("fitted") / "osc-fit.toml"
    cli("fit", "--model", OSCILLATOR, "--data", oscillator_record, "--max-iter", 40,
        "--out", path)
    return path
