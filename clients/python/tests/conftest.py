"""Shared fixtures of the client's tests: live `curvenet serve` processes on
free loopback ports (started, restarted and killed by the tests), and the
in-process bakes (`curvenet bake`) of the shipped shots to compare with.

Needs the debug binary (`cargo test --workspace` builds it; scripts/test runs
the Rust tests first); CURVENET_BIN overrides its path. Every wait is bounded:
a server that does not print where it listens within 60 s is killed.
"""

from __future__ import annotations

import os
import pathlib
import socket
import subprocess
import threading
import time
import urllib.request
from collections.abc import Iterator

import numpy as np
import pytest
from pxr import Usd

ROOT = pathlib.Path(__file__).resolve().parents[3]
SHOTS = ROOT / "fixtures" / "shots"
HAND_WAVE = SHOTS / "hand_wave" / "shot.usda"
HAND_SKINNED = SHOTS / "hand_skinned" / "shot.usda"
START_TIMEOUT_S = 60


def curvenet_binary() -> pathlib.Path:
    if os.environ.get("CURVENET_BIN"):
        return pathlib.Path(os.environ["CURVENET_BIN"])
    target = pathlib.Path(os.environ.get("CARGO_TARGET_DIR", ROOT / "target"))
    return target / "debug" / "curvenet"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def server_env(**extra: str) -> dict[str, str]:
    """The environment without the caller's CURVENET_* settings."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("CURVENET_")}
    env.update(extra)
    return env


class Server:
    """One `curvenet serve` process on 127.0.0.1."""

    def __init__(self, args: list[str], port: int = 0, env: dict[str, str] | None = None) -> None:
        self.args = args
        self.env = env if env is not None else server_env()
        self.port = port
        self.proc: subprocess.Popen[str] | None = None
        self.url = ""
        self.start()

    def start(self) -> None:
        binary = curvenet_binary()
        assert binary.exists(), f"{binary} is missing: build it (cargo build --ignore-rust-version) or set CURVENET_BIN"
        deadline = time.monotonic() + START_TIMEOUT_S
        while True:  # a port just freed may briefly refuse to bind again: bounded retries
            proc = subprocess.Popen(
                [str(binary), "serve", "--addr", f"127.0.0.1:{self.port}", "--drain-timeout", "5", *self.args],
                stdout=subprocess.PIPE,
                stderr=subprocess.DEVNULL,
                text=True,
                env=self.env,
            )
            timer = threading.Timer(START_TIMEOUT_S, proc.kill)
            timer.start()
            assert proc.stdout is not None
            line = proc.stdout.readline()
            timer.cancel()
            if line.startswith("listening on http://"):
                break
            proc.kill()
            proc.wait()
            assert time.monotonic() < deadline, f"the server did not start: first line {line!r}"
            time.sleep(0.2)
        self.proc = proc
        self.url = line.split("listening on ")[1].strip()
        self.port = int(self.url.rsplit(":", 1)[1])

    def kill(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(timeout=30)
        self.proc = None

    def restart(self) -> None:
        """Kills the process and starts a new one on the same port (an empty cache)."""
        self.kill()
        self.start()

    def metrics(self) -> str:
        req = urllib.request.Request(f"{self.url}/metrics")
        token = self.env.get("CURVENET_TOKEN")
        if token:
            req.add_header("Authorization", f"Bearer {token}")
        with urllib.request.urlopen(req, timeout=30) as r:
            return str(r.read().decode())

    def metric(self, name: str, **labels: str) -> float:
        """The sum of a Prometheus counter or gauge over the series matching `labels`."""
        total = 0.0
        for line in self.metrics().splitlines():
            if not line.startswith(name) or line.startswith("#"):
                continue
            key, value = line.rsplit(" ", 1)
            series, _, rest = key.partition("{")
            if series != name:
                continue
            if all(f'{k}="{v}"' in rest for k, v in labels.items()):
                total += float(value)
        return total


@pytest.fixture
def start_server() -> Iterator[object]:
    """A factory: start_server(*args, port=0, env=None) -> Server; all killed at the end."""
    started: list[Server] = []

    def start(*args: str, port: int = 0, env: dict[str, str] | None = None) -> Server:
        s = Server(list(args), port, env)
        started.append(s)
        return s

    yield start
    for s in started:
        s.kill()


@pytest.fixture(scope="module")
def server() -> Iterator[Server]:
    """A plain server shared by a test module."""
    s = Server([])
    yield s
    s.kill()


def run_bake(stage: pathlib.Path, out: pathlib.Path, *extra: str) -> None:
    r = subprocess.run(
        [str(curvenet_binary()), "bake", str(stage), "--out", str(out), "--quiet", *extra],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=ROOT,
    )
    assert r.returncode == 0, f"curvenet bake failed ({r.returncode}): {r.stderr}"


def read_baked_points(layer: pathlib.Path, mesh: str = "/Hand/Mesh") -> dict[float, np.ndarray]:
    """The `points` samples of a bake layer, read with usd-core."""
    lay = Usd.Stage.Open(str(layer))
    attr = lay.GetPrimAtPath(mesh).GetAttribute("points")
    return {float(t): np.asarray(attr.Get(t), dtype=np.float32) for t in attr.GetTimeSamples()}


@pytest.fixture(scope="session")
def baked(tmp_path_factory: pytest.TempPathFactory) -> dict[str, dict[float, np.ndarray]]:
    """`curvenet bake` (in process, no service) of both shipped shots: {shot: {time: points}}."""
    d = tmp_path_factory.mktemp("bakes")
    out = {}
    for name, stage in (("hand_wave", HAND_WAVE), ("hand_skinned", HAND_SKINNED)):
        layer = d / f"{name}.usdc"
        run_bake(stage, layer)
        out[name] = read_baked_points(layer)
    return out
