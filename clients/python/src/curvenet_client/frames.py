"""Frame inputs and the service's binary frame form.

Binary frames (server/README.md, "Binary frames")::

    u32 little-endian   header length H
    H bytes             JSON header
    raw data            the arrays the header lists, in its order, little-endian f32

A request header lists ``posed`` (with ``index``: the curvenet), ``rest``,
``blend_shape_weights``, ``rest_cage`` and ``posed_cage_offsets`` arrays; the answer lists ``points`` ``[n, 3]`` and,
when asked for, ``gradients`` ``[n, 9]``. A batch wraps the per-frame headers
in ``{"frames": [...]}`` and concatenates the frames' arrays.

Inputs travel as float32 in this form (USD's ``point3f`` is float32, so a
stage's values go through unchanged); the JSON form (``Client(protocol="json")``)
sends float64.
"""

from __future__ import annotations

import json
import struct
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from .errors import ProtocolError

__all__ = ["Frame", "FrameResult", "decode_frames", "encode_frames", "frame_json"]

BlendShapeMode = Literal["after", "before"]

F32 = np.dtype("<f4")


@dataclass
class Frame:
    """One frame's input for a binding.

    Attributes:
        posed: one ``(P, 3)`` posed control-point pool per curvenet of the
            binding, in binding order, or ``None`` for a curvenet that is not
            articulated this frame; ``None`` altogether: none articulated.
        rest: the mesh's rest pose this frame, ``(V, 3)``; ``None``: the
            projection pose.
        blend_shape_weights: one weight per blend shape of the binding;
            ``None``: all zero.
        blend_shape_mode: ``"after"`` (the default: offsets follow each
            vertex's deformation gradient) or ``"before"`` (added to the rest pose).
        topology_hash: the binding's topology as the caller knows it; the
            server refuses the frame (``topology_changed``) when it differs.
        adjustments: Curvenet Adjustments (server/README.md, "Curvenet
            Adjustments"): mappings with ``curvenet`` and ``knot`` (a pool
            index of a spline endpoint) and optionally ``translate``,
            ``rotate`` (degrees, XYZ) or ``orient`` (a ``[w, x, y, z]``
            quaternion), ``scale``, ``attach_tangents`` and
            ``tangent_translates``, sent as given.
        orientations: also answer every knot's orientation
            (:attr:`FrameResult.knot_orientations`).
        rest_cage: a caged binding's rest cage this frame, ``(C, 3)`` (one
            point per cage vertex); ``None``: the cage at bind.
        posed_cage_offsets: a caged binding's posed-cage edits this frame,
            ``(C, 3)``; ``None``: none.
    """

    posed: Sequence[npt.ArrayLike | None] | None = None
    rest: npt.ArrayLike | None = None
    blend_shape_weights: npt.ArrayLike | None = None
    blend_shape_mode: BlendShapeMode = "after"
    topology_hash: str | None = field(default=None)
    adjustments: Sequence[Mapping[str, Any]] | None = None
    orientations: bool = False
    rest_cage: npt.ArrayLike | None = None
    posed_cage_offsets: npt.ArrayLike | None = None


@dataclass(frozen=True)
class FrameResult:
    """A deformed frame: ``points`` ``(V, 3)`` float32 and, when asked for,
    ``gradients`` ``(V, 3, 3)`` float32 (row-major, acting on column vectors)
    and ``knot_orientations``: per curvenet, each knot's pool index to its
    orientation ``(3, 3)`` float64."""

    points: npt.NDArray[np.float32]
    gradients: npt.NDArray[np.float32] | None
    solve_ms: float
    knot_orientations: list[dict[int, npt.NDArray[np.float64]]] | None = None


def _points(value: npt.ArrayLike, what: str) -> npt.NDArray[np.float32]:
    a = np.ascontiguousarray(value, dtype=F32)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"{what} has shape {a.shape}; expected (n, 3)")
    return a


def _weights(value: npt.ArrayLike) -> npt.NDArray[np.float32]:
    a = np.ascontiguousarray(value, dtype=F32)
    if a.ndim != 1:
        raise ValueError(f"blend_shape_weights has shape {a.shape}; expected (k,)")
    return a


def _adjustments(frame: Frame) -> list[dict[str, Any]]:
    return [dict(a) for a in frame.adjustments or ()]


def _orientations(value: Any, where: str) -> list[dict[int, npt.NDArray[np.float64]]] | None:
    """``knot_orientations`` of an answer: per curvenet, pool index -> 3x3."""
    if value is None:
        return None
    if not isinstance(value, list) or not all(isinstance(m, dict) for m in value):
        raise ProtocolError("protocol", f"{where}: knot_orientations is not a list of objects")
    try:
        return [{int(k): np.asarray(v, dtype=np.float64).reshape(3, 3) for k, v in m.items()} for m in value]
    except (TypeError, ValueError) as e:
        raise ProtocolError("protocol", f"{where}: knot_orientations: {e}") from None


def _frame_arrays(frame: Frame, gradients: bool) -> tuple[dict[str, Any], list[npt.NDArray[np.float32]]]:
    """One frame's binary header and its arrays, in header order."""
    arrays: list[dict[str, Any]] = []
    data: list[npt.NDArray[np.float32]] = []
    if frame.posed is not None:
        for k, pool in enumerate(frame.posed):
            if pool is not None:
                a = _points(pool, f"posed[{k}]")
                arrays.append({"name": "posed", "index": k, "shape": list(a.shape)})
                data.append(a)
    if frame.rest is not None:
        a = _points(frame.rest, "rest")
        arrays.append({"name": "rest", "shape": list(a.shape)})
        data.append(a)
    if frame.blend_shape_weights is not None:
        a = _weights(frame.blend_shape_weights)
        arrays.append({"name": "blend_shape_weights", "shape": list(a.shape)})
        data.append(a)
    for name in ("rest_cage", "posed_cage_offsets"):
        value = getattr(frame, name)
        if value is not None:
            a = _points(value, name)
            arrays.append({"name": name, "shape": list(a.shape)})
            data.append(a)
    header: dict[str, Any] = {"arrays": arrays, "gradients": gradients}
    if frame.blend_shape_mode != "after":
        header["blend_shape_mode"] = frame.blend_shape_mode
    if frame.topology_hash is not None:
        header["topology_hash"] = frame.topology_hash
    if frame.adjustments:
        header["adjustments"] = _adjustments(frame)
    if frame.orientations:
        header["orientations"] = True
    return header, data


def encode_frames(frames: Sequence[Frame], *, gradients: bool, batch: bool) -> bytes:
    """The binary body of one frame (``batch=False``: exactly one frame) or of
    a ``frames:batch`` request."""
    if not batch and len(frames) != 1:
        raise ValueError(f"a single-frame body holds one frame, not {len(frames)}")
    headers, data = [], []
    for f in frames:
        h, d = _frame_arrays(f, gradients)
        headers.append(h)
        data.extend(d)
    header = json.dumps({"frames": headers} if batch else headers[0], separators=(",", ":")).encode()
    return b"".join([struct.pack("<I", len(header)), header, *(a.tobytes() for a in data)])


def frame_json(frame: Frame, *, gradients: bool) -> dict[str, Any]:
    """One frame as the JSON ``FrameRequest`` (float64 numbers)."""
    out: dict[str, Any] = {"gradients": gradients}
    if frame.posed is not None:
        out["posed"] = [
            None if p is None else np.asarray(p, dtype=np.float64).reshape(-1, 3).tolist() for p in frame.posed
        ]
    if frame.rest is not None:
        out["rest"] = np.asarray(frame.rest, dtype=np.float64).reshape(-1, 3).tolist()
    if frame.blend_shape_weights is not None:
        out["blend_shape_weights"] = np.asarray(frame.blend_shape_weights, dtype=np.float64).reshape(-1).tolist()
    for name in ("rest_cage", "posed_cage_offsets"):
        value = getattr(frame, name)
        if value is not None:
            out[name] = np.asarray(value, dtype=np.float64).reshape(-1, 3).tolist()
    if frame.blend_shape_mode != "after":
        out["blend_shape_mode"] = frame.blend_shape_mode
    if frame.topology_hash is not None:
        out["topology_hash"] = frame.topology_hash
    if frame.adjustments:
        out["adjustments"] = _adjustments(frame)
    if frame.orientations:
        out["orientations"] = True
    return out


def _array(body: bytes, offset: int, spec: Any, width: int, where: str) -> tuple[npt.NDArray[np.float32], int]:
    shape = spec.get("shape") if isinstance(spec, dict) else None
    dtype = spec.get("dtype", "f32") if isinstance(spec, dict) else None
    if dtype not in ("f32", "float32", "<f4"):
        raise ProtocolError("protocol", f"{where} has dtype {dtype!r}; expected f32")
    if (
        not isinstance(shape, list)
        or len(shape) != 2
        or not all(isinstance(x, int) and x >= 0 for x in shape)
        or shape[1] != width
    ):
        raise ProtocolError("protocol", f"{where} has shape {shape!r}; expected [n, {width}]")
    n = shape[0] * width
    end = offset + 4 * n
    if end > len(body):
        raise ProtocolError("protocol", f"{where} needs {4 * n} bytes but only {len(body) - offset} remain")
    a = np.frombuffer(body, dtype=F32, count=n, offset=offset).reshape(shape[0], width)
    return a.astype(np.float32), end  # native byte order, writable, independent of the body


def decode_frames(body: bytes, *, batch: bool) -> list[FrameResult]:
    """The frames of a binary answer (one, or a batch's in request order).
    Anything out of order in the framing raises :class:`ProtocolError`."""
    if len(body) < 4:
        raise ProtocolError("protocol", f"the binary answer has {len(body)} bytes; no header length")
    (h,) = struct.unpack_from("<I", body)
    if 4 + h > len(body):
        raise ProtocolError("protocol", f"the header length is {h} bytes but only {len(body) - 4} follow")
    try:
        header = json.loads(body[4 : 4 + h])
    except ValueError as e:
        raise ProtocolError("protocol", f"the binary answer's header is not JSON: {e}") from None
    if batch:
        if not isinstance(header, dict) or not isinstance(header.get("frames"), list):
            raise ProtocolError("protocol", 'a batch answer\'s header must be {"frames": [...]}')
        headers = header["frames"]
    else:
        headers = [header]
    offset = 4 + h
    out = []
    for i, fh in enumerate(headers):
        where = f"frames[{i}]" if batch else "the answer"
        arrays = fh.get("arrays") if isinstance(fh, dict) else None
        if not isinstance(arrays, list):
            raise ProtocolError("protocol", f"{where} has no arrays list")
        points = gradients = None
        for spec in arrays:
            name = spec.get("name") if isinstance(spec, dict) else None
            if name == "points" and points is None:
                points, offset = _array(body, offset, spec, 3, f"{where}: points")
            elif name == "gradients" and gradients is None:
                g, offset = _array(body, offset, spec, 9, f"{where}: gradients")
                gradients = g.reshape(-1, 3, 3)
            else:
                raise ProtocolError("protocol", f"{where}: unexpected array {name!r}")
        if points is None:
            raise ProtocolError("protocol", f"{where} has no points")
        solve_ms = fh.get("solve_ms", 0.0)
        out.append(
            FrameResult(
                points,
                gradients,
                float(solve_ms) if isinstance(solve_ms, (int, float)) else 0.0,
                _orientations(fh.get("knot_orientations"), where),
            )
        )
    if offset != len(body):
        raise ProtocolError("protocol", f"{len(body) - offset} bytes follow the last array of the binary answer")
    return out


def decode_json_frame(doc: Any, where: str = "the answer") -> FrameResult:
    """A JSON ``FrameResponse``."""
    if not isinstance(doc, dict) or "points" not in doc:
        raise ProtocolError("protocol", f"{where} is not a FrameResponse")
    points = np.asarray(doc["points"], dtype=np.float32).reshape(-1, 3)
    gradients = None
    if doc.get("gradients") is not None:
        gradients = np.asarray(doc["gradients"], dtype=np.float32).reshape(-1, 3, 3)
    solve_ms = doc.get("solve_ms", 0.0)
    return FrameResult(
        points,
        gradients,
        float(solve_ms) if isinstance(solve_ms, (int, float)) else 0.0,
        _orientations(doc.get("knot_orientations"), where),
    )


def frame_bytes(frame: Frame) -> int:
    """The size of a frame's arrays in the binary form (what counts towards
    the server's body limit), without its small JSON header."""
    n = 0
    if frame.posed is not None:
        n += sum(12 * np.shape(p)[0] for p in frame.posed if p is not None)
    if frame.rest is not None:
        n += 12 * np.shape(frame.rest)[0]
    if frame.blend_shape_weights is not None:
        n += 4 * int(np.size(frame.blend_shape_weights))
    for cage in (frame.rest_cage, frame.posed_cage_offsets):
        if cage is not None:
            n += 12 * np.shape(cage)[0]
    return n
