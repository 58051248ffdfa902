"""The ``BindingRequest`` of ``POST /v1/bindings`` as typed numpy data.

The wire type is documented in the service (``schema/src/wire.rs``, served as
OpenAPI at ``/openapi.json``); this is its Python form. Faces are
counter-clockwise seen from outside; every point is float64 here (the binding
id hashes the float64 bits, so a stage's float32 values are widened exactly).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

__all__ = ["BindingOptions", "BindingRequest", "BlendShape", "Cage", "CurvenetSpec", "Inbetween"]

#: Samples per mean mesh edge length when a curvenet authors none (``curvenet:sampleDensity``).
DEFAULT_SAMPLE_DENSITY = 5.0


def _points(value: npt.ArrayLike, what: str) -> npt.NDArray[np.float64]:
    a = np.asarray(value, dtype=np.float64)
    if a.size == 0:
        a = a.reshape(0, 3)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"{what} has shape {a.shape}; expected (n, 3)")
    return a


def _ints(value: npt.ArrayLike, what: str) -> npt.NDArray[np.int64]:
    a = np.asarray(value)
    if a.size == 0:
        return np.zeros(0, dtype=np.int64)
    if not np.issubdtype(a.dtype, np.integer):
        raise ValueError(f"{what} must hold integers, not {a.dtype}")
    return a.astype(np.int64).reshape(-1)


@dataclass
class CurvenetSpec:
    """One curvenet: the neutral pool ``(P, 3)``, the splines ``(S, 4)`` (pool
    indices: endpoint, handle, handle, endpoint) and the sample density."""

    pool: npt.NDArray[np.float64]
    splines: npt.NDArray[np.int64]
    sample_density: float = DEFAULT_SAMPLE_DENSITY

    def __post_init__(self) -> None:
        self.pool = _points(self.pool, "pool")
        self.splines = _ints(self.splines, "splines").reshape(-1, 4)

    def to_json(self) -> dict[str, Any]:
        return {
            "pool": self.pool.tolist(),
            "splines": self.splines.tolist(),
            "sample_density": float(self.sample_density),
        }


@dataclass
class Inbetween:
    """An inbetween shape reached exactly at ``weight``, laid out like its shape's offsets."""

    weight: float
    offsets: npt.NDArray[np.float64]

    def __post_init__(self) -> None:
        self.offsets = _points(self.offsets, "inbetween offsets")


@dataclass
class BlendShape:
    """A UsdSkel blend shape: ``offsets`` at weight 1 (one per vertex, or one
    per entry of ``point_indices`` for a sparse shape) and its inbetweens."""

    offsets: npt.NDArray[np.float64]
    point_indices: npt.NDArray[np.int64] | None = None
    inbetweens: list[Inbetween] = field(default_factory=list)
    name: str | None = None

    def __post_init__(self) -> None:
        self.offsets = _points(self.offsets, "offsets")
        if self.point_indices is not None:
            self.point_indices = _ints(self.point_indices, "point_indices")

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {"offsets": self.offsets.tolist()}
        if self.name is not None:
            out["name"] = self.name
        if self.point_indices is not None:
            out["point_indices"] = self.point_indices.tolist()
        if self.inbetweens:
            out["inbetweens"] = [{"weight": float(i.weight), "offsets": i.offsets.tolist()} for i in self.inbetweens]
        return out


@dataclass
class BindingOptions:
    """``strict``: refuse a mesh component no curvenet touches. The tolerances
    are relative to the bounding-box diagonal; ``None`` takes the server's
    default (snapping 1e-5, projection distance 0.05)."""

    strict: bool = False
    snap_tolerance: float | None = None
    max_projection_distance: float | None = None

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {}
        if self.strict:
            out["strict"] = True
        if self.snap_tolerance is not None:
            out["snap_tolerance"] = float(self.snap_tolerance)
        if self.max_projection_distance is not None:
            out["max_projection_distance"] = float(self.max_projection_distance)
        return out


@dataclass
class Cage:
    """A closed triangle cage around the mesh (server/README.md, "The
    cage"): its rest points at bind ``(C, 3)`` and its triangles ``(T, 3)``,
    counter-clockwise seen from outside. Without a skin (this client sends
    none) the cage alone deforms the mesh; frames edit it with
    ``rest_cage`` and ``posed_cage_offsets``."""

    points: npt.NDArray[np.float64]
    triangles: npt.NDArray[np.int64]

    def __post_init__(self) -> None:
        self.points = _points(self.points, "cage.points")
        self.triangles = _ints(self.triangles, "cage.triangles").reshape(-1, 3)

    def to_json(self) -> dict[str, Any]:
        return {"points": self.points.tolist(), "triangles": self.triangles.tolist()}


@dataclass
class BindingRequest:
    """A mesh (topology and projection pose) and the curvenets that deform it,
    with its blend shapes: everything the service hashes into a binding id."""

    face_vertex_counts: npt.NDArray[np.int64]
    face_vertex_indices: npt.NDArray[np.int64]
    projection_points: npt.NDArray[np.float64]
    curvenets: list[CurvenetSpec]
    blend_shapes: list[BlendShape] = field(default_factory=list)
    options: BindingOptions = field(default_factory=BindingOptions)
    cage: Cage | None = None

    def __post_init__(self) -> None:
        self.face_vertex_counts = _ints(self.face_vertex_counts, "face_vertex_counts")
        self.face_vertex_indices = _ints(self.face_vertex_indices, "face_vertex_indices")
        self.projection_points = _points(self.projection_points, "projection_points")

    @property
    def vertices(self) -> int:
        """``#V``: the length of every frame's points and rest pose."""
        return int(self.projection_points.shape[0])

    def to_json(self) -> dict[str, Any]:
        """The JSON ``BindingRequest`` (float64 numbers printed to round-trip exactly)."""
        out: dict[str, Any] = {
            "face_vertex_counts": self.face_vertex_counts.tolist(),
            "face_vertex_indices": self.face_vertex_indices.tolist(),
            "projection_points": self.projection_points.tolist(),
            "curvenets": [c.to_json() for c in self.curvenets],
        }
        if self.blend_shapes:
            out["blend_shapes"] = [s.to_json() for s in self.blend_shapes]
        if self.cage is not None:
            out["cage"] = self.cage.to_json()
        options = self.options.to_json()
        if options:
            out["options"] = options
        return out

    def to_bytes(self) -> bytes:
        """The request body (UTF-8 JSON)."""
        return json.dumps(self.to_json(), separators=(",", ":")).encode()

    @classmethod
    def from_json(cls, doc: Mapping[str, Any]) -> BindingRequest:
        """From the JSON form (also accepts ``faceVertexCounts``/``faceVertexIndices``)."""

        def get(name: str, alias: str | None = None) -> Any:
            if name in doc:
                return doc[name]
            if alias is not None and alias in doc:
                return doc[alias]
            raise ValueError(f"the binding request has no {name}")

        options = doc.get("options") or {}
        return cls(
            face_vertex_counts=get("face_vertex_counts", "faceVertexCounts"),
            face_vertex_indices=get("face_vertex_indices", "faceVertexIndices"),
            projection_points=get("projection_points"),
            curvenets=[
                CurvenetSpec(c["pool"], c["splines"], float(c.get("sample_density", DEFAULT_SAMPLE_DENSITY)))
                for c in get("curvenets")
            ],
            blend_shapes=[
                BlendShape(
                    s["offsets"],
                    s.get("point_indices"),
                    [Inbetween(float(i["weight"]), i["offsets"]) for i in s.get("inbetweens", [])],
                    s.get("name"),
                )
                for s in doc.get("blend_shapes", [])
            ],
            options=BindingOptions(
                bool(options.get("strict", False)),
                options.get("snap_tolerance"),
                options.get("max_projection_distance"),
            ),
            cage=Cage(doc["cage"]["points"], doc["cage"]["triangles"]) if doc.get("cage") is not None else None,
        )


def as_request(request: BindingRequest | Mapping[str, Any]) -> BindingRequest:
    """A :class:`BindingRequest`, given one or its JSON form."""
    if isinstance(request, BindingRequest):
        return request
    if isinstance(request, Mapping):
        return BindingRequest.from_json(request)
    raise TypeError(f"expected a BindingRequest or its JSON form (a mapping), not {type(request).__name__}")
