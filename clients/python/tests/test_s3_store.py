"""The binding store's S3 backend (`--store s3://bucket/prefix`) against a
real S3-compatible server: moto's standalone server (`python -m moto.server`,
pinned in requirements-dev.txt), started here on a free loopback port and
stopped at the end. curvenet reaches it through the standard AWS_* variables
(AWS_ENDPOINT_URL, AWS_ALLOW_HTTP=true, test credentials); boto3 makes a
bucket per test and reads, lists and corrupts the objects.

a. two `serve` replicas on one prefix: a binding posted to A is answered by
   B (GET and frames, never posted to B), the same points bit for bit; the
   object `<prefix>/<id>.cnb` is in the bucket and B's store metrics count
   the hit;
b. a stored object corrupted (bytes flipped in the middle) or truncated is
   refused by a fresh replica: the id is unknown_binding there, the object
   is deleted, `curvenet_store_rejected_total` counts it, and the client's
   re-post rebuilds the binding, whose frames equal the original ones;
c. `curvenet bake --store s3://...` twice: the first builds and writes the
   binding object, the second loads it; both layers are byte-identical to a
   bake without a store.

Every run also checks that moto answered none of curvenet's requests with an
error other than 404 (a request this S3 implementation refuses). Skipped only
when moto cannot be imported: the project's requirements install it, so CI
runs these tests.
"""

from __future__ import annotations

import os
import pathlib
import re
import subprocess
import sys
import time
import urllib.error
import urllib.request
import uuid
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest
from conftest import HAND_WAVE, ROOT, curvenet_binary, free_port, server_env
from test_deform import shot_frames

from curvenet_client import Binding, Client, UnknownBindingError

pytest.importorskip(
    "moto.server", reason="moto's S3 server cannot be imported: install moto[server] (clients/python/requirements-dev.txt)"
)
import boto3  # noqa: E402 - a dependency of moto: importable whenever moto is

ACCESS = {
    "AWS_ACCESS_KEY_ID": "testing",
    "AWS_SECRET_ACCESS_KEY": "testing",
    "AWS_REGION": "us-east-1",
}
START_TIMEOUT_S = 60
BLOB = re.compile(r"[0-9a-f]{64}\.cnb")
# moto's request log: `"PUT /bucket/key HTTP/1.1" 200 -`.
LOGGED = re.compile(r'"(?P<method>[A-Z]+) (?P<path>\S+) HTTP/[\d.]+" (?P<status>\d{3})')
ANSI = re.compile(r"\x1b\[[0-9;]*m")  # werkzeug colours the error lines


class Moto:
    """One `python -m moto.server` process on 127.0.0.1, its request log in a file."""

    def __init__(self, log: pathlib.Path) -> None:
        self.log_path = log
        deadline = time.monotonic() + START_TIMEOUT_S
        while True:  # the free port may be taken before moto binds it: bounded retries
            self.port = free_port()
            self.url = f"http://127.0.0.1:{self.port}"
            self.log = open(log, "w")  # noqa: SIM115 - closed in stop()
            self.proc = subprocess.Popen(
                [sys.executable, "-m", "moto.server", "-H", "127.0.0.1", "-p", str(self.port)],
                stdout=self.log,
                stderr=subprocess.STDOUT,
                stdin=subprocess.DEVNULL,
                env={k: v for k, v in os.environ.items() if not k.startswith(("AWS_", "MOTO_"))} | {"PYTHONUNBUFFERED": "1"},
            )
            while self.proc.poll() is None and not self.answers() and time.monotonic() < deadline:
                time.sleep(0.1)
            if self.proc.poll() is None and self.answers():
                break
            self.stop()
            assert time.monotonic() < deadline, f"moto did not start within {START_TIMEOUT_S} s: {self.log_text()[-2000:]}"
        self.s3 = boto3.client("s3", endpoint_url=self.url, region_name=ACCESS["AWS_REGION"],
                               aws_access_key_id=ACCESS["AWS_ACCESS_KEY_ID"],
                               aws_secret_access_key=ACCESS["AWS_SECRET_ACCESS_KEY"])  # fmt: skip

    def answers(self) -> bool:
        try:
            with urllib.request.urlopen(f"{self.url}/moto-api/data.json", timeout=2) as r:
                return bool(r.status == 200)
        except (urllib.error.URLError, OSError):
            return False

    def log_text(self) -> str:
        self.log.flush()
        return self.log_path.read_text(errors="replace")

    def refused(self) -> list[str]:
        """Requests moto answered with an error other than 404 (a missing object or marker)."""
        out = []
        for line in self.log_text().splitlines():
            m = LOGGED.search(ANSI.sub("", line))
            if m and int(m["status"]) >= 400 and m["status"] != "404":
                out.append(ANSI.sub("", line).strip())
        return out

    def env(self, **extra: str) -> dict[str, str]:
        """curvenet's environment for this server: no inherited AWS_* or CURVENET_* setting."""
        env = {k: v for k, v in server_env().items() if not k.startswith("AWS_")}
        env.update(ACCESS, AWS_ENDPOINT_URL=self.url, AWS_ALLOW_HTTP="true", **extra)
        return env

    def bucket(self) -> str:
        name = f"curvenet-{uuid.uuid4().hex[:12]}"
        self.s3.create_bucket(Bucket=name)
        return name

    def keys(self, bucket: str, prefix: str) -> dict[str, int]:
        """{key: size} of the objects under `prefix/`."""
        listed = self.s3.list_objects_v2(Bucket=bucket, Prefix=f"{prefix}/")
        return {o["Key"]: int(o["Size"]) for o in listed.get("Contents", [])}

    def get(self, bucket: str, key: str) -> bytes:
        return bytes(self.s3.get_object(Bucket=bucket, Key=key)["Body"].read())

    def put(self, bucket: str, key: str, body: bytes) -> None:
        self.s3.put_object(Bucket=bucket, Key=key, Body=body)

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=10)
        self.log.close()


@pytest.fixture(scope="module")
def moto(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Moto]:
    m = Moto(tmp_path_factory.mktemp("moto") / "moto.log")
    yield m
    m.stop()


@pytest.fixture(autouse=True)
def no_refused_requests(moto: Moto) -> Iterator[None]:
    """After each test: moto refused none of the requests it was sent."""
    before = len(moto.refused())
    yield
    refused = moto.refused()[before:]
    assert not refused, f"moto refused requests: {refused}"


def reference(url: str, mesh: Any, frames: list[Any]) -> tuple[str, list[np.ndarray]]:
    """Binds `mesh` on `url` through the client and deforms `frames`: (id, points per frame)."""
    with Client(url) as c:
        b = c.bind(mesh.request)
        points = [b.deform(f.posed, f.rest, f.blend_shape_weights) for f in frames]
    assert len({p.tobytes() for p in points}) > 1, "the frames do not move: the comparison is of one pose"
    return b.id, points


def unposted(client: Client, mesh: Any, binding_id: str) -> Binding:
    """A Binding for an id the server has (found by GET, never posted through
    this client); with `rebinds=0` a frame that meets unknown_binding raises."""
    return Binding(client, mesh.request, mesh.request.to_bytes(), client.get_binding(binding_id))


def deform_all(b: Binding, frames: list[Any]) -> list[np.ndarray]:
    return [b.deform(f.posed, f.rest, f.blend_shape_weights) for f in frames]


# ------------------------------------------------------- a. two replicas


def test_a_binding_posted_to_one_replica_is_served_by_another_through_s3(start_server, moto: Moto) -> None:
    mesh, times, frames = shot_frames("hand_wave")
    bucket = moto.bucket()
    store = f"s3://{bucket}/some/prefix"
    a = start_server("--store", store, env=moto.env())
    b = start_server("--store", store, env=moto.env())
    binding_id, expected = reference(a.url, mesh, frames)
    assert len(binding_id) == 64
    # The answer came once the object was written: it is there, and only it
    # (no recency marker yet: nobody has read it).
    keys = moto.keys(bucket, "some/prefix")
    blob = f"some/prefix/{binding_id}.cnb"
    assert list(keys) == [blob], keys
    assert moto.get(bucket, blob)[:8] == b"CNENTRY\0"

    with Client(b.url, rebinds=0) as cb:
        info = cb.get_binding(binding_id)  # loaded from the bucket
        assert info["binding_id"] == binding_id and info["vertices"] == 1400
        on_b = unposted(cb, mesh, binding_id)
        points = deform_all(on_b, frames)
        assert cb.stats["rebinds"] == 0
    for t, p, e in zip(times, points, expected):
        assert p.dtype == np.float32 and p.shape == (1400, 3)
        assert np.array_equal(p, e), f"frame {t}: B differs from A (max |diff| {np.abs(p - e).max()})"
    assert b.metric("curvenet_bindings_computed_total") == 0  # B never built it
    assert b.metric("curvenet_store_hits_total") >= 1
    assert b.metric("curvenet_store_read_bytes_total") >= keys[blob]
    assert b.metric("curvenet_store_rejected_total") == 0
    assert b.metric("curvenet_store_errors_total") == 0
    assert a.metric("curvenet_bindings_computed_total") == 1
    assert a.metric("curvenet_store_written_total") == 1
    assert a.metric("curvenet_store_written_bytes_total") == keys[blob]
    assert a.metric("curvenet_store_errors_total") == 0
    # B's hit wrote the entry's recency marker beside it.
    assert sorted(moto.keys(bucket, "some/prefix")) == [blob, f"some/prefix/{binding_id}.used"]


# ----------------------------------------------------- b. corrupted objects


def flipped(blob: bytes) -> bytes:
    """The same bytes with 8 flipped in the middle (inside the deformer, past
    the envelope's header and meta: core's own checksum must catch it)."""
    mid = len(blob) // 2
    assert mid > 64 + int.from_bytes(blob[48:52], "little"), "the middle is not in the deformer"
    return blob[:mid] + bytes(x ^ 0xFF for x in blob[mid : mid + 8]) + blob[mid + 8 :]


def truncated(blob: bytes) -> bytes:
    return blob[: len(blob) * 3 // 4]


@pytest.mark.parametrize("corrupt", [flipped, truncated], ids=["flipped", "truncated"])
def test_b_a_corrupted_object_is_refused_and_rebuilt(start_server, moto: Moto, corrupt) -> None:
    mesh, times, frames = shot_frames("hand_wave")
    bucket = moto.bucket()
    store = f"s3://{bucket}/bindings"
    a = start_server("--store", store, env=moto.env())
    binding_id, expected = reference(a.url, mesh, frames)
    a.kill()
    blob = f"bindings/{binding_id}.cnb"
    good = moto.get(bucket, blob)
    bad = corrupt(good)
    assert bad != good
    moto.put(bucket, blob, bad)
    assert moto.get(bucket, blob) == bad

    fresh = start_server("--store", store, env=moto.env())
    with Client(fresh.url, rebinds=0) as strict:
        with pytest.raises(UnknownBindingError) as e:
            strict.get_binding(binding_id)
        assert e.value.code == "unknown_binding" and e.value.status == 404
        assert fresh.metric("curvenet_store_rejected_total") == 1
        # The refused object was deleted: the frame by id finds nothing either.
        assert blob not in moto.keys(bucket, "bindings")
        on_fresh = Binding(strict, mesh.request, mesh.request.to_bytes(), {"binding_id": binding_id})
        with pytest.raises(UnknownBindingError) as e:
            on_fresh.deform(frames[0].posed, frames[0].rest, frames[0].blend_shape_weights)
        assert e.value.code == "unknown_binding" and binding_id in e.value.message
    assert fresh.metric("curvenet_bindings_computed_total") == 0
    # The client's re-post rebuilds it: the same id, the same points.
    with Client(fresh.url) as c:
        rebuilt = Binding(c, mesh.request, mesh.request.to_bytes(), {"binding_id": binding_id})
        points = deform_all(rebuilt, frames)
        assert rebuilt.rebound == 1 and rebuilt.id == binding_id
    assert fresh.metric("curvenet_bindings_computed_total") == 1
    for t, p, want in zip(times, points, expected):
        assert np.array_equal(p, want), f"frame {t}: the rebuilt binding differs (max |diff| {np.abs(p - want).max()})"
    assert fresh.metric("curvenet_store_rejected_total") == 1
    assert fresh.metric("curvenet_store_errors_total") == 0
    # The rebuilt binding was written back, and another replica reads it.
    assert blob in moto.keys(bucket, "bindings")
    other = start_server("--store", store, env=moto.env())
    with Client(other.url, rebinds=0) as cb:
        again = deform_all(unposted(cb, mesh, binding_id), frames)
    assert all(np.array_equal(p, want) for p, want in zip(again, expected))
    assert other.metric("curvenet_store_hits_total") == 1 and other.metric("curvenet_store_rejected_total") == 0


# ------------------------------------------------------------- c. bake


def bake(out: pathlib.Path, env: dict[str, str], *extra: str) -> str:
    """`curvenet bake` of hand_wave (the whole shot) to `out`; returns its stderr (the summary)."""
    r = subprocess.run(
        [str(curvenet_binary()), "bake", str(HAND_WAVE), "--out", str(out), *extra],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=ROOT,
        env=env,
    )
    assert r.returncode == 0, f"curvenet bake {' '.join(extra)} failed ({r.returncode}): {r.stderr}"
    assert "warning" not in r.stderr, r.stderr
    return r.stderr


def test_c_bake_with_an_s3_store_writes_the_same_bytes(moto: Moto, tmp_path: pathlib.Path) -> None:
    bucket = moto.bucket()
    env = moto.env()
    store = ["--store", f"s3://{bucket}/bake"]
    plain = tmp_path / "plain.usdc"
    bake(plain, env)
    first = bake(tmp_path / "first.usdc", env, *store)
    assert "(built, written to the store)" in first, first
    keys = moto.keys(bucket, "bake")
    assert len(keys) == 1 and BLOB.fullmatch(next(iter(keys)).removeprefix("bake/")), keys
    (blob,) = keys
    assert moto.get(bucket, blob)[:8] == b"CNENTRY\0"
    second = bake(tmp_path / "second.usdc", env, *store)
    assert "(loaded from the store)" in second, second
    # The second bake's hit marked the entry used; nothing else was written.
    assert sorted(moto.keys(bucket, "bake")) == [blob, blob.removesuffix(".cnb") + ".used"]
    want = plain.read_bytes()
    assert (tmp_path / "first.usdc").read_bytes() == want
    assert (tmp_path / "second.usdc").read_bytes() == want
