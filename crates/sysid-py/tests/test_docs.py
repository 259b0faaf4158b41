"""The Python session of docs/python.md runs as written (from the repository root),
and the README's Python section names the install command the docs give."""

import os
import re

from conftest import REPO


def python_blocks(path):
    return re.findall(r"```python\n(.*?)```", path.read_text(), flags=re.S)


def test_the_python_guide_runs(tmp_path, monkeypatch):
    blocks = python_blocks(REPO / "docs" / "python.md")
    assert len(blocks) == 1
    monkeypatch.chdir(REPO)
    # the guide saves heat.json in the working directory: keep it out of the checkout
    script = blocks[0].replace('"heat.json"', repr(str(tmp_path / "heat.json")))
    exec(compile(script, "docs/python.md", "exec"), {"__name__": "__docs__"})
    assert (tmp_path / "heat.json").exists()


def test_the_readme_installs_the_package_as_the_guide_does():
    readme = (REPO / "README.md").read_text()
    assert "pip install ./crates/sysid-py" in readme
    assert os.path.exists(REPO / "crates" / "sysid-py" / "pyproject.toml")


def test_the_readme_python_example_runs(monkeypatch):
    blocks = python_blocks(REPO / "README.md")
    assert len(blocks) == 1
    monkeypatch.chdir(REPO)
    exec(compile(blocks[0], "README.md", "exec"), {"__name__": "__readme__"})
