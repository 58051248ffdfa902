"""Each error family raised by a live server, with the server's code, status
and message: bad input (frames and bindings), not found, unauthorised (token
and bake roots), server (a cache too small), and the client's own transport
error when nothing answers. (Saturated: test_recovery.py.)"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import HAND_WAVE, free_port, server_env
from test_deform import shot_frames

from curvenet_client import (
    BadInputError,
    BindingRequest,
    Client,
    CurvenetSpec,
    NotFoundError,
    ServerError,
    TransportError,
    UnauthorizedError,
    UnknownBindingError,
)


def test_bad_input(server) -> None:
    mesh, _, frames = shot_frames("hand_wave")
    with Client(server.url) as client:
        binding = client.bind(mesh.request)
        pool = np.asarray(frames[0].posed[0])
        cases = [
            (dict(posed=[pool[:-1]]), "count_mismatch", "posed[0] has 250 control points"),
            (dict(posed=[pool, pool]), "index_out_of_range", "posed index 1"),
            (dict(rest=np.zeros((1399, 3))), "count_mismatch", "rest has 1399 points"),
            (dict(blend_shape_weights=[1.0, 2.0]), "count_mismatch", "blend_shape_weights has 2 weights"),
        ]
        nan_pool = pool.copy()
        nan_pool[17, 1] = np.nan
        cases.append((dict(posed=[nan_pool]), "non_finite", "posed[0][17]"))
        for kwargs, code, text in cases:
            with pytest.raises(BadInputError) as e:
                binding.deform(**kwargs)
            assert (e.value.code, e.value.status) == (code, 422), e.value
            assert text in e.value.message, e.value.message
            assert e.value.request_id  # the server's x-request-id, to find its log line
        with pytest.raises(BadInputError) as e:
            binding.deform(topology_hash="0" * 64)
        assert (e.value.code, e.value.status) == ("topology_changed", 409)
        # A binding whose spline points past its pool.
        bad = BindingRequest(
            mesh.request.face_vertex_counts,
            mesh.request.face_vertex_indices,
            mesh.request.projection_points,
            [CurvenetSpec(mesh.request.curvenets[0].pool[:10], mesh.request.curvenets[0].splines)],
        )
        with pytest.raises(BadInputError) as e:
            client.bind(bad)
        assert (e.value.code, e.value.status) == ("index_out_of_range", 422)
        assert "curvenets[0].splines" in e.value.message
        # A batch names the failing frame.
        with pytest.raises(BadInputError) as e:
            binding.deform_many([frames[0], {"posed": [pool[:-2]]}])
        assert e.value.code == "count_mismatch" and e.value.message.startswith("frames[1]")


def test_not_found(server, tmp_path) -> None:
    with Client(server.url) as client:
        with pytest.raises(UnknownBindingError) as e:
            client.get_binding("0" * 64)
        assert (e.value.code, e.value.status) == ("unknown_binding", 404)
        assert isinstance(e.value, NotFoundError)
        assert client.delete_binding("0" * 64) is False


def test_unauthorised_and_not_found_bakes(start_server, tmp_path, monkeypatch) -> None:
    root = tmp_path / "shots"
    root.mkdir()
    server = start_server("--bake-root", str(root), env=server_env(CURVENET_TOKEN="s3cret"))
    mesh, _, _ = shot_frames("hand_wave")
    monkeypatch.delenv("CURVENET_TOKEN", raising=False)
    with Client(server.url) as anonymous:
        assert anonymous.health()  # /healthz needs no token
        with pytest.raises(UnauthorizedError) as e:
            anonymous.bind(mesh.request)
        assert (e.value.code, e.value.status) == ("unauthorized", 401)
    with Client(server.url, token="wrong") as wrong:
        with pytest.raises(UnauthorizedError) as e:
            wrong.bind(mesh.request)
        assert e.value.code == "unauthorized" and "wrong" in e.value.message
    monkeypatch.setenv("CURVENET_TOKEN", "s3cret")
    with Client(server.url) as client:  # the token from the environment
        assert client.token == "s3cret"
        assert client.bind(mesh.request).vertices == 1400
        with pytest.raises(UnauthorizedError) as e:
            client.bake(str(HAND_WAVE), str(root / "out.usda"))
        assert (e.value.code, e.value.status) == ("path_forbidden", 403)
        with pytest.raises(NotFoundError) as e:
            client.bake(str(root / "missing.usda"), str(root / "out.usda"))
        assert (e.value.code, e.value.status) == ("stage_not_found", 404)


def test_server_errors(start_server) -> None:
    server = start_server("--cache-bytes", "4KiB")
    mesh, _, _ = shot_frames("hand_wave")
    with Client(server.url) as client:
        with pytest.raises(ServerError) as e:
            client.bind(mesh.request)
        assert (e.value.code, e.value.status) == ("cache_too_small", 507)


def test_nothing_listening_is_a_transport_error() -> None:
    port = free_port()  # closed again: connections are refused
    with Client(f"http://127.0.0.1:{port}", retries=2, backoff=0.01) as client:
        with pytest.raises(TransportError) as e:
            client.get_binding("0" * 64)
        assert e.value.code == "transport" and e.value.status is None
        assert "after 3 tries" in e.value.message
        assert not client.health()


def test_bad_client_arguments() -> None:
    with pytest.raises(ValueError, match="not an http"):
        Client("ftp://example.com")
    with pytest.raises(ValueError, match="protocol"):
        Client("http://127.0.0.1:1", protocol="xml")  # type: ignore[arg-type]
