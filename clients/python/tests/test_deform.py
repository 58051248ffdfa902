"""Bind and deform through a live `curvenet serve`, compared with the
in-process bake (`curvenet bake`, no service) of the shipped shots: every
frame's points must be the same float32 values, bit for bit.

- hand_wave: an articulated curvenet and a blend shape with an inbetween
  (posed pools and weights per frame);
- hand_skinned: a linear-blend-skinned rest pose per frame and a separate
  projection pose (rest per frame, no posed pools).
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import HAND_SKINNED, HAND_WAVE, Server

from curvenet_client import Client, Frame, PayloadTooLargeError
from curvenet_client.usd import StageMesh, deformed_meshes, frame_range

SHOTS = {"hand_wave": HAND_WAVE, "hand_skinned": HAND_SKINNED}


def shot_frames(name: str) -> tuple[StageMesh, list[float], list[Frame]]:
    stage = SHOTS[name]
    (mesh_path,) = deformed_meshes(stage)
    mesh = StageMesh(stage, mesh_path)
    times = frame_range(mesh.stage, [mesh])
    return mesh, times, [mesh.frame(t) for t in times]


def batch_requests(server: Server, status: str = "200") -> float:
    return server.metric(
        "curvenet_http_requests_total", route="/v1/bindings/{id}/frames:batch", method="POST", status=status
    )


@pytest.mark.parametrize("shot", ["hand_wave", "hand_skinned"])
def test_bind_and_deform_equal_the_in_process_bake(server: Server, baked: dict, shot: str) -> None:
    mesh, times, frames = shot_frames(shot)
    expected = baked[shot]
    assert sorted(expected) == times  # the bake baked the same frames
    with Client(server.url) as client:
        binding = client.bind(mesh.request)
        assert binding.vertices == mesh.vertices == 1400
        assert len(binding.id) == 64 and binding.info["control_points"] == [251]
        moved = 0
        for t, f in zip(times, frames):
            points = binding.deform(f.posed, f.rest, f.blend_shape_weights)
            assert points.dtype == np.float32 and points.shape == (1400, 3)
            assert np.array_equal(points, expected[t]), f"{shot} frame {t}: max |diff| {np.abs(points - expected[t]).max()}"
            moved += not np.array_equal(points, expected[times[0]])
        assert moved >= len(times) // 2  # the shot moves: the comparison is not of one pose
        # The same frames through frames:batch and through the streaming form.
        assert all(np.array_equal(p, expected[t]) for t, p in zip(times, binding.deform_many(frames)))
        streamed = list(binding.deform_iter(iter(frames), in_flight=3))
        assert all(np.array_equal(p, expected[t]) for t, p in zip(times, streamed))


def test_gradients_and_the_json_form(server: Server, baked: dict) -> None:
    mesh, times, frames = shot_frames("hand_wave")
    t, f = times[12], frames[12]  # the curl's peak, the blend shape at weight 1
    with Client(server.url) as binary, Client(server.url, protocol="json") as js:
        b = binary.bind(mesh.request)
        points, gradients = b.deform(f.posed, f.rest, f.blend_shape_weights, gradients=True)
        assert np.array_equal(points, baked["hand_wave"][t])
        assert gradients.shape == (1400, 3, 3) and gradients.dtype == np.float32
        # The curled finger rotates: a gradient far from the identity with det ~ 1.
        dets = np.linalg.det(gradients.astype(np.float64))
        assert np.abs(dets - 1).max() < 0.5 and np.abs(gradients - np.eye(3)).max() > 0.5
        j = js.bind(mesh.request)
        assert j.id == b.id  # the same content, the same binding
        # The stage's values are float32, so both forms send the same numbers.
        jp, jg = j.deform(f.posed, f.rest, f.blend_shape_weights, gradients=True)
        assert np.array_equal(jp, points) and np.array_equal(jg, gradients)
        many = j.deform_many(frames[:5])
        assert all(np.array_equal(p, baked["hand_wave"][tt]) for tt, p in zip(times[:5], many))


def test_batches_are_chunked_under_the_body_budget(server: Server, baked: dict) -> None:
    """hand_skinned frames carry a 1400-point rest pose (16.8 kB each): a
    64 kB budget makes chunks of 3 frames, max_batch_frames caps them too."""
    mesh, times, frames = shot_frames("hand_skinned")
    with Client(server.url, max_body_bytes=64 << 10) as client:
        binding = client.bind(mesh.request)
        before = batch_requests(server)
        out = binding.deform_many(frames)
        assert batch_requests(server) - before == 4  # 12 frames in chunks of 3
        assert all(np.array_equal(p, baked["hand_skinned"][t]) for t, p in zip(times, out))
    with Client(server.url, max_batch_frames=5) as client:
        before = batch_requests(server)
        client.bind(mesh.request).deform_many(frames)
        assert batch_requests(server) - before == 3  # 5 + 5 + 2


def test_a_batch_over_the_servers_body_limit_is_split(start_server, baked: dict) -> None:
    """The server takes bodies a little larger than the binding; the client
    does not know the limit and learns it from the 413: the 12-frame batch
    (over the limit) is split until the parts pass."""
    mesh, times, frames = shot_frames("hand_skinned")
    limit = len(mesh.request.to_bytes()) + 1000
    assert 12 * 1400 * 12 > limit  # the whole batch's rest poses alone are over it
    server = start_server("--body-limit", f"{limit}B")
    with Client(server.url) as client:
        binding = client.bind(mesh.request)
        out = binding.deform_many(frames)
        assert all(np.array_equal(p, baked["hand_skinned"][t]) for t, p in zip(times, out))
        # The server refuses the body before routing it, so its per-route
        # metrics do not count the 413: the client's own counters do.
        assert client.stats["batch_splits"] >= 1 and batch_requests(server) >= 2
        assert client.max_body_bytes <= limit  # learnt: the next batches fit at once
        splits, sent, tries = client.stats["batch_splits"], batch_requests(server), client.stats["requests"]
        assert all(np.array_equal(p, baked["hand_skinned"][t]) for t, p in zip(times, binding.deform_many(frames)))
        # Two chunks of 6 frames (the refused 12 halved), both accepted at once.
        assert client.stats["batch_splits"] == splits
        assert batch_requests(server) - sent == 2 and client.stats["requests"] - tries == 2
        # One frame over the limit cannot be split: raised with the server's code.
        with pytest.raises(PayloadTooLargeError) as e:
            binding.deform(rest=np.zeros((limit // 12 + 1, 3)))
        assert e.value.code == "payload_too_large" and e.value.status == 413


def test_a_batch_over_the_servers_answer_limit_is_split(start_server, baked: dict) -> None:
    """A batch whose answer is over the server's --max-batch-bytes (422
    limit_exceeded) is split until the parts pass, and the client's frames
    per batch lowered to match."""
    mesh, times, frames = shot_frames("hand_skinned")
    # Three frames' answers (1,400 vertices x 12 bytes each) fit, twelve do not.
    server = start_server("--max-batch-bytes", f"{3 * 1400 * 12}B")
    with Client(server.url) as client:
        binding = client.bind(mesh.request)
        out = binding.deform_many(frames)
        assert all(np.array_equal(p, baked["hand_skinned"][t]) for t, p in zip(times, out))
        assert client.stats["batch_splits"] >= 1 and client.max_batch_frames <= 3
        # With gradients (48 bytes a vertex) not even one frame's answer fits a
        # batch: the halves go one frame at a time, to /frames (no batch limit).
        with_gradients = binding.deform_many(frames[:2], gradients=True)
        assert all(np.array_equal(p, baked["hand_skinned"][t]) for t, (p, _) in zip(times, with_gradients))
        assert client.max_batch_frames == 1


def test_adjustments_and_knot_orientations_in_both_forms(server: Server) -> None:
    """A Curvenet Adjustment moves the surface the same in the binary and
    JSON forms; identity adjustments change nothing; the orientations are
    one rotation per knot of each curvenet, the same in both forms."""
    mesh, _, frames = shot_frames("hand_wave")
    splines = np.asarray(mesh.request.curvenets[0].splines)
    knot = int(splines[0][0])
    adjust = [{"curvenet": 0, "knot": knot, "translate": [0.0, 0.004, 0.0], "rotate": [0.0, 0.0, 20.0]}]
    f = frames[3]
    results = {}
    for protocol in ("binary", "json"):
        with Client(server.url, protocol=protocol) as client:
            binding = client.bind(mesh.request)
            plain, adjusted, identity = binding.solve(
                [
                    Frame(f.posed, f.rest, f.blend_shape_weights),
                    Frame(f.posed, f.rest, f.blend_shape_weights, adjustments=adjust, orientations=True),
                    Frame(f.posed, f.rest, f.blend_shape_weights, adjustments=[{"curvenet": 0, "knot": knot}]),
                ]
            )
        assert np.array_equal(identity.points, plain.points)
        assert np.abs(adjusted.points - plain.points).max() > 1e-3
        assert plain.knot_orientations is None
        orientations = adjusted.knot_orientations
        assert orientations is not None and len(orientations) == 1
        knots = set(splines[:, 0].tolist()) | set(splines[:, 3].tolist())
        assert set(orientations[0]) == knots
        for m in orientations[0].values():
            assert np.allclose(m @ m.T, np.eye(3), atol=1e-9) and np.linalg.det(m) > 0
        results[protocol] = adjusted
    # Binary sends float32 inputs, JSON float64: the surfaces agree to float32 precision.
    assert np.abs(results["binary"].points - results["json"].points).max() < 1e-5
    assert results["binary"].knot_orientations is not None and results["json"].knot_orientations is not None
    for k, m in results["json"].knot_orientations[0].items():
        assert np.allclose(results["binary"].knot_orientations[0][k], m, atol=1e-5)
