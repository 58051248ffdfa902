"""A live `curvenet serve` on a free loopback port: its metrics and OpenAPI
description, and a clean stop on SIGTERM. (The Python client of
server/README.md is tested with the client package, clients/python/tests.)

Needs the debug binary (`cargo test --workspace` builds it; scripts/test
runs the Rust tests first). CURVENET_BIN overrides its path."""

import json
import os
import pathlib
import signal
import subprocess
import threading
import urllib.request

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]


def _binary():
    if os.environ.get("CURVENET_BIN"):
        return pathlib.Path(os.environ["CURVENET_BIN"])
    target = pathlib.Path(os.environ.get("CARGO_TARGET_DIR", ROOT / "target"))
    return target / "debug" / "curvenet"


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
