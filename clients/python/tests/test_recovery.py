"""What the client recovers from by itself, against live servers:

- the binding evicted mid-shot (a cache that holds one binding, another
  binding posted between two frames): re-posted and the frame repeated;
- the server restarted between frames (and down for a while during a frame):
  connection failures retried, the lost binding re-posted;
- 503 `saturated` under concurrent load on a server admitting one solve at a
  time: retried after Retry-After until the frames pass; with no retries
  left, raised as SaturatedError with the server's code.

Each recovered shot is compared with the in-process bake, bit for bit.
"""

from __future__ import annotations

import threading
import time
import urllib.error
import urllib.request

import numpy as np
import pytest
from conftest import HAND_SKINNED, free_port
from test_deform import shot_frames

from curvenet_client import Client, SaturatedError, UnknownBindingError
from curvenet_client.usd import StageMesh


def cached(url: str, binding_id: str) -> bool:
    """Whether the server has the binding (GET /v1/bindings/ID)."""
    try:
        with urllib.request.urlopen(f"{url}/v1/bindings/{binding_id}", timeout=30):
            return True
    except urllib.error.HTTPError as e:
        assert e.code == 404
        return False


def evict(server, other: Client, intruder, victim_id: str) -> None:
    """Posts `intruder` through `other` so that the one-binding cache evicts
    `victim_id`. moka evicts in its maintenance, which /metrics runs: once
    before (settling earlier re-posts, which may have left the intruder
    cached) and once after the post."""
    server.metrics()
    assert other.bind(intruder).id != victim_id
    server.metrics()
    assert not cached(server.url, victim_id)  # really evicted


def test_eviction_mid_shot_is_recovered(start_server, baked: dict) -> None:
    wave, times, frames = shot_frames("hand_wave")
    skinned = StageMesh(HAND_SKINNED, "/Hand/Mesh")
    probe = start_server()
    with Client(probe.url) as c:
        sizes = [c.bind(wave.request).info["size_bytes"], c.bind(skinned.request).info["size_bytes"]]
    # Room for the larger binding, not for both.
    server = start_server("--cache-bytes", f"{int(max(sizes) * 1.3)}B")
    with Client(server.url) as client, Client(server.url) as other:
        binding = client.bind(wave.request)
        out = {}
        for i, (t, f) in enumerate(zip(times, frames)):
            if i in (5, 15):
                evict(server, other, skinned.request, binding.id)
            out[t] = binding.deform(f.posed, f.rest, f.blend_shape_weights)
        assert binding.rebound == 2
        assert server.metric("curvenet_cache_evictions_total") >= 2
        assert all(np.array_equal(out[t], baked["hand_wave"][t]) for t in times)
        # Evicted before a batch, too.
        evict(server, other, skinned.request, binding.id)
        assert all(np.array_equal(p, baked["hand_wave"][t]) for t, p in zip(times, binding.deform_many(frames)))
        assert binding.rebound == 3
        # With no re-posts allowed the eviction is raised with the server's code.
        strict = Client(server.url, rebinds=0)
        b = strict.bind(wave.request)
        evict(server, other, skinned.request, b.id)
        with pytest.raises(UnknownBindingError) as e:
            b.deform(frames[3].posed, None, frames[3].blend_shape_weights)
        assert e.value.code == "unknown_binding" and e.value.status == 404 and b.id in e.value.message
        strict.close()


def test_server_restarts_between_frames_are_recovered(start_server, baked: dict) -> None:
    mesh, times, frames = shot_frames("hand_skinned")
    server = start_server(port=free_port())
    with Client(server.url, backoff=0.1, max_backoff=1.0, retries=30) as client:
        binding = client.bind(mesh.request)
        first_id = binding.id
        out = {}
        for i, (t, f) in enumerate(zip(times, frames)):
            if i == 4:
                server.restart()  # killed (no drain): a fresh process with an empty cache
            if i == 8:
                # Down for a while: the frame's connection attempts are refused
                # until the new process listens.
                server.kill()
                threading.Timer(1.5, server.start).start()
            out[t] = binding.deform(f.posed, f.rest, f.blend_shape_weights)
        assert binding.rebound == 2 and binding.id == first_id
        assert client.stats["retry:connection"] >= 1  # refused while the server was down
        assert client.stats["stale_connections"] >= 1  # the kept-alive connection to the killed process
        assert all(np.array_equal(out[t], baked["hand_skinned"][t]) for t in times)
    deadline = time.monotonic() + 30
    while server.proc is None and time.monotonic() < deadline:  # the timer's start, for the teardown
        time.sleep(0.1)


def test_saturation_is_retried_then_succeeds(start_server, baked: dict) -> None:
    """One solve admitted at a time, eight threads streaming the shot at once:
    most requests meet 503 saturated at first; every frame ends up right."""
    mesh, times, frames = shot_frames("hand_wave")
    server = start_server("--max-solves", "1", "--solve-threads", "1")
    with Client(server.url, retries=60, max_backoff=2.0) as client:
        binding = client.bind(mesh.request)
        results: list[object] = [None] * 8
        errors: list[BaseException] = []

        def run(k: int) -> None:
            try:
                results[k] = list(binding.deform_iter(frames, in_flight=2))
            except BaseException as e:  # noqa: BLE001 - reported by the main thread
                errors.append(e)

        threads = [threading.Thread(target=run, args=(k,)) for k in range(8)]
        for th in threads:
            th.start()
        for th in threads:
            th.join(timeout=600)
        assert not any(th.is_alive() for th in threads), "the streaming threads did not finish in 10 minutes"
        assert not errors, errors
        saturated = server.metric("curvenet_saturated_total")
        assert saturated >= 1, "no request met a 503: the test did not load the server"
        assert client.stats["retry:503"] == saturated  # every 503 the server sent was retried
        for out in results:
            assert isinstance(out, list) and len(out) == len(times)
            assert all(np.array_equal(p, baked["hand_wave"][t]) for t, p in zip(times, out))
        print(f"503 saturated answers retried: {saturated:.0f} for {8 * len(times)} frames")


def test_saturation_without_retries_raises_with_the_servers_code(start_server) -> None:
    """A batch holds the only solve permit; a frame sent meanwhile with no
    retries raises SaturatedError carrying `saturated`, 503 and Retry-After."""
    mesh, times, frames = shot_frames("hand_wave")
    server = start_server("--max-solves", "1", "--solve-threads", "1")
    # The loader retries often and fast, so that it gets the permit back
    # between the impatient client's frames.
    with Client(server.url, retries=10_000, max_backoff=0.05) as busy, Client(server.url, retries=0) as impatient:
        binding = busy.bind(mesh.request)
        lone = impatient.bind(mesh.request)
        stop = threading.Event()
        failed: list[BaseException] = []

        def load() -> None:
            try:
                while not stop.is_set():
                    binding.deform_many(frames * 4)
            except BaseException as e:  # noqa: BLE001 - reported by the main thread
                failed.append(e)

        loader = threading.Thread(target=load)
        loader.start()
        try:
            caught = None
            deadline = time.monotonic() + 120
            while caught is None and not failed and time.monotonic() < deadline:
                try:
                    lone.deform(frames[0].posed, None, frames[0].blend_shape_weights)
                except SaturatedError as e:
                    caught = e
                time.sleep(0.02)
            assert not failed, f"the loading batches failed: {failed[0]!r}"
            assert caught is not None, "no 503 within 120 s while batches held the only permit"
            assert caught.code == "saturated" and caught.status == 503 and caught.retry_after == 1.0
        finally:
            stop.set()
            loader.join(timeout=300)
