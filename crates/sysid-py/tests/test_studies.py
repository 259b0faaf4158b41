"""Acceptance 8 and 9: a study's runs spread over Dask workers (two processes) or
joblib reproduce the command line's sharded study (`--shard 0/2`, `--shard 1/2`, merge)
line for line but for the timing fields; chains spread over workers concatenate to one
run's."""

import json
from functools import partial

import pytest

import sysid
from sysid import studies
from conftest import REPO, bench_binary
import subprocess

# a small study: 4 runs of 5 EM iterations with 20 particles on 100 steps
SETTINGS = dict(runs=4, iters=5, particles=20, steps=100, seed=3)
# what changes from one run of the same study to another: the time it took, and the
# label of the shard a line came from
TIMING = {"seconds", "wall_seconds", "threads", "seconds_per_run_median", "shard"}


def without_timing(value):
    if isinstance(value, dict):
        return {k: without_timing(v) for k, v in value.items() if k not in TIMING}
    if isinstance(value, list):
        return [without_timing(v) for v in value]
    return value


@pytest.fixture(scope="module")
def command_line_study(tmp_path_factory):
    """The study as the command line runs it: two shards, merged."""
    dir_ = tmp_path_factory.mktemp("study")
    shards = []
    for shard in ("0/2", "1/2"):
        out = dir_ / f"shard{shard[0]}.jsonl"
        run = subprocess.run([bench_binary(), "nlbench-em", *studies.flags(**SETTINGS),
                              "--shard", shard], capture_output=True, text=True, check=True)
        out.write_text(run.stdout)
        shards.append(out)
    merged = subprocess.run([bench_binary(), "nlbench-em-merge", *map(str, shards)],
                            capture_output=True, text=True, check=True)
    return [json.loads(line) for line in merged.stdout.splitlines()]


def test_runs_one_by_one_give_the_command_line_s_study(command_line_study):
    lines = [studies.nlbench_em_run(r, **SETTINGS) for r in range(SETTINGS["runs"])]
    ours = studies.nlbench_em_merge(lines, "merged from 2 files")
    assert len(ours) == SETTINGS["runs"] + 1
    assert without_timing(ours) == without_timing(command_line_study)


def test_dask_workers_reproduce_the_sharded_study(command_line_study):
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        futures = client.map(partial(studies.nlbench_em_run, **SETTINGS),
                             range(SETTINGS["runs"]))
        lines = client.gather(futures)
        # the workers are separate processes
        assert len(set(client.run(lambda: __import__("os").getpid()).values())) == 2
    ours = studies.nlbench_em_merge(lines)
    assert without_timing(ours) == without_timing(command_line_study)


def test_joblib_over_runs_equals_in_process():
    joblib = pytest.importorskip("joblib")
    spread = joblib.Parallel(n_jobs=2)(
        joblib.delayed(studies.nlbench_em_run)(r, **SETTINGS) for r in range(SETTINGS["runs"]))
    here = [studies.nlbench_em_run(r, **SETTINGS) for r in range(SETTINGS["runs"])]
    assert without_timing(spread) == without_timing(here)


def test_chains_on_two_dask_workers_concatenate_to_one_run(oscillator_record,
                                                           fitted_oscillator):
    distributed = pytest.importorskip("distributed")
    import pandas as pd
    frame = pd.read_csv(oscillator_record)
    model = sysid.ModelFile(fitted_oscillator)
    kw = dict(iterations=100, particles=200, seed=3, strict=False)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        parts = client.gather([client.submit(sysid.pmmh, model, frame, chains=ids, **kw)
                               for ids in ([0, 1], [2, 3])])
    assert sysid.Chains.concat(parts) == sysid.pmmh(model, frame, chains=4, **kw)


def test_a_bad_setting_is_an_option_error():
    with pytest.raises(sysid.OptionError):
        studies.nlbench_em_run(0, runs=4, no_such_setting=1)
    with pytest.raises(sysid.SysidError):
        studies.nlbench_em_run(7, **SETTINGS)
