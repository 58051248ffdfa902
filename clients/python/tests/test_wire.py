"""The client's own pieces without a server: error answers to exceptions
(known codes, unknown codes by status, `details`, bodies that are not the
service's JSON) and the binary framing (what the server's format says, and
refusing answers whose framing is wrong)."""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest

from curvenet_client import (
    BadInputError,
    BindingRequest,
    Cage,
    CurvenetError,
    CurvenetSpec,
    Frame,
    NotFoundError,
    PayloadTooLargeError,
    ProtocolError,
    SaturatedError,
    ServerError,
    UnauthorizedError,
    UnknownBindingError,
)
from curvenet_client.errors import CODE_FAMILIES, error_from_response
from curvenet_client.frames import decode_frames, encode_frames, frame_json



def body(**doc: object) -> bytes:
    return json.dumps(doc).encode()


def test_every_documented_code_has_a_family() -> None:
    """The code table of server/README.md, read from the README itself."""
    import pathlib

    readme = pathlib.Path(__file__).resolve().parents[3] / "server" / "README.md"
    table = readme.read_text().split("<!-- error-codes: begin -->")[1].split("<!-- error-codes: end -->")[0]
    rows = [line.split("|") for line in table.splitlines() if line.startswith("| `")]
    documented = {r[1].strip().strip("`"): int(r[2]) for r in rows}
    assert len(documented) >= 26
    assert set(documented) == set(CODE_FAMILIES), set(documented) ^ set(CODE_FAMILIES)
    for code, status in documented.items():
        err = error_from_response(status, body(code=code, message="m"))
        assert type(err) is CODE_FAMILIES[code], code
        assert (err.code, err.status, err.message) == (code, status, "m")


@pytest.mark.parametrize(
    ("status", "cls"),
    [
        (400, BadInputError),
        (405, BadInputError),
        (409, BadInputError),
        (413, PayloadTooLargeError),
        (422, BadInputError),
        (401, UnauthorizedError),
        (403, UnauthorizedError),
        (404, NotFoundError),
        (429, SaturatedError),
        (503, SaturatedError),
        (500, ServerError),
        (507, ServerError),
        (502, ServerError),
    ],
)
def test_unknown_codes_map_by_status_family(status: int, cls: type[CurvenetError]) -> None:
    err = error_from_response(status, body(code="some_future_code", message="new"))
    assert type(err) is cls
    assert err.code == "some_future_code" and err.status == status and err.message == "new"


def test_details_are_carried_when_present_and_empty_when_absent() -> None:
    details = {"curvenet": 0, "spline": 3, "face": 17}
    err = error_from_response(422, body(code="invalid_curvenet", message="x", details=details), request_id="r-1")
    assert err.details == details and err.request_id == "r-1"
    assert error_from_response(422, body(code="invalid_curvenet", message="x")).details == {}
    # A details field that is not an object is not carried.
    assert error_from_response(422, body(code="invalid_curvenet", message="x", details=[1])).details == {}


def test_a_body_that_is_not_the_services_json() -> None:
    err = error_from_response(502, b"<html>Bad Gateway</html>", retry_after=3.0)
    assert type(err) is ServerError
    assert err.code == "http_502" and "Bad Gateway" in err.message and err.retry_after == 3.0
    err = error_from_response(503, b"")
    assert type(err) is SaturatedError and err.code == "http_503"
    assert isinstance(error_from_response(404, body(code="unknown_binding", message="m")), UnknownBindingError)


def test_binary_request_matches_the_documented_framing() -> None:
    pool = np.arange(12, dtype=np.float64).reshape(4, 3) / 7
    rest = np.ones((5, 3))
    frame = Frame(posed=[None, pool], rest=rest, blend_shape_weights=[0.5], topology_hash="ab")
    raw = encode_frames([frame], gradients=True, batch=False)
    (h,) = struct.unpack_from("<I", raw)
    header = json.loads(raw[4 : 4 + h])
    assert header == {
        "arrays": [
            {"name": "posed", "index": 1, "shape": [4, 3]},
            {"name": "rest", "shape": [5, 3]},
            {"name": "blend_shape_weights", "shape": [1]},
        ],
        "gradients": True,
        "topology_hash": "ab",
    }
    data = np.frombuffer(raw, dtype="<f4", offset=4 + h)
    assert data.size == 12 + 15 + 1
    assert np.array_equal(data[:12], pool.astype(np.float32).ravel())
    assert np.array_equal(data[12:27], np.ones(15, dtype=np.float32))
    assert data[27] == np.float32(0.5)

    batch = encode_frames([frame, Frame()], gradients=False, batch=True)
    (h,) = struct.unpack_from("<I", batch)
    assert [len(f["arrays"]) for f in json.loads(batch[4 : 4 + h])["frames"]] == [3, 0]
    with pytest.raises(ValueError, match=r"posed\[0\] has shape"):
        encode_frames([Frame(posed=[np.zeros((3, 2))])], gradients=False, batch=False)


def test_cage_arrays_travel_in_both_forms_and_the_binding_carries_the_cage() -> None:
    rest_cage = np.arange(12, dtype=np.float64).reshape(4, 3) / 3
    offsets = np.full((4, 3), 0.25)
    frame = Frame(rest_cage=rest_cage, posed_cage_offsets=offsets)
    raw = encode_frames([frame], gradients=False, batch=False)
    (h,) = struct.unpack_from("<I", raw)
    header = json.loads(raw[4 : 4 + h])
    assert header["arrays"] == [
        {"name": "rest_cage", "shape": [4, 3]},
        {"name": "posed_cage_offsets", "shape": [4, 3]},
    ]
    data = np.frombuffer(raw, dtype="<f4", offset=4 + h)
    assert np.array_equal(data[:12], rest_cage.astype(np.float32).ravel())
    assert np.array_equal(data[12:], np.full(12, 0.25, dtype=np.float32))
    doc = frame_json(frame, gradients=False)
    assert doc["rest_cage"] == rest_cage.tolist() and doc["posed_cage_offsets"] == offsets.tolist()
    assert "rest_cage" not in frame_json(Frame(), gradients=False)
    with pytest.raises(ValueError, match=r"rest_cage has shape"):
        encode_frames([Frame(rest_cage=np.zeros((4, 2)))], gradients=False, batch=False)

    tetra = Cage([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    request = BindingRequest([3], [0, 1, 2], np.eye(3), [CurvenetSpec(np.zeros((4, 3)), [[0, 1, 2, 3]])], cage=tetra)
    doc = request.to_json()
    assert doc["cage"] == {"points": tetra.points.tolist(), "triangles": tetra.triangles.tolist()}
    again = BindingRequest.from_json(doc)
    assert again.cage is not None and np.array_equal(again.cage.triangles, tetra.triangles)
    assert "cage" not in BindingRequest.from_json({k: v for k, v in doc.items() if k != "cage"}).to_json()


def test_adjustments_travel_in_the_header_and_orientations_decode() -> None:
    adjust = [{"curvenet": 0, "knot": 12, "translate": [0.0, 1.0, 0.0], "attach_tangents": False}]
    raw = encode_frames([Frame(adjustments=adjust, orientations=True)], gradients=False, batch=False)
    (h,) = struct.unpack_from("<I", raw)
    header = json.loads(raw[4 : 4 + h])
    assert header["adjustments"] == adjust and header["orientations"] is True
    plain = json.loads(encode_frames([Frame()], gradients=False, batch=False)[4:])
    assert "adjustments" not in plain and "orientations" not in plain

    rotation = [0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0]
    head = {"arrays": [{"name": "points", "dtype": "f32", "shape": [1, 3]}], "solve_ms": 1.0,
            "knot_orientations": [{"12": rotation}]}
    body = json.dumps(head).encode()
    (one,) = decode_frames(struct.pack("<I", len(body)) + body + np.zeros(3, "<f4").tobytes(), batch=False)
    assert one.knot_orientations is not None
    assert np.array_equal(one.knot_orientations[0][12], np.asarray(rotation).reshape(3, 3))
    head["knot_orientations"] = [{"12": [1.0, 2.0]}]
    body = json.dumps(head).encode()
    with pytest.raises(ProtocolError, match="knot_orientations"):
        decode_frames(struct.pack("<I", len(body)) + body + np.zeros(3, "<f4").tobytes(), batch=False)


def answer(frames: list[tuple[np.ndarray, np.ndarray | None]], batch: bool, pad: bool = True) -> bytes:
    headers, data = [], []
    for points, grads in frames:
        arrays = [{"name": "points", "dtype": "f32", "shape": [len(points), 3]}]
        data.append(points.astype("<f4").tobytes())
        if grads is not None:
            arrays.append({"name": "gradients", "dtype": "f32", "shape": [len(grads), 9]})
            data.append(grads.astype("<f4").tobytes())
        headers.append({"arrays": arrays, "solve_ms": 1.5})
    header = json.dumps({"frames": headers} if batch else headers[0]).encode()
    while pad and len(header) % 4:
        header += b" "
    return struct.pack("<I", len(header)) + header + b"".join(data)


def test_binary_answers_decode_and_bad_framing_is_refused() -> None:
    rng = np.random.default_rng(1)
    p1, p2 = rng.normal(size=(7, 3)), rng.normal(size=(7, 3))
    g = rng.normal(size=(7, 9))
    (one,) = decode_frames(answer([(p1, g)], batch=False), batch=False)
    assert one.points.dtype == np.float32 and np.array_equal(one.points, p1.astype(np.float32))
    assert one.gradients is not None and one.gradients.shape == (7, 3, 3)
    assert np.array_equal(one.gradients.reshape(7, 9), g.astype(np.float32))
    assert one.solve_ms == 1.5
    two = decode_frames(answer([(p1, None), (p2, None)], batch=True, pad=False), batch=True)
    assert [np.array_equal(f.points, p.astype(np.float32)) for f, p in zip(two, (p1, p2))] == [True, True]

    good = answer([(p1, None)], batch=False)
    for broken, message in [
        (good[:3], "no header length"),
        (good[:-4], "remain"),
        (good + b"\0\0\0\0", "follow the last array"),
        (struct.pack("<I", 1000) + good[4:], "header length"),
        (struct.pack("<I", 2) + b"{x" + good[6:], "not JSON"),
    ]:
        with pytest.raises(ProtocolError, match=message):
            decode_frames(broken, batch=False)
    with pytest.raises(ProtocolError, match="batch"):
        decode_frames(good, batch=True)


def test_back_off_delays() -> None:
    from curvenet_client import Client

    c = Client("http://127.0.0.1:1", backoff=0.25, max_backoff=10.0)
    for _ in range(200):
        assert 0.1875 <= c._delay(0, None) <= 0.25
        assert 2.0 * 0.75 <= c._delay(3, None) <= 2.0
        assert c._delay(10, None) == 10.0  # capped
        assert 1.0 <= c._delay(0, 1.0) <= 1.25  # Retry-After is a floor
        assert 4.0 <= c._delay(0, 4.0) <= 5.0
        assert c._delay(0, 60.0) == 10.0  # even Retry-After is capped at max_backoff
