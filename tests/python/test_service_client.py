"""The numpy client of server/README.md, run as written against a live
`curvenet serve` on a free loopback port: the hand_1k4 fixture read with
usd-core, bound, and deformed in the binary form.

Needs the debug binary (`cargo test --workspace` builds it; scripts/test
runs the Rust tests first). CURVENET_BIN overrides its path."""

import json
import os
import pathlib
import signal
import subprocess
import threading
import urllib.request

import numpy as np
import pytest
from pxr import Usd, UsdGeom

ROOT = pathlib.Path(__file__).resolve().parents[2]
README = ROOT / "server" / "README.md"
STAGE = ROOT / "fixtures" / "hand" / "hand_1k4.usda"


def _binary():
    if os.environ.get("CURVENET_BIN"):
        return pathlib.Path(os.environ["CURVENET_BIN"])
    target = pathlib.Path(os.environ.get("CARGO_TARGET_DIR", ROOT / "target"))
    return target / "debug" / "curvenet"


def _snippet():
    """The README's numpy client, exactly as written there."""
    text = README.read_text()
    block = text.split("<!-- numpy-client: begin -->")[1].split("<!-- numpy-client: end -->")[0]
    code = block.split("```python\n")[1].split("```")[0]
    namespace = {}
    exec(compile(code, str(README), "exec"), namespace)
    return namespace


@pytest.fixture(scope="module")
def server():
    binary = _binary()
    assert binary.exists(), f"{binary} is missing: build it first (cargo build --ignore-rust-version) or set CURVENET_BIN"
    env = {k: v for k, v in os.environ.items() if not k.startswith("CURVENET_")}
    proc = subprocess.Popen(
        [str(binary), "serve", "--addr", "127.0.0.1:0", "--drain-timeout", "10"],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
        env=env,
    )
    timer = threading.Timer(60, proc.kill)  # a server that never says where it listens
    timer.start()
    line = proc.stdout.readline()
    timer.cancel()
    assert line.startswith("listening on http://"), f"unexpected first line {line!r}"
    url = line.split("listening on ")[1].strip()
    yield url, proc
    if proc.poll() is None:
        proc.kill()
        proc.wait()


def _mesh_points():
    stage = Usd.Stage.Open(str(STAGE))
    mesh = next(p for p in stage.Traverse() if p.IsA(UsdGeom.Mesh) and p.GetRelationship("curvenet:curvenets").GetTargets())
    return np.asarray(mesh.GetAttribute("points").Get(), dtype=np.float64)


def _rotation(deg):
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def test_readme_numpy_client_against_a_live_server(server):
    url, _ = server
    client = _snippet()
    binding = client["binding_request"](STAGE)
    answer = client["post_binding"](url, binding)
    binding_id = answer["binding_id"]
    assert len(binding_id) == 64 and not answer["cached"]
    assert answer["vertices"] == len(binding["projection_points"])
    assert client["post_binding"](url, binding)["cached"]

    mesh = _mesh_points()
    pool = np.asarray(binding["curvenets"][0]["pool"])

    # The neutral pose (not articulated) reproduces the input mesh.
    neutral = client["deform_frame"](url, binding_id, [None])
    assert neutral.dtype == np.float32 and neutral.shape == mesh.shape
    assert np.abs(neutral - mesh).max() <= 1e-5

    # The neutral pool sent explicitly: the same.
    posed = client["deform_frame"](url, binding_id, [pool])
    assert np.abs(posed - mesh).max() <= 1e-5

    # A rigid motion of the pool moves the mesh rigidly.
    r, t = _rotation(30.0), np.array([0.05, -0.02, 0.1])
    moved = client["deform_frame"](url, binding_id, [pool @ r.T + t])
    assert np.abs(moved - (mesh @ r.T + t)).max() <= 1e-4

    # Once the server lost the binding, `deform` posts it again (same id).
    req = urllib.request.Request(f"{url}/v1/bindings/{binding_id}", method="DELETE")
    with urllib.request.urlopen(req) as resp:
        assert resp.status == 204
    again, again_id = client["deform"](url, binding, binding_id, [pool @ r.T + t])
    assert again_id == binding_id
    assert np.abs(again - moved).max() <= 1e-6


def test_metrics_and_openapi_are_served(server):
    url, _ = server
    with urllib.request.urlopen(f"{url}/openapi.json") as resp:
        doc = json.loads(resp.read())
    assert doc["openapi"].startswith("3.1")
    assert "/v1/bindings/{id}/frames" in doc["paths"]
    with urllib.request.urlopen(f"{url}/metrics") as resp:
        text = resp.read().decode()
    assert "curvenet_cache_hits_total" in text


def test_sigterm_stops_the_server_cleanly(server):
    _, proc = server
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(timeout=15) == 0
