"""The code of docs/python.md runs as written (from the repository root): the session,
the Dask and joblib recipes (with a small study), and the Slurm recipe's commands one
after the other; the README's Python section too."""

import os
import re
import subprocess

from conftest import REPO, bench_binary

GUIDE = REPO / "docs" / "python.md"
SMALL = "dict(runs=4, iters=5, particles=20, steps=100)"


def blocks(path, kind):
    """The fenced blocks whose info string is `kind` (e.g. "python", "python dask")."""
    fences = re.finditer(r"```([^\n]*)\n(.*?)```", path.read_text(), re.S)
    return [m.group(2) for m in fences if m.group(1).strip() == kind]


def run_python(code, name):
    exec(compile(code, name, "exec"), {"__name__": "__docs__"})


def test_the_python_session_runs(tmp_path, monkeypatch):
    [session] = blocks(GUIDE, "python")
    monkeypatch.chdir(REPO)
    # the guide saves heat.json in the working directory: keep it out of the checkout
    run_python(session.replace('"heat.json"', repr(str(tmp_path / "heat.json"))),
               "docs/python.md")
    assert (tmp_path / "heat.json").exists()


def test_the_dask_and_joblib_recipes_run_with_a_small_study(monkeypatch):
    monkeypatch.chdir(REPO)
    for kind in ("python dask", "python joblib"):
        [code] = blocks(GUIDE, kind)
        assert "dict(runs=200, iters=1000, particles=50)" in code
        run_python(code.replace("dict(runs=200, iters=1000, particles=50)", SMALL),
                   f"docs/python.md ({kind})")


def test_the_slurm_recipe_s_commands_run_one_after_the_other(tmp_path):
    [array] = blocks(GUIDE, "sh slurm")
    [merge] = blocks(GUIDE, "sh merge")
    env = dict(os.environ, SETTINGS="--runs 4 --iters 5 --particles 20 --steps 100",
               PATH=f"{os.path.dirname(bench_binary())}:{os.environ['PATH']}")
    script = tmp_path / "study.sh"
    script.write_text(array)
    for task in range(4):
        subprocess.run(["bash", str(script)], cwd=tmp_path, check=True,
                       env=dict(env, SLURM_ARRAY_TASK_ID=str(task)))
    subprocess.run(["bash", "-c", merge], cwd=tmp_path, check=True, env=env)
    lines = (tmp_path / "study.jsonl").read_text().splitlines()
    assert len(lines) == 5 and '"nlbench_em_summary"' in lines[-1]


def test_the_readme_installs_the_package_as_the_guide_does():
    readme = (REPO / "README.md").read_text()
    assert 'pip install "./crates/sysid-py[pandas]"' in readme
    assert 'pip install "./crates/sysid-py[pandas]"' in GUIDE.read_text()
    assert (REPO / "crates" / "sysid-py" / "pyproject.toml").exists()


def test_the_readme_python_example_runs(monkeypatch):
    [code] = blocks(REPO / "README.md", "python")
    monkeypatch.chdir(REPO)
    run_python(code, "README.md")
