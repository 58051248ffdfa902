"""The documentation's code, run as written against a live server from the
repository root with CURVENET_URL set:

- the Python block of server/README.md (between its `python-client` markers),
  whose results are then checked: the neutral pose reproduces the mesh, a
  rotated pool rotates it, and the batch equals the in-process bake;
- every Python block of clients/python/README.md, in order, in one namespace;
- its shell block (bake-remote), with `python` the test's interpreter.

Also: the wheel pip builds from clients/python (metadata, py.typed).
"""

from __future__ import annotations

import os
import pathlib
import re
import shutil
import subprocess
import sys
import tomllib
import zipfile

import numpy as np
import pytest
from conftest import ROOT, curvenet_binary

import curvenet_client

SERVER_README = ROOT / "server" / "README.md"
CLIENT_README = ROOT / "clients" / "python" / "README.md"


def blocks(text: str, lang: str) -> list[str]:
    return re.findall(rf"```{lang}\n(.*?)```", text, flags=re.S)


@pytest.fixture
def in_repo(server, monkeypatch):
    monkeypatch.chdir(ROOT)
    monkeypatch.setenv("CURVENET_URL", server.url)
    monkeypatch.delenv("CURVENET_TOKEN", raising=False)
    return server


def test_server_readme_block(in_repo, baked, capsys) -> None:
    text = SERVER_README.read_text()
    section = text.split("<!-- python-client: begin -->")[1].split("<!-- python-client: end -->")[0]
    (code,) = blocks(section, "python")
    namespace: dict = {}
    exec(compile(code, str(SERVER_README), "exec"), namespace)
    mesh = namespace["shot"].request.projection_points
    assert namespace["neutral"].shape == (1400, 3) and np.abs(namespace["neutral"] - mesh).max() <= 1e-5
    c, s = np.cos(0.3), np.sin(0.3)
    r = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    assert np.abs(namespace["turned"] - mesh @ r.T).max() <= 1e-4  # a rigid pose moves the mesh rigidly
    assert all(np.array_equal(p, baked["hand_wave"][float(t)]) for t, p in zip(range(1, 25), namespace["baked"]))
    assert len(capsys.readouterr().out.splitlines()) == 24


def test_client_readme_blocks(in_repo, tmp_path, capsys) -> None:
    text = CLIENT_README.read_text()
    python = blocks(text, "python")
    assert python, "the README has Python blocks"
    namespace: dict = {}
    for code in python:
        exec(compile(code, str(CLIENT_README), "exec"), namespace)
    assert namespace["points"].shape == (1400, 3) and namespace["gradients"].shape == (1400, 3, 3)
    assert len(namespace["shot_points"]) == 24 and len(namespace["still"]) == 2
    assert namespace["binding"].id in capsys.readouterr().out

    shell = [b for b in blocks(text, "sh") if b.startswith("python -m curvenet_client")]
    assert len(shell) == 1
    script = shell[0]
    if os.environ.get("CURVENET_BIN"):
        script = script.replace("target/debug/curvenet", str(curvenet_binary()))
    (ROOT / "target").mkdir(exist_ok=True)
    outputs = [ROOT / "target" / "hand_wave.remote.usda", ROOT / "target" / "hand_wave.remote.usdc"]
    for o in outputs:
        o.unlink(missing_ok=True)
    env = dict(os.environ, PATH=f"{pathlib.Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}")
    r = subprocess.run(["bash", "-euo", "pipefail", "-c", script], cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    assert all(o.stat().st_size > 0 for o in outputs)
    for o in outputs:
        o.unlink()


def test_the_package_builds_as_documented(tmp_path) -> None:
    """`pip install ./clients/python` builds this wheel: numpy its only
    requirement, usd-core the `usd` extra, py.typed and the modules inside."""
    project = tomllib.loads((ROOT / "clients" / "python" / "pyproject.toml").read_text())["project"]
    assert project["version"] == curvenet_client.__version__
    # Built from a copy: setuptools leaves build/ in the tree it builds.
    source = tmp_path / "src"
    shutil.copytree(ROOT / "clients" / "python", source, ignore=shutil.ignore_patterns(
        "build", "*.egg-info", "__pycache__", ".mypy_cache", "tests"))
    r = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "--quiet", "-w", str(tmp_path),
         str(source)],
        capture_output=True, text=True, timeout=300,
    )
    assert r.returncode == 0, r.stderr
    (wheel,) = tmp_path.glob("curvenet_client-*.whl")
    assert wheel.name.startswith(f"curvenet_client-{curvenet_client.__version__}-py3-none-any")
    with zipfile.ZipFile(wheel) as z:
        names = set(z.namelist())
        meta = z.read(f"curvenet_client-{curvenet_client.__version__}.dist-info/METADATA").decode()
    for module in ("__init__", "__main__", "client", "errors", "frames", "request", "usd"):
        assert f"curvenet_client/{module}.py" in names
    assert "curvenet_client/py.typed" in names
    requires = [line for line in meta.splitlines() if line.startswith("Requires-Dist:")]
    assert requires[0] == "Requires-Dist: numpy>=1.24"
    assert requires[1:] == ['Requires-Dist: usd-core>=24.11; extra == "usd"']
