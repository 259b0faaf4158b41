"""Monte Carlo studies run by parts, on any engine.

A run of a study depends only on the study's settings and its index, so runs spread
over processes or machines in any way give exactly the study's lines.
``nlbench_em_run(r, **settings)`` is run ``r`` of the seed-000 particle-EM study (the
``sysid-bench nlbench-em`` runner: the same settings, spelled as keywords:
``runs=``, ``iters=``, ``particles=``, ``steps=``, ``smoother=``, ``seed=``,
``method=``, ...); ``nlbench_em_merge(lines)`` orders the run lines and appends the
study's summary, as ``sysid-bench nlbench-em-merge`` does for shards.

With Dask (docs/python.md)::

    from functools import partial
    from dask.distributed import Client, LocalCluster
    from sysid import studies
    settings = dict(runs=200, iters=1000, particles=50)
    with Client(LocalCluster(n_workers=2)) as client:
        futures = client.map(partial(studies.nlbench_em_run, **settings),
                             range(settings["runs"]))
        lines = studies.nlbench_em_merge(client.gather(futures))
"""

import json

from . import _sysid
from ._errors import OptionError

__all__ = ["flags", "nlbench_em_merge", "nlbench_em_run"]


def flags(**settings):
    """Keyword settings as the runner's flags: ``iters=5`` -> ``--iters 5``, a true
    boolean -> the bare flag (``at_truth=True`` -> ``--at-truth``)."""
    out = []
    for key, value in settings.items():
        flag = "--" + key.replace("_", "-")
        if value is True:
            out.append(flag)
        elif value is False or value is None:
            continue
        else:
            out += [flag, str(value)]
    return out


def nlbench_em_run(run, threads=None, **settings):
    """Run ``run`` (0-based) of the nlbench particle-EM study: its line, as a dict."""
    if isinstance(run, bool) or not isinstance(run, int) or run < 0:
        raise OptionError(f"run: expected a run index, got {run!r}", "run")
    return json.loads(_sysid.nlbench_em_run(flags(**settings), run, threads))


def nlbench_em_merge(lines, label="merged"):
    """The run lines among ``lines`` (dicts), each once and in run order, then the
    study's summary (its ``params.shard`` set to ``label``)."""
    texts = [line if isinstance(line, str) else json.dumps(line) for line in lines]
    return [json.loads(t) for t in _sysid.nlbench_em_merge(texts, label)]
