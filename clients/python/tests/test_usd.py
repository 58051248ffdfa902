"""The USD helpers (curvenet_client.usd) against the Rust reader and usd-core:

- the BindingRequest read here has the binding id the server computes for
  the same stage with its own reader (`curvenet serve --open-stage`), for
  every fixture stage; the id hashes the topology, the projection pose's
  float64 bits, the pools, splines, densities and blend shapes, so equal ids
  mean equal content;
- a leftHanded mesh (faces authored reversed) reads as the rightHanded one,
  also by the Rust reader; an indexed projectionPoints primvar is flattened;
- per-frame inputs are the stage's values; contract violations name the prim
  and attribute;
- write_points_layer writes `over` opinions that usd-core composes over the
  stage, and nothing (not even a temporary file) when it fails.
"""

from __future__ import annotations

import json
import pathlib
import urllib.request

import numpy as np
import pytest
from conftest import HAND_SKINNED, HAND_WAVE, ROOT
from pxr import Sdf, Usd, UsdGeom, Vt

from curvenet_client import Client
from curvenet_client.usd import (
    StageMesh,
    UsdContractError,
    binding_request,
    deformed_meshes,
    frame_inputs,
    frame_range,
    write_points_layer,
)

HAND_1K4 = ROOT / "fixtures" / "hand" / "hand_1k4.usda"
STAGES = [
    HAND_WAVE,
    HAND_SKINNED,
    HAND_1K4,
    ROOT / "fixtures" / "grid" / "grid.usda",
    ROOT / "fixtures" / "cylinder" / "cylinder.usda",
]


def get(url: str) -> dict:
    with urllib.request.urlopen(url, timeout=300) as r:
        doc: dict = json.loads(r.read())
        return doc


def server_ids(start_server, stages: list[pathlib.Path]) -> list[str]:
    """The binding id the server's own reader gives each stage's mesh."""
    args = [a for s in stages for a in ("--open-stage", str(s))]
    server = start_server(*args)
    listed = get(f"{server.url}/v1/viewer/stages")["stages"]
    assert len(listed) == len(stages)
    return [get(f"{server.url}/v1/viewer/stages/{s['index']}")["binding"]["binding_id"] for s in listed]


def test_binding_requests_match_the_rust_reader(start_server) -> None:
    expected = server_ids(start_server, STAGES)
    server = start_server()
    with Client(server.url) as client:
        for stage, want in zip(STAGES, expected):
            (mesh,) = deformed_meshes(stage)
            got = client.bind(binding_request(stage, mesh))
            assert got.id == want, stage
    assert len(set(expected)) == len(STAGES) - 1  # hand_skinned binds as hand_1k4: same mesh, pose, curvenet


def write_override(tmp_path: pathlib.Path, name: str, body: str) -> pathlib.Path:
    layer = tmp_path / name
    layer.write_text(
        f'#usda 1.0\n(\n    subLayers = [@{HAND_1K4}@]\n)\n\nover "Hand"\n{{\n    over "Mesh"\n    {{\n{body}    }}\n}}\n'
    )
    return layer


def test_left_handed_meshes_and_indexed_projection_points(tmp_path, start_server) -> None:
    plain = binding_request(HAND_1K4, "/Hand/Mesh")
    counts = plain.face_vertex_counts
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    reversed_faces = np.concatenate([plain.face_vertex_indices[s : s + c][::-1] for s, c in zip(starts, counts)])
    assert not np.array_equal(reversed_faces, plain.face_vertex_indices)
    left = write_override(
        tmp_path,
        "left.usda",
        '        uniform token orientation = "leftHanded"\n'
        f"        int[] faceVertexIndices = [{', '.join(map(str, reversed_faces.tolist()))}]\n",
    )
    read = binding_request(left, "/Hand/Mesh")
    assert np.array_equal(read.face_vertex_indices, plain.face_vertex_indices)
    assert read.to_bytes() == plain.to_bytes()
    # The Rust reader agrees: the same binding id for both stages.
    ids = server_ids(start_server, [HAND_1K4, left])
    assert ids[0] == ids[1]

    # An indexed projectionPoints primvar: values in another order plus indices.
    points = plain.projection_points
    order = np.random.default_rng(3).permutation(len(points))
    stage = Usd.Stage.Open(str(write_override(tmp_path, "indexed.usda", "")))
    primvar = UsdGeom.PrimvarsAPI(stage.GetPrimAtPath("/Hand/Mesh")).CreatePrimvar(
        "curvenet:projectionPoints", Sdf.ValueTypeNames.Point3fArray, UsdGeom.Tokens.vertex
    )
    primvar.Set(Vt.Vec3fArray.FromNumpy(points[order].astype(np.float32)))
    primvar.SetIndices(Vt.IntArray.FromNumpy(np.argsort(order).astype(np.int32)))
    flattened = binding_request(stage, "/Hand/Mesh")
    assert np.array_equal(flattened.projection_points, points)


def test_frame_inputs_are_the_stages_values() -> None:
    wave = Usd.Stage.Open(str(HAND_WAVE))
    f = frame_inputs(wave, "/Hand/Mesh", 7.0)
    cv = np.asarray(wave.GetPrimAtPath("/Hand/Curvenet").GetAttribute("primvars:curvenet:cv").Get(7.0))
    assert f.rest is None and f.posed is not None and np.array_equal(f.posed[0], cv)
    assert np.array_equal(f.blend_shape_weights, np.array([0.5], dtype=np.float32))
    assert frame_range(wave) == [float(t) for t in range(1, 25)]

    skinned = StageMesh(HAND_SKINNED, "/Hand/Mesh")
    assert skinned.reads_rest and skinned.articulated == [False]
    f = skinned.frame(6.0)
    pts = np.asarray(skinned.stage.GetPrimAtPath("/Hand/Mesh").GetAttribute("points").Get(6.0))
    assert f.posed == [None] and f.blend_shape_weights is None and np.array_equal(f.rest, pts)
    # The projection pose is the authored primvar, not the animated points.
    assert not np.array_equal(skinned.request.projection_points, pts)


def test_contract_violations_name_the_prim_and_attribute(tmp_path) -> None:
    stage = Usd.Stage.Open(str(write_override(tmp_path, "broken.usda", "")))
    net = stage.GetPrimAtPath("/Hand/Curvenet")
    net.GetAttribute("primvars:curvenet:cv:indices").Set(Vt.IntArray([0, 1, 2, 3, 4, 5]))
    net.GetAttribute("curveVertexCounts").Clear()
    with pytest.raises(UsdContractError, match=r"/Hand/Curvenet: primvars:curvenet:cv:indices has 6 entries"):
        binding_request(stage, "/Hand/Mesh")
    with pytest.raises(UsdContractError, match="/Hand/Nothing: no such prim"):
        StageMesh(stage, "/Hand/Nothing")


def test_write_points_layer_composes_over_the_stage(tmp_path) -> None:
    mesh = StageMesh(HAND_WAVE, "/Hand/Mesh")
    rng = np.random.default_rng(5)
    frames = {t: (mesh.request.projection_points + rng.normal(scale=0.01, size=(1400, 3))).astype(np.float32)
              for t in (1.0, 2.0, 3.0)}
    out = tmp_path / "points.usda"
    write_points_layer(HAND_WAVE, "/Hand/Mesh", frames, out)
    layer = Sdf.Layer.FindOrOpen(str(out))
    assert (layer.startTimeCode, layer.endTimeCode) == (1.0, 3.0) and "/Hand/Mesh" in layer.documentation
    specs = []
    layer.Traverse("/", lambda p: specs.append(p))
    prims = [layer.GetPrimAtPath(p) for p in specs if p.IsPrimPath()]
    assert sorted(str(p.path) for p in prims) == ["/Hand", "/Hand/Mesh"]
    assert all(p.specifier == Sdf.SpecifierOver for p in prims)
    assert [str(p) for p in specs if p.IsPropertyPath()] == ["/Hand/Mesh.points"]
    # Sublayered above the shot, the points are the written ones.
    composed = tmp_path / "composed.usda"
    composed.write_text(f"#usda 1.0\n(\n    subLayers = [@{out}@, @{HAND_WAVE}@]\n)\n")
    stage = Usd.Stage.Open(str(composed))
    attr = stage.GetPrimAtPath("/Hand/Mesh").GetAttribute("points")
    for t, p in frames.items():
        assert np.array_equal(np.asarray(attr.Get(t), dtype=np.float32), p)

    # A failure writes nothing: the output stays as it was, no temporary file.
    before = out.read_bytes()
    with pytest.raises(ValueError, match="shape"):
        write_points_layer(HAND_WAVE, "/Hand/Mesh", {1.0: frames[1.0], 2.0: np.zeros((4, 2))}, out)
    assert out.read_bytes() == before
    assert sorted(x.name for x in tmp_path.iterdir()) == ["composed.usda", "points.usda"]
