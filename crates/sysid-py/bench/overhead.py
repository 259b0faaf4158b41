"""The Python call's overhead over the library call (issue 46, acceptance 13):
`particle_filter` at M = 1000, T = 1000 (the guide's oscillator, repeats=0) and
`fit_lti` on the README tour's record (order 8, max_iter 10000).

Each call reports the time its library call took on the worker thread (`seconds` in
its raw result); the rest of the call's wall time is the Python face's overhead (data
in, the worker thread, the GIL, results out). Paired call by call, so that the
machine's load, which moves both, cancels. Medians as JSON lines.

    cargo build --release -p sysid-cli     # (the records are simulated by the CLI)
    python crates/sysid-py/bench/overhead.py [--reps 31]
"""

import argparse
import json
import statistics
import subprocess
import tempfile
import time
import warnings
from pathlib import Path

import pandas as pd

import sysid
from sysid import _sysid

REPO = Path(__file__).resolve().parents[3]
MODEL = REPO / "examples" / "models" / "oscillator.toml"


def paired(reps, call):
    """(wall ms, library ms) of `reps` calls; `call` returns the library's seconds."""
    pairs = []
    for _ in range(reps):
        start = time.perf_counter()
        library = call()
        pairs.append(((time.perf_counter() - start) * 1e3, library * 1e3))
    return pairs


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--reps", type=int, default=31)
    args = parser.parse_args()
    tmp = Path(tempfile.mkdtemp())
    osc, tour = tmp / "osc.csv", tmp / "tour.csv"
    cli = str(REPO / "target" / "release" / "sysid")
    for what, out in ((["--model", str(MODEL), "--steps", "1000", "--seed", "5"], osc),
                      (["lti2x2", "--steps", "200", "--seed", "1"], tour)):
        subprocess.run([cli, "simulate", *what, "--out", str(out)], check=True,
                       capture_output=True)
    model, osc_frame, tour_frame = sysid.ModelFile(MODEL), pd.read_csv(osc), pd.read_csv(tour)
    warnings.simplefilter("ignore")
    # the public functions, whose raw results carry the library's time
    calls = {
        "particle_filter": lambda: _raw_seconds(
            lambda: sysid.particle_filter(model, osc_frame, particles=1000, repeats=0)),
        "fit_lti": lambda: _raw_seconds(
            lambda: sysid.fit_lti(tour_frame, order=8, max_iter=10000)),
    }
    for name, call in calls.items():
        pairs = paired(args.reps, call)
        wall = statistics.median(w for w, _ in pairs)
        library = statistics.median(l for _, l in pairs)
        overhead = statistics.median(100 * (w / l - 1) for w, l in pairs)
        print(json.dumps({"task": name, "reps": args.reps, "wall_ms_median": wall,
                          "library_ms_median": library,
                          "overhead_percent_median": overhead,
                          "overhead_ms_median": statistics.median(w - l for w, l in pairs)}))


def _raw_seconds(call):
    return call()._raw["seconds"]


if __name__ == "__main__":
    main()
