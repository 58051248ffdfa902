"""The USD fixtures read back through usd-core agree with fixtures/manifest.json
(which fixtures/generate.py writes from its in-memory arrays), follow the contract
of schema/README.md, and are up to date with the generator.

Run: .venv/bin/python -m pytest tests/python -q
"""

import json
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from pxr import Gf, Sdf, Usd, UsdGeom, UsdSkel, Vt

REPO = Path(__file__).resolve().parents[2]
FIXTURES = REPO / "fixtures"
GENERATE = FIXTURES / "generate.py"
MANIFEST = json.loads((FIXTURES / "manifest.json").read_text(encoding="utf-8"))
STAGES = sorted(MANIFEST["stages"])
SHOT = "shots/hand_wave/shot.usda"
SKINNED = "shots/hand_skinned/shot.usda"
RIGGED = "shots/hand_rigged/shot.usda"
ADJUSTED = "shots/hand_adjusted/shot.usda"
HAND_STAGES = [f"hand/{n}" for n in
               ("hand_1k4.usda", "hand_closed.usda", "hand_lowres.usda", "hand_22k.usdc", "hand_94k.usdc")]
CORPUS_STAGES = [f"corpus/{n}" for n in
                 ("fish_cc2.usda", "fish_cc3.usdc", "penguin_cc2.usda", "penguin_cc3.usdc", "fish.usdc",
                  "penguin.usda", "scorpion.usdc", "koala.usdc")]


# ----------------------------------------------------------------------------
# helpers


def checksum(points):
    """sum_i (i+1)(x_i + 2 y_i + 3 z_i) / n over float32 values widened to float64."""
    p = np.asarray(points, dtype=np.float32).astype(np.float64).reshape(-1, 3)
    if len(p) == 0:
        return 0.0
    i = np.arange(1, len(p) + 1, dtype=np.float64)
    return float(np.sum(i * (p[:, 0] + 2.0 * p[:, 1] + 3.0 * p[:, 2]))) / len(p)


def int_checksum(values):
    v = [int(x) for x in values]
    return sum((i + 1) * x for i, x in enumerate(v))


def assert_close(got, want, what):
    assert abs(got - want) <= 1e-9 * max(1.0, abs(want)), f"{what}: usd-core gives {got!r}, manifest {want!r}"


def vec3(value):
    return np.array(value, dtype=np.float32).reshape(-1, 3)


_STAGES = {}


def stage(rel):
    if rel not in _STAGES:
        s = Usd.Stage.Open(str(FIXTURES / rel))
        assert s, f"usd-core cannot open {rel}"
        _STAGES[rel] = s
    return _STAGES[rel]


def curvenet_prims(s):
    return sorted(str(p.GetPath()) for p in s.Traverse() if p.HasAttribute("primvars:curvenet:cv"))


def deformed_meshes(s):
    return sorted(str(p.GetPath()) for p in s.Traverse()
                  if p.IsA(UsdGeom.Mesh) and p.GetRelationship("curvenet:curvenets"))


def pool_primvar(prim):
    pv = UsdGeom.PrimvarsAPI(prim).GetPrimvar("curvenet:cv")
    assert pv, f"{prim.GetPath()}: no primvars:curvenet:cv"
    return pv


def valences(indices):
    val = {}
    for s in np.asarray(indices).reshape(-1, 4):
        for e in (int(s[0]), int(s[3])):
            val[e] = val.get(e, 0) + 1
    return val


def inbetween_name(ib):
    return ib.GetAttr().GetName().split(":", 1)[1]


def expected_offsets(full, inbetweens, weight):
    """UsdSkel's rule: piecewise linear in the weight between the neighbouring
    shapes, with an implicit zero shape at weight 0 and the full shape at 1."""
    keys = [(0.0, np.zeros_like(full))] + sorted(inbetweens, key=lambda k: k[0]) + [(1.0, full)]
    for (w0, o0), (w1, o1) in zip(keys, keys[1:]):
        if w0 <= weight <= w1:
            f = (weight - w0) / (w1 - w0)
            return o0.astype(np.float64) * (1.0 - f) + o1.astype(np.float64) * f
    raise AssertionError(f"weight {weight} outside [0, 1]")


# ----------------------------------------------------------------------------
# the manifest itself


def test_manifest_lists_every_composed_stage():
    assert MANIFEST["format"] == 1
    assert STAGES == sorted(["grid/grid.usda", "cylinder/cylinder.usda", SHOT, SKINNED, RIGGED, ADJUSTED,
                             "shots/hand_caged/shot.usda", "shots/hand_cage_only/shot.usda"]
                            + HAND_STAGES + CORPUS_STAGES)
    for rel in STAGES:
        assert (FIXTURES / rel).is_file(), rel


# ----------------------------------------------------------------------------
# every stage against the manifest


@pytest.mark.parametrize("rel", STAGES)
def test_time_range(rel):
    s, want = stage(rel), MANIFEST["stages"][rel]
    if want["start"] is None:
        assert want["end"] is None
        assert not s.HasAuthoredTimeCodeRange(), f"{rel}: a time range is authored"
    else:
        assert s.HasAuthoredTimeCodeRange(), f"{rel}: no startTimeCode/endTimeCode"
        assert s.GetStartTimeCode() == want["start"]
        assert s.GetEndTimeCode() == want["end"]


@pytest.mark.parametrize("rel", STAGES)
def test_meshes(rel):
    s, want = stage(rel), MANIFEST["stages"][rel]["meshes"]
    assert deformed_meshes(s) == sorted(want)
    for path, w in want.items():
        prim = s.GetPrimAtPath(path)
        mesh = UsdGeom.Mesh(prim)
        assert prim.IsA(UsdGeom.Mesh), path
        counts = np.array(mesh.GetFaceVertexCountsAttr().Get(), dtype=np.int64)
        indices = np.array(mesh.GetFaceVertexIndicesAttr().Get(), dtype=np.int64)
        assert mesh.GetFaceVertexCountsAttr().GetNumTimeSamples() == 0, "topology is static"
        assert mesh.GetFaceVertexIndicesAttr().GetNumTimeSamples() == 0, "topology is static"
        points_attr = mesh.GetPointsAttr()
        points = vec3(points_attr.Get(Usd.TimeCode.Default()))
        assert len(points) == w["n_points"]
        assert len(counts) == w["n_faces"]
        assert len(indices) == w["n_face_vertex_indices"] == int(counts.sum())
        assert indices.min() >= 0 and indices.max() < len(points)
        assert int_checksum(indices) + int_checksum(counts) == w["topology_checksum"]
        proj = UsdGeom.PrimvarsAPI(prim).GetPrimvar("curvenet:projectionPoints")
        projection = vec3(proj.Get()) if proj and proj.HasAuthoredValue() else points
        assert_close(checksum(projection), w["projection_checksum"], f"{rel} {path} projection")
        assert_close(checksum(points), w["rest_default_checksum"], f"{rel} {path} rest default")
        times = points_attr.GetTimeSamples()
        assert [float(t) for t, _ in w["rest_samples"]] == list(times)
        for t, c in w["rest_samples"]:
            assert_close(checksum(points_attr.Get(t)), c, f"{rel} {path} rest at {t}")
        targets = prim.GetRelationship("curvenet:curvenets").GetTargets()
        assert [str(p) for p in targets] == w["curvenets"]
        for p in targets:
            assert s.GetPrimAtPath(p).IsA(UsdGeom.BasisCurves), f"{path} -> {p} is not a BasisCurves"


@pytest.mark.parametrize("rel", STAGES)
def test_curvenets(rel):
    s, want = stage(rel), MANIFEST["stages"][rel]["curvenets"]
    assert curvenet_prims(s) == sorted(want)
    for path, w in want.items():
        prim = s.GetPrimAtPath(path)
        pv = pool_primvar(prim)
        pool = vec3(pv.Get(Usd.TimeCode.Default()))  # the pool itself, not flattened
        indices = np.array(pv.GetIndices(), dtype=np.int64)
        assert len(pool) == w["n_cv"]
        assert len(indices) == 4 * w["n_splines"]
        assert int_checksum(indices) == w["indices_checksum"]
        density = prim.GetAttribute("curvenet:sampleDensity")
        assert density.GetVariability() == Sdf.VariabilityUniform
        assert density.Get() == w["sample_density"]
        assert_close(checksum(pool), w["cv_default_checksum"], f"{rel} {path} cv default")
        times = pv.GetTimeSamples()
        assert [float(t) for t, _ in w["cv_samples"]] == list(times)
        for t, c in w["cv_samples"]:
            assert_close(checksum(pv.Get(t)), c, f"{rel} {path} cv at {t}")


@pytest.mark.parametrize("rel", STAGES)
def test_curvenet_encoding_follows_the_contract(rel):
    s = stage(rel)
    for path in curvenet_prims(s):
        prim = s.GetPrimAtPath(path)
        curves = UsdGeom.BasisCurves(prim)
        assert prim.IsA(UsdGeom.BasisCurves)
        assert curves.GetTypeAttr().Get() == "cubic"
        assert curves.GetBasisAttr().Get() == "bezier"
        assert curves.GetWrapAttr().Get() == "nonperiodic"
        for attr in (curves.GetTypeAttr(), curves.GetBasisAttr(), curves.GetWrapAttr()):
            assert attr.HasAuthoredValue(), f"{path}: {attr.GetName()} must be authored"
        pv = pool_primvar(prim)
        assert pv.GetTypeName() == Sdf.ValueTypeNames.Point3fArray
        assert pv.GetInterpolation() == UsdGeom.Tokens.vertex
        assert pv.IsIndexed()
        assert pv.GetIndicesAttr().GetTypeName() == Sdf.ValueTypeNames.IntArray
        assert pv.GetIndicesAttr().GetNumTimeSamples() == 0, "indices are static"
        indices = np.array(pv.GetIndices(), dtype=np.int64)
        counts = list(curves.GetCurveVertexCountsAttr().Get())
        assert counts == [4] * (len(indices) // 4) and len(indices) % 4 == 0
        pool = vec3(pv.Get())
        assert indices.min() >= 0 and indices.max() < len(pool)
        assert sorted(set(indices.tolist())) == list(range(len(pool))), "every pool entry is used"
        # points is the expanded copy cv[indices], at the default time and at every sample
        points = curves.GetPointsAttr()
        assert list(points.GetTimeSamples()) == list(pv.GetTimeSamples())
        for t in [Usd.TimeCode.Default()] + [Usd.TimeCode(t) for t in pv.GetTimeSamples()]:
            cv = vec3(pv.Get(t))
            expanded = vec3(points.Get(t))
            np.testing.assert_array_equal(expanded, cv[indices], err_msg=f"{rel} {path} points at {t}")
            np.testing.assert_array_equal(vec3(pv.ComputeFlattened(t)), expanded)


@pytest.mark.parametrize("rel", STAGES)
def test_blend_shapes(rel):
    s, want = stage(rel), MANIFEST["stages"][rel]["meshes"]
    for path, w in want.items():
        prim = s.GetPrimAtPath(path)
        binding = UsdSkel.BindingAPI(prim)
        if not w["blend_shapes"]:
            assert not prim.HasAPI(UsdSkel.BindingAPI) or not binding.GetBlendShapesAttr().HasAuthoredValue()
            assert w["blend_shape_weights"] == []
            continue
        assert prim.HasAPI(UsdSkel.BindingAPI)
        names = list(binding.GetBlendShapesAttr().Get())
        targets = [str(p) for p in binding.GetBlendShapeTargetsRel().GetTargets()]
        assert names == [b["name"] for b in w["blend_shapes"]]
        assert targets == [b["prim"] for b in w["blend_shapes"]]
        n_points = len(UsdGeom.Mesh(prim).GetPointsAttr().Get())
        for b in w["blend_shapes"]:
            shape = UsdSkel.BlendShape(s.GetPrimAtPath(b["prim"]))
            assert shape.GetPrim().IsA(UsdSkel.BlendShape)
            offsets = vec3(shape.GetOffsetsAttr().Get())
            assert len(offsets) == b["n_offsets"]
            assert_close(checksum(offsets), b["offsets_checksum"], f"{b['prim']} offsets")
            pi_attr = shape.GetPointIndicesAttr()
            if b["point_indices_checksum"] is None:
                assert not pi_attr.HasAuthoredValue()
                assert len(offsets) == n_points
            else:
                pi = np.array(pi_attr.Get(), dtype=np.int64)
                assert int_checksum(pi) == b["point_indices_checksum"]
                assert len(pi) == len(offsets) and pi.min() >= 0 and pi.max() < n_points
                assert len(set(pi.tolist())) == len(pi)
            inbetweens = sorted(shape.GetInbetweens(), key=inbetween_name)
            assert [inbetween_name(ib) for ib in inbetweens] == [x["name"] for x in b["inbetweens"]]
            for ib, x in zip(inbetweens, b["inbetweens"]):
                assert_close(ib.GetWeight(), x["weight"], f"{b['prim']} {x['name']} weight")
                assert_close(checksum(ib.GetOffsets()), x["offsets_checksum"], f"{b['prim']} {x['name']}")


@pytest.mark.parametrize("rel", STAGES)
def test_blend_shape_weights(rel):
    s, want = stage(rel), MANIFEST["stages"][rel]["meshes"]
    for path, w in want.items():
        if not w["blend_shape_weights"]:
            continue
        binding = UsdSkel.BindingAPI(s.GetPrimAtPath(path))
        order = list(binding.GetBlendShapesAttr().Get())
        skel_targets = binding.GetSkeletonRel().GetTargets()
        assert len(skel_targets) == 1
        skel = UsdSkel.Skeleton(s.GetPrimAtPath(skel_targets[0]))
        assert skel, f"{path}: skel:skeleton does not lead to a Skeleton"
        anim_targets = UsdSkel.BindingAPI(skel.GetPrim()).GetAnimationSourceRel().GetTargets()
        assert len(anim_targets) == 1
        anim = UsdSkel.Animation(s.GetPrimAtPath(anim_targets[0]))
        assert anim, "skel:animationSource does not lead to a SkelAnimation"
        anim_order = list(anim.GetBlendShapesAttr().Get())
        attr = anim.GetBlendShapeWeightsAttr()
        assert list(attr.GetTimeSamples()) == [float(t) for t, _ in w["blend_shape_weights"]]
        for t, ws in w["blend_shape_weights"]:
            values = list(attr.Get(t))
            got = [values[anim_order.index(name)] for name in order]
            assert len(got) == len(ws)
            for g, x in zip(got, ws):
                assert_close(float(g), x, f"{rel} {path} weight at {t}")


# ----------------------------------------------------------------------------
# UsdSkel recognises the shot's setup


def test_usdskel_cache_finds_the_blend_shapes_of_the_shot():
    s = stage(SHOT)
    root = UsdSkel.Root(s.GetPrimAtPath("/Hand"))
    assert root, "/Hand must be a SkelRoot in the shot"
    cache = UsdSkel.Cache()
    assert cache.Populate(root, Usd.TraverseInstanceProxies())
    mesh = s.GetPrimAtPath("/Hand/Mesh")
    query = cache.GetSkinningQuery(mesh)
    assert query and query.HasBlendShapes()
    assert list(query.GetBlendShapeOrder()) == ["bulge"]
    skel_query = cache.GetSkelQuery(UsdSkel.Skeleton(s.GetPrimAtPath("/Hand/Skel")))
    anim_query = skel_query.GetAnimQuery()
    assert anim_query and list(anim_query.GetBlendShapeOrder()) == ["bulge"]
    want = dict((t, ws) for t, ws in MANIFEST["stages"][SHOT]["meshes"]["/Hand/Mesh"]["blend_shape_weights"])
    assert sorted(want) == list(range(1, 25))
    for t, ws in want.items():
        got = anim_query.ComputeBlendShapeWeights(Usd.TimeCode(t))
        mapper = query.GetBlendShapeMapper()
        if mapper is not None:
            got = mapper.Remap(got)
        assert [float(x) for x in got] == pytest.approx(ws, abs=0, rel=1e-9)
    bindings = cache.ComputeSkelBindings(root, Usd.TraverseInstanceProxies())
    assert [(str(b.GetSkeleton().GetPath()), len(b.GetSkinningTargets())) for b in bindings] == [("/Hand/Skel", 1)]
    # the weights rise from 0 to 1 through 0.5, and return to 0
    series = [want[t][0] for t in sorted(want)]
    assert series[0] == 0.0 and max(series) == 1.0 and 0.5 in series and series[-1] == 0.0


@pytest.mark.parametrize("weight", [0.0, 0.25, 0.5, 0.75, 1.0])
def test_blend_shape_query_interpolates_inbetweens(weight):
    s = stage(SHOT)
    mesh = s.GetPrimAtPath("/Hand/Mesh")
    shape = UsdSkel.BlendShape(s.GetPrimAtPath("/Hand/Mesh/Bulge"))
    full = vec3(shape.GetOffsetsAttr().Get())
    point_indices = np.array(shape.GetPointIndicesAttr().Get(), dtype=np.int64)
    inbetweens = [(ib.GetWeight(), vec3(ib.GetOffsets())) for ib in shape.GetInbetweens()]
    n_points = len(UsdGeom.Mesh(mesh).GetPointsAttr().Get())

    query = UsdSkel.BlendShapeQuery(UsdSkel.BindingAPI(mesh))
    # sub-shapes: the implicit zero shape at weight 0, the inbetweens and the full shape
    assert query.GetNumBlendShapes() == 1 and query.GetNumSubShapes() == 2 + len(inbetweens)
    sub_weights, blend_indices, sub_indices = query.ComputeSubShapeWeights(Vt.FloatArray([weight]))
    points = Vt.Vec3fArray(n_points)
    assert query.ComputeDeformedPoints(sub_weights, blend_indices, sub_indices,
                                       query.ComputeBlendShapePointIndices(),
                                       query.ComputeSubShapePointOffsets(), points)
    got = vec3(points).astype(np.float64)

    want = np.zeros((n_points, 3))
    want[point_indices] = expected_offsets(full, inbetweens, weight)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-7)
    # the inbetween is not half of the full shape, so interpolating through it is observable
    if 0.0 < weight < 1.0:
        linear = np.zeros((n_points, 3))
        linear[point_indices] = weight * full
        assert np.abs(got - linear).max() > 1e-4


# ----------------------------------------------------------------------------
# what the fixtures are meant to show


def test_grid_curvenet_topology_and_frames():
    s = stage("grid/grid.usda")
    pv = pool_primvar(s.GetPrimAtPath("/Grid/Curvenet"))
    val = valences(pv.GetIndices())
    assert sorted(val.values()).count(4) == 9
    assert sorted(val.values()).count(3) == 12
    assert sorted(val.values()).count(2) == 4
    neutral = vec3(pv.Get()).astype(np.float64)
    np.testing.assert_array_equal(vec3(pv.Get(1)), vec3(pv.Get()))
    # frame 2 is rigid: pairwise distances kept
    moved = vec3(pv.Get(2)).astype(np.float64)
    d0 = np.linalg.norm(neutral[:, None] - neutral[None], axis=2)
    d1 = np.linalg.norm(moved[:, None] - moved[None], axis=2)
    np.testing.assert_allclose(d1, d0, atol=1e-6)
    assert np.abs(moved - neutral).max() > 0.1
    # frame 3: the hinge folds x > 0 up to +z, leaves x <= 0 alone
    hinge = vec3(pv.Get(3)).astype(np.float64)
    left = neutral[:, 0] <= 1e-9
    np.testing.assert_array_equal(hinge[left], neutral[left])
    np.testing.assert_allclose(hinge[~left], np.stack([0 * neutral[~left, 0], neutral[~left, 1], neutral[~left, 0]], 1),
                               atol=1e-7)
    np.testing.assert_allclose(vec3(pv.Get(4)), 1.5 * neutral, atol=1e-6)
    # the mesh has vertex lines at x = 0 but not at x = 0.35
    pts = vec3(UsdGeom.Mesh(s.GetPrimAtPath("/Grid/Mesh")).GetPointsAttr().Get())
    assert np.any(np.abs(pts[:, 0]) < 1e-7) and not np.any(np.abs(pts[:, 0] - 0.35) < 1e-3)


def test_cylinder_curvenet_topology_and_twist():
    s = stage("cylinder/cylinder.usda")
    pv = pool_primvar(s.GetPrimAtPath("/Cylinder/Curvenet"))
    val = valences(pv.GetIndices())
    assert sorted(val.values()) == [3] * 8 + [4] * 12
    neutral = vec3(pv.Get()).astype(np.float64)
    for t, total in ((2, 90.0), (3, 180.0)):
        posed = vec3(pv.Get(t)).astype(np.float64)
        np.testing.assert_allclose(posed[:, 2], neutral[:, 2], atol=1e-7)
        np.testing.assert_allclose(np.hypot(posed[:, 0], posed[:, 1]), np.hypot(neutral[:, 0], neutral[:, 1]), atol=1e-6)
        a0 = np.arctan2(neutral[:, 1], neutral[:, 0])
        a1 = np.arctan2(posed[:, 1], posed[:, 0])
        turn = np.degrees((a1 - a0 + np.pi) % (2 * np.pi) - np.pi) % 360.0
        want = (total * (neutral[:, 2] + 0.9) / 1.8) % 360.0
        diff = np.abs((turn - want + 180.0) % 360.0 - 180.0)
        assert diff.max() < 1e-3
    # outward faces: the signed volume of the closed mesh is positive (close to pi r^2 h)
    mesh = UsdGeom.Mesh(s.GetPrimAtPath("/Cylinder/Mesh"))
    assert signed_volume(mesh) == pytest.approx(math.pi * 0.25 * 2.0, rel=0.01)


def signed_volume(mesh):
    pts = vec3(mesh.GetPointsAttr().Get()).astype(np.float64)
    counts = list(mesh.GetFaceVertexCountsAttr().Get())
    idx = list(mesh.GetFaceVertexIndicesAttr().Get())
    vol, k = 0.0, 0
    for c in counts:
        f = idx[k:k + c]
        k += c
        for j in range(1, c - 1):
            vol += np.dot(pts[f[0]], np.cross(pts[f[j]], pts[f[j + 1]])) / 6.0
    return vol


@pytest.mark.parametrize("rel", HAND_STAGES)
def test_hand_stages_reference_the_shared_curvenet(rel):
    s = stage(rel)
    layer_prim = s.GetRootLayer().GetPrimAtPath("/Hand/Curvenet")
    refs = layer_prim.referenceList.GetAddedOrExplicitItems()
    assert [r.assetPath for r in refs] == ["./curvenet.usda"]
    assert not layer_prim.attributes, "the curvenet's data comes from the reference only"
    prim = s.GetPrimAtPath("/Hand/Curvenet")
    assert prim.GetTypeName() == "BasisCurves"
    shared = Usd.Stage.Open(str(FIXTURES / "hand" / "curvenet.usda"))
    assert shared.GetDefaultPrim().GetPath() == Sdf.Path("/Curvenet")
    np.testing.assert_array_equal(vec3(pool_primvar(prim).Get()),
                                  vec3(pool_primvar(shared.GetDefaultPrim()).Get()))
    assert "CC BY 4.0" in s.GetRootLayer().documentation


def test_hand_curvenet_has_rings_lines_anchors_and_junctions():
    s = stage("hand/hand_closed.usda")
    pv = pool_primvar(s.GetPrimAtPath("/Hand/Curvenet"))
    indices = np.array(pv.GetIndices()).reshape(-1, 4)
    assert 40 <= len(indices) <= 120
    val = valences(indices)
    assert sum(v == 1 for v in val.values()) >= 1, "an anchor"
    assert sum(v == 3 for v in val.values()) >= 1, "a T-junction"
    assert sum(v >= 4 for v in val.values()) >= 5, "intersections"
    # an isolated closed ring: a connected component whose knots all have valence 2
    parent = {k: k for k in val}

    def find(k):
        while parent[k] != k:
            parent[k] = parent[parent[k]]
            k = parent[k]
        return k

    for sp in indices:
        parent[find(int(sp[0]))] = find(int(sp[3]))
    comps = {}
    for k in val:
        comps.setdefault(find(k), []).append(k)
    assert any(all(val[k] == 2 for k in c) for c in comps.values()), "an isolated closed ring"
    # the knots lie on the surface (within 0.5% of the diagonal of hand_closed): vertex distance is an upper bound
    pts = vec3(UsdGeom.Mesh(s.GetPrimAtPath("/Hand/Mesh")).GetPointsAttr().Get()).astype(np.float64)
    diag = np.linalg.norm(pts.max(0) - pts.min(0))
    cv = vec3(pv.Get()).astype(np.float64)
    knots = cv[sorted(val)]
    nearest = np.sqrt(((knots[:, None, :] - pts[None, :, :]) ** 2).sum(2)).min(1)
    assert nearest.max() < 0.02 * diag  # vertex spacing ~1% of the diagonal; the exact check is in generate.py


def test_shot_curls_only_the_index_finger():
    s = stage(SHOT)
    pv = pool_primvar(s.GetPrimAtPath("/Hand/Curvenet"))
    neutral = vec3(pv.Get()).astype(np.float64)
    np.testing.assert_array_equal(vec3(pv.Get(1)), vec3(pv.Get()))
    np.testing.assert_array_equal(vec3(pv.Get(24)), vec3(pv.Get()))
    peak = vec3(pv.Get(13)).astype(np.float64)
    moved = np.linalg.norm(peak - neutral, axis=1) > 1e-6
    assert 10 < moved.sum() < len(neutral) / 3
    # the moving points are around x ~ -0.12 (the index finger), and move towards the palm (+z)
    assert np.all(np.abs(neutral[moved, 0] + 0.12) < 0.08)
    assert np.mean(peak[moved, 2] - neutral[moved, 2]) > 0.05
    # layers: anim.usda holds only `over` prims at its root
    anim = Sdf.Layer.FindOrOpen(str(FIXTURES / "shots/hand_wave/anim.usda"))
    assert [p.specifier for p in anim.rootPrims] == [Sdf.SpecifierOver]
    assert list(s.GetRootLayer().subLayerPaths) == ["./anim.usda", "../../hand/hand_1k4.usda"]
    assert s.GetFramesPerSecond() == 24


@pytest.mark.parametrize("rel", STAGES)
def test_adjustments(rel):
    """CurvenetAdjustment prims (schema/README.md) as the manifest says: children of
    their curvenet, a static knot that is a spline endpoint, the knot's tangents by the
    contract's rule (recomputed here from the composed indices), one rotate at most,
    and every value and time sample."""
    s, want = stage(rel), MANIFEST["stages"][rel].get("adjustments", {})
    found = sorted(str(p.GetPath()) for p in s.Traverse() if p.GetTypeName() == "CurvenetAdjustment")
    assert found == sorted(want)
    for path, w in want.items():
        prim = s.GetPrimAtPath(path)
        assert str(prim.GetParent().GetPath()) == w["curvenet"]
        knot = prim.GetAttribute("curvenet:knot")
        assert knot.GetVariability() == Sdf.VariabilityUniform and knot.GetNumTimeSamples() == 0
        assert knot.Get() == w["knot"]
        attach = prim.GetAttribute("curvenet:attachTangents")
        assert (attach.Get() if attach and attach.HasAuthoredValue() else True) == w["attach_tangents"]
        indices = np.asarray(pool_primvar(s.GetPrimAtPath(w["curvenet"])).GetIndices()).reshape(-1, 4)
        val = valences(indices)
        assert val[w["knot"]] == w["valence"]
        tangents = sorted({int(h) for sp in indices for e, h in ((sp[0], sp[1]), (sp[3], sp[2]))
                           if int(e) == w["knot"] and int(h) != int(e) and int(h) not in val})
        assert tangents == w["tangents"], path
        rotates = [n for n in ("xformOp:rotateXYZ", "xformOp:orient") if prim.GetAttribute(n).HasAuthoredValue()]
        assert rotates == ([w["rotate"]] if w["rotate"] else [])
        for name, samples in w["values"].items():
            attr = prim.GetAttribute(name)
            assert [float(t) for t in attr.GetTimeSamples()] == [t for t, _ in samples if t is not None], name
            for t, value in samples:
                got = attr.Get(Usd.TimeCode.Default() if t is None else t)
                if isinstance(got, (Gf.Quatf, Gf.Quatd)):
                    got = [got.GetReal(), *got.GetImaginary()]
                got = np.asarray(got, dtype=np.float64).ravel()
                assert np.array_equal(got, np.asarray(value, dtype=np.float64).ravel()), f"{path} {name} at {t}"


def test_adjusted_shot_layers_adjustments_over_the_skinned_shot():
    s = stage(ADJUSTED)
    assert list(s.GetRootLayer().subLayerPaths) == ["./adjust.usda", "../hand_skinned/shot.usda"]
    layer = Sdf.Layer.FindOrOpen(str(FIXTURES / "shots/hand_adjusted/adjust.usda"))
    # only opinions on existing prims and the new adjustment prims
    for path in ("/Hand", "/Hand/Curvenet"):
        assert layer.GetPrimAtPath(path).specifier == Sdf.SpecifierOver
    # the curvenet is not articulated: it tracks the skinned rest pose
    assert pool_primvar(s.GetPrimAtPath("/Hand/Curvenet")).GetTimeSamples() == []
    # at frame 1 every adjustment is the identity
    for prim in s.GetPrimAtPath("/Hand/Curvenet").GetChildren():
        orient = prim.GetAttribute("xformOp:orient")
        if orient and orient.HasAuthoredValue():
            assert orient.Get(1) == Gf.Quatf(1.0), prim.GetPath()
        for name in ("xformOp:translate", "xformOp:rotateXYZ", "curvenet:tangentTranslates"):
            attr = prim.GetAttribute(name)
            if attr and attr.GetNumTimeSamples():
                assert not np.asarray(attr.Get(1), dtype=np.float64).any(), f"{prim.GetPath()} {name}"
        scale = prim.GetAttribute("xformOp:scale")
        if scale and scale.HasAuthoredValue():
            assert tuple(scale.Get(1)) == (1.0, 1.0, 1.0)


# ----------------------------------------------------------------------------
# the skinned shot: the rest pose is baked linear blend skinning


SKIN_FRAMES = list(range(1, 13))


def skin_rig():
    """skel.usda composed over the hand asset, in memory (the shot does not sublayer it)."""
    if "rig" not in _STAGES:
        layer = Sdf.Layer.CreateAnonymous(".usda")
        layer.subLayerPaths = [str(FIXTURES / "shots/hand_skinned/skel.usda"), str(FIXTURES / "hand/hand_1k4.usda")]
        _STAGES["rig"] = Usd.Stage.Open(layer)
    return _STAGES["rig"]


def skin_queries():
    rig = skin_rig()
    cache = UsdSkel.Cache()
    root = UsdSkel.Root(rig.GetPrimAtPath("/Hand"))
    assert root and cache.Populate(root, Usd.PrimDefaultPredicate)
    skel_query = cache.GetSkelQuery(UsdSkel.Skeleton(rig.GetPrimAtPath("/Hand/Skel")))
    skinning = cache.GetSkinningQuery(rig.GetPrimAtPath("/Hand/Mesh"))
    assert skel_query and skinning and skinning.HasJointInfluences()
    return skel_query, skinning


def quat_matrix(q):
    """3x3 rotation (acting on column vectors) of a unit Gf quaternion."""
    w, (x, y, z) = q.GetReal(), q.GetImaginary()
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]], dtype=np.float64)


def quat_angle(q):
    return math.degrees(2.0 * math.atan2(float(np.linalg.norm(list(q.GetImaginary()))), q.GetReal()))


def neutral_hand():
    return vec3(UsdGeom.Mesh(stage("hand/hand_1k4.usda").GetPrimAtPath("/Hand/Mesh")).GetPointsAttr().Get())


def skinned_rest(t):
    return vec3(UsdGeom.Mesh(stage(SKINNED).GetPrimAtPath("/Hand/Mesh")).GetPointsAttr().Get(t))


def joint_positions():
    skel = UsdSkel.Skeleton(skin_rig().GetPrimAtPath("/Hand/Skel"))
    names = list(skel.GetJointsAttr().Get())
    return {n.split("/")[-1]: np.array(m.ExtractTranslation(), dtype=np.float64)
            for n, m in zip(names, skel.GetBindTransformsAttr().Get())}


def test_skinned_shot_layers_bake_the_skinning_without_binding_it():
    s = stage(SKINNED)
    assert list(s.GetRootLayer().subLayerPaths) == ["./rest.usda", "../../hand/hand_1k4.usda"]
    assert s.GetFramesPerSecond() == 24 and s.GetTimeCodesPerSecond() == 24
    assert UsdGeom.GetStageUpAxis(s) == UsdGeom.Tokens.y
    assert not any(p.endswith("skel.usda") for p in [l.identifier for l in s.GetLayerStack()])
    # the rest layer: `over` opinions on /Hand/Mesh only, no UsdSkel data
    rest = Sdf.Layer.FindOrOpen(str(FIXTURES / "shots/hand_skinned/rest.usda"))
    specs = []
    rest.Traverse(Sdf.Path.absoluteRootPath, lambda p: specs.append(p) if p.IsPrimPath() else None)
    assert sorted(str(p) for p in specs) == ["/Hand", "/Hand/Mesh"]
    for p in specs:
        spec = rest.GetPrimAtPath(p)
        assert spec.specifier == Sdf.SpecifierOver and spec.typeName == "", p
    mesh_spec = rest.GetPrimAtPath("/Hand/Mesh")
    assert sorted(mesh_spec.attributes.keys()) == ["extent", "points", "primvars:curvenet:projectionPoints"]
    assert not mesh_spec.relationships and not mesh_spec.GetInfo("apiSchemas").GetAddedOrExplicitItems()
    # nothing in the composed shot would skin the mesh a second time
    assert not any(p.IsA(UsdSkel.Skeleton) or p.IsA(UsdSkel.Root) or p.IsA(UsdSkel.Animation) for p in s.Traverse())
    mesh = s.GetPrimAtPath("/Hand/Mesh")
    assert not mesh.HasAPI(UsdSkel.BindingAPI)
    assert not [a.GetName() for a in mesh.GetAttributes() if a.GetName().startswith(("skel:", "primvars:skel:"))]
    # the curvenet is not articulated: it tracks the rest pose
    assert pool_primvar(s.GetPrimAtPath("/Hand/Curvenet")).GetTimeSamples() == []
    assert list(UsdGeom.Mesh(mesh).GetPointsAttr().GetTimeSamples()) == [float(t) for t in SKIN_FRAMES]


def test_skinned_shot_projection_pose_is_the_neutral_hand():
    prim = stage(SKINNED).GetPrimAtPath("/Hand/Mesh")
    pv = UsdGeom.PrimvarsAPI(prim).GetPrimvar("curvenet:projectionPoints")
    assert pv and pv.HasAuthoredValue()
    assert pv.GetTypeName() == Sdf.ValueTypeNames.Point3fArray
    assert pv.GetInterpolation() == UsdGeom.Tokens.vertex
    assert pv.GetAttr().GetNumTimeSamples() == 0, "the projection pose is static"
    np.testing.assert_array_equal(vec3(pv.Get()), neutral_hand())
    # and so is the points default: only the time samples are the skinned rest pose
    np.testing.assert_array_equal(vec3(UsdGeom.Mesh(prim).GetPointsAttr().Get(Usd.TimeCode.Default())), neutral_hand())


def test_skinned_rig_weights():
    binding = UsdSkel.BindingAPI(skin_rig().GetPrimAtPath("/Hand/Mesh"))
    indices_pv, weights_pv = binding.GetJointIndicesPrimvar(), binding.GetJointWeightsPrimvar()
    assert indices_pv.GetElementSize() == weights_pv.GetElementSize() == 4
    assert indices_pv.GetInterpolation() == weights_pv.GetInterpolation() == UsdGeom.Tokens.vertex
    idx = np.array(indices_pv.Get(), dtype=np.int64).reshape(-1, 4)
    w = np.array(weights_pv.Get(), dtype=np.float64).reshape(-1, 4)
    assert len(idx) == len(neutral_hand())
    assert idx.min() >= 0 and idx.max() < 4 and w.min() >= 0.0
    np.testing.assert_allclose(w.sum(axis=1), 1.0, rtol=0, atol=1e-6)
    # every joint drives some vertices; most of the hand follows the wrist alone
    for j in range(4):
        assert np.any((idx == j) & (w > 0.5)), f"joint {j} drives no vertex"
    wrist_only = np.all((idx == 0) | (w == 0.0), axis=1)
    assert 0.7 * len(idx) < wrist_only.sum() < len(idx)
    assert UsdSkel.BindingAPI(skin_rig().GetPrimAtPath("/Hand/Mesh")).GetSkinningMethodAttr().Get() == "classicLinear"


def test_skinned_rig_animation():
    skel = UsdSkel.Skeleton(skin_rig().GetPrimAtPath("/Hand/Skel"))
    assert list(skel.GetJointsAttr().Get()) == ["wrist", "wrist/index_mcp", "wrist/index_mcp/index_pip",
                                                 "wrist/index_mcp/index_pip/index_dip"]
    anim = UsdSkel.Animation(skin_rig().GetPrimAtPath("/Hand/Skel/Anim"))
    rot = anim.GetRotationsAttr()
    assert list(rot.GetTimeSamples()) == [float(t) for t in SKIN_FRAMES]
    assert [quat_angle(q) for q in rot.Get(1)] == [0.0] * 4
    wrist, mcp, pip, dip = rot.Get(12)
    assert quat_angle(wrist) == pytest.approx(15.0, abs=1e-4)
    np.testing.assert_allclose(list(wrist.GetImaginary().GetNormalized()), [0, 0, 1], atol=1e-6)
    assert quat_angle(mcp) == pytest.approx(50.0, abs=1e-4)
    assert quat_angle(pip) == pytest.approx(40.0, abs=1e-4)
    assert 0.0 < quat_angle(dip) < 40.0
    # the angles rise monotonically
    for k in range(4):
        series = [quat_angle(rot.Get(t)[k]) for t in SKIN_FRAMES]
        assert all(b > a for a, b in zip(series, series[1:]))
    # the joints lie on the index finger's axis, in order from the wrist
    j = joint_positions()
    assert j["wrist"][1] < 0.15 < 0.5 < j["index_mcp"][1] < j["index_pip"][1] < j["index_dip"][1] < 0.9
    axis = (j["index_dip"] - j["index_mcp"]) / np.linalg.norm(j["index_dip"] - j["index_mcp"])
    off = (j["index_pip"] - j["index_mcp"]) - axis * np.dot(j["index_pip"] - j["index_mcp"], axis)
    assert np.linalg.norm(off) < 1e-3
    # the finger bends towards the palm (+z)
    tip = int(np.argmax(neutral_hand()[:, 1] - 10.0 * np.abs(neutral_hand()[:, 0] - j["index_dip"][0])))
    assert skinned_rest(12)[tip, 2] - neutral_hand()[tip, 2] > 0.15


@pytest.mark.parametrize("frame", [1, 6, 12])
def test_skinned_rest_pose_is_the_rig_skinned_by_usdskel(frame):
    skel_query, skinning = skin_queries()
    xforms = skel_query.ComputeSkinningTransforms(frame)
    points = Vt.Vec3fArray(list(map(tuple, neutral_hand().tolist())))
    assert skinning.ComputeSkinnedPoints(xforms, points, frame)
    rest = skinned_rest(frame).astype(np.float64)
    np.testing.assert_allclose(vec3(points).astype(np.float64), rest, rtol=0, atol=1e-6)
    # the same, as plain linear blend skinning: p' = sum_k w_k (p M_k), row vectors
    binding = UsdSkel.BindingAPI(skin_rig().GetPrimAtPath("/Hand/Mesh"))
    idx = np.array(binding.GetJointIndicesPrimvar().Get(), dtype=np.int64).reshape(-1, 4)
    w = np.array(binding.GetJointWeightsPrimvar().Get(), dtype=np.float64).reshape(-1, 4)
    M = np.array([np.array(m, dtype=np.float64).reshape(4, 4) for m in xforms])
    p = np.hstack([neutral_hand().astype(np.float64), np.ones((len(idx), 1))])
    lbs = np.zeros((len(idx), 3))
    for k in range(4):
        lbs += w[:, k:k + 1] * np.einsum("ni,nij->nj", p, M[idx[:, k]])[:, :3]
    np.testing.assert_allclose(lbs, rest, rtol=0, atol=1e-6)


def test_skinned_frame_1_is_the_neutral_hand():
    np.testing.assert_allclose(skinned_rest(1).astype(np.float64), neutral_hand().astype(np.float64), rtol=0, atol=1e-6)


def test_skinned_hand_away_from_the_finger_turns_rigidly_about_the_wrist():
    j = joint_positions()
    p0 = neutral_hand().astype(np.float64)
    axis = (j["index_dip"] - j["index_mcp"]) / np.linalg.norm(j["index_dip"] - j["index_mcp"])
    a, b = j["index_mcp"] - 0.05 * axis, j["index_dip"] + 0.12 * axis  # the finger, knuckle to tip
    f = np.clip((p0 - a) @ (b - a) / np.dot(b - a, b - a), 0.0, 1.0)
    from_finger = np.linalg.norm(p0 - (a + f[:, None] * (b - a)), axis=1)
    far = (from_finger > 0.1) & (np.linalg.norm(p0 - j["wrist"], axis=1) > 0.1)
    assert far.sum() > 0.6 * len(p0)
    anim = UsdSkel.Animation(skin_rig().GetPrimAtPath("/Hand/Skel/Anim"))
    diag = np.linalg.norm(p0.max(0) - p0.min(0))
    for t in SKIN_FRAMES:
        R = quat_matrix(anim.GetRotationsAttr().Get(t)[0])
        want = (p0 - j["wrist"]) @ R.T + j["wrist"]
        got = skinned_rest(t).astype(np.float64)
        np.testing.assert_allclose(got[far], want[far], rtol=0, atol=1e-6, err_msg=f"frame {t}")
        if t == SKIN_FRAMES[-1]:
            # the turn is visible, and the finger does more than turn
            assert np.linalg.norm(got[far] - p0[far], axis=1).max() > 0.1 * diag
            assert np.linalg.norm(got[~far] - want[~far], axis=1).max() > 0.2 * diag


# ----------------------------------------------------------------------------
# the rigged shot: the skeleton is bound in the shot and usd-core skins it


def rigged_queries(rel):
    s = stage(rel)
    cache = UsdSkel.Cache()
    root = UsdSkel.Root(s.GetPrimAtPath("/Hand"))
    assert root and cache.Populate(root, Usd.PrimDefaultPredicate)
    skel_query = cache.GetSkelQuery(UsdSkel.Skeleton(s.GetPrimAtPath("/Hand/Skel")))
    skinning = cache.GetSkinningQuery(s.GetPrimAtPath("/Hand/Mesh"))
    assert skel_query and skinning and skinning.HasJointInfluences() and skinning.HasBlendShapes()
    return skel_query, skinning


def usdskel_reference(prim, t):
    layer = Usd.Stage.Open(str(FIXTURES / "shots/hand_rigged/usdskel.usdc"))
    return vec3(layer.GetPrimAtPath(prim).GetAttribute("points").Get(t))


def test_rigged_shot_binds_its_skeleton_and_replaces_the_curvenet():
    s = stage(RIGGED)
    mesh = s.GetPrimAtPath("/Hand/Mesh")
    assert UsdGeom.Mesh(mesh).GetPointsAttr().GetTimeSamples() == [], "the rest pose is the skinning"
    assert not s.GetPrimAtPath("/Hand/Curvenet").IsActive()
    skel_query, skinning = rigged_queries(RIGGED)
    assert skinning.GetSkinningMethod() == "classicLinear"
    assert skinning.GetNumInfluencesPerComponent() == 4
    assert [j.split("/")[-1] for j in skel_query.GetJointOrder()] == [
        "wrist", "palm", "index_mcp", "index_pip", "index_dip", "middle_mcp", "middle_pip", "middle_dip"]
    assert rigged_queries("shots/hand_rigged/dqs.usda")[1].GetSkinningMethod() == "dualQuaternion"
    nets = [str(p) for p in mesh.GetRelationship("curvenet:curvenets").GetTargets()]
    assert nets == ["/Hand/IndexNet", "/Hand/MiddleNet", "/Hand/PalmNet"]
    pools = [set(map(tuple, vec3(pool_primvar(s.GetPrimAtPath(p)).Get()).tolist())) for p in nets]
    assert not (pools[0] & pools[1] or pools[0] & pools[2] or pools[1] & pools[2]), "the curvenets share points"
    middle = s.GetPrimAtPath("/Hand/MiddleNet")
    assert middle.GetAttribute("curvenet:skinning").Get() == "mesh"
    assert middle.GetAttribute("curvenet:skinning").GetVariability() == Sdf.VariabilityUniform
    for p in ("/Hand/MiddleNet", "/Hand/PalmNet"):
        assert not s.GetPrimAtPath(p).HasAttribute("primvars:curvenet:skel:jointIndices")
    assert not s.GetPrimAtPath("/Hand/PalmNet").HasAttribute("curvenet:skinning")


def test_rigged_index_net_weights_are_per_control_point():
    prim = stage(RIGGED).GetPrimAtPath("/Hand/IndexNet")
    pv = UsdGeom.PrimvarsAPI(prim)
    idx_pv, w_pv = pv.GetPrimvar("curvenet:skel:jointIndices"), pv.GetPrimvar("curvenet:skel:jointWeights")
    assert idx_pv.GetElementSize() == w_pv.GetElementSize() == 4
    assert idx_pv.GetInterpolation() == w_pv.GetInterpolation() == UsdGeom.Tokens.vertex
    n = len(pool_primvar(prim).Get())
    idx = np.array(idx_pv.Get(), dtype=np.int64).reshape(-1, 4)
    w = np.array(w_pv.Get(), dtype=np.float64).reshape(-1, 4)
    assert len(idx) == len(w) == n
    assert idx.min() >= 0 and idx.max() < 8 and w.min() >= 0.0
    np.testing.assert_allclose(w.sum(axis=1), 1.0, rtol=0, atol=1e-6)
    # the finger's rings follow the index joints; the base ring blends with the palm
    finger = (w * (np.isin(idx, [2, 3, 4]) & (w > 0.0))).sum(axis=1)
    palm = (w * (idx == 1)).sum(axis=1)
    assert finger.max() > 0.99 and finger.min() > 0.5
    assert np.any((palm > 0.01) & (finger > 0.5)), "no control point blends the finger with the palm"


@pytest.mark.parametrize("frame", [1, 6, 12])
def test_rigged_reference_is_usd_cores_skinning_after_the_blend_shape(frame):
    """usdskel.usdc (BakeSkinning) = the blend shape on the bind pose, then
    SkinningQuery.ComputeSkinnedPoints, for both methods."""
    for rel, prim in ((RIGGED, "/LBS"), ("shots/hand_rigged/dqs.usda", "/DQS")):
        skel_query, skinning = rigged_queries(rel)
        mesh = stage(rel).GetPrimAtPath("/Hand/Mesh")
        points = Vt.Vec3fArray(UsdGeom.Mesh(mesh).GetPointsAttr().Get())
        bs_query = UsdSkel.BlendShapeQuery(UsdSkel.BindingAPI(mesh))
        weights = skel_query.GetAnimQuery().ComputeBlendShapeWeights(frame)
        sub_weights, bs_indices, sub_indices = bs_query.ComputeSubShapeWeights(
            skinning.GetBlendShapeMapper().Remap(weights) if skinning.GetBlendShapeMapper() else weights)
        bs_query.ComputeDeformedPoints(sub_weights, bs_indices, sub_indices,
                                       bs_query.ComputeBlendShapePointIndices(),
                                       bs_query.ComputeSubShapePointOffsets(), points)
        assert skinning.ComputeSkinnedPoints(skel_query.ComputeSkinningTransforms(frame), points, frame)
        np.testing.assert_allclose(vec3(points).astype(np.float64), usdskel_reference(prim, frame).astype(np.float64),
                                   rtol=0, atol=1e-6, err_msg=f"{rel} frame {frame}")
    lbs, dqs = usdskel_reference("/LBS", frame), usdskel_reference("/DQS", frame)
    diff = float(np.abs(lbs.astype(np.float64) - dqs).max())
    if frame == 1:
        np.testing.assert_allclose(lbs.astype(np.float64), neutral_hand().astype(np.float64), rtol=0, atol=1e-6)
    else:
        assert diff > 1e-4, "dual quaternions should differ from linear blending"


# ----------------------------------------------------------------------------
# the caged shots: a coarse cage around the hand, with and without the skeleton

CAGED = "shots/hand_caged/shot.usda"
CAGE_ONLY = "shots/hand_cage_only/shot.usda"
CAGE_STAGES = [rel for rel in STAGES if MANIFEST["stages"][rel].get("cages")]
CAGE_CLEARANCE = 0.01  # fixtures/README.md: every hand vertex is at least this far inside the cage


def cage_of(rel):
    """(mesh prim, cage prim, points default, triangles) of the one cage of a stage."""
    s = stage(rel)
    (path, want), = MANIFEST["stages"][rel]["cages"].items()
    mesh = s.GetPrimAtPath(want["mesh"])
    targets = [str(p) for p in mesh.GetRelationship("curvenet:cage").GetTargets()]
    assert targets == [path], f"{rel}: {want['mesh']}.curvenet:cage targets {targets}"
    cage = s.GetPrimAtPath(path)
    assert cage.IsA(UsdGeom.Mesh), f"{path} is not a Mesh"
    geom = UsdGeom.Mesh(cage)
    counts = np.array(geom.GetFaceVertexCountsAttr().Get(), dtype=np.int64)
    assert np.all(counts == 3), f"{path}: faces {np.nonzero(counts != 3)[0][:5]} are not triangles"
    tris = np.array(geom.GetFaceVertexIndicesAttr().Get(), dtype=np.int64).reshape(-1, 3)
    return mesh, cage, vec3(geom.GetPointsAttr().Get(Usd.TimeCode.Default())).astype(np.float64), tris


def solid_angle_winding(points, tris, q):
    """Generalised winding number of each query point q w.r.t. a triangle mesh (Van Oosterom-Strackee)."""
    w = np.zeros(len(q))
    for t in tris:
        a, b, c = (points[i] - q for i in t)
        la, lb, lc = (np.linalg.norm(x, axis=1) for x in (a, b, c))
        det = np.einsum("ij,ij->i", a, np.cross(b, c))
        den = (la * lb * lc + np.einsum("ij,ij->i", a, b) * lc + np.einsum("ij,ij->i", b, c) * la
               + np.einsum("ij,ij->i", c, a) * lb)
        w += 2.0 * np.arctan2(det, den)
    return w / (4.0 * math.pi)


def distance_to_triangles(points, tris, q):
    """Distance from each q to the nearest triangle: the plane when the projection falls
    inside, else the nearest edge segment."""
    best = np.full(len(q), np.inf)
    for t in tris:
        a, b, c = (points[i] for i in t)
        n = np.cross(b - a, c - a)
        n /= np.linalg.norm(n)
        h = (q - a) @ n
        proj = q - h[:, None] * n
        inside = np.ones(len(q), dtype=bool)
        for u, v in ((a, b), (b, c), (c, a)):
            inside &= np.cross(v - u, proj - u) @ n >= 0.0
        d = np.where(inside, np.abs(h), np.inf)
        for u, v in ((a, b), (b, c), (c, a)):
            s = np.clip((q - u) @ (v - u) / ((v - u) @ (v - u)), 0.0, 1.0)
            d = np.minimum(d, np.linalg.norm(q - (u + s[:, None] * (v - u)), axis=1))
        best = np.minimum(best, d)
    return best


def test_cage_stages_are_the_caged_shots():
    assert CAGE_STAGES == sorted([CAGED, CAGE_ONLY])


@pytest.mark.parametrize("rel", CAGE_STAGES)
def test_cages_match_the_manifest(rel):
    s = stage(rel)
    (path, want), = MANIFEST["stages"][rel]["cages"].items()
    mesh, cage, points, tris = cage_of(rel)
    assert len(points) == want["n_points"] and len(tris) == want["n_triangles"]
    assert 100 <= len(points) <= 300
    assert int_checksum(tris.ravel()) == want["indices_checksum"]
    assert tris.min() >= 0 and tris.max() < len(points)
    geom = UsdGeom.Mesh(cage)
    assert geom.GetFaceVertexIndicesAttr().GetNumTimeSamples() == 0, "the cage's topology is static"
    assert geom.GetPurposeAttr().Get() == UsdGeom.Tokens.guide
    assert_close(checksum(points), want["rest_default_checksum"], f"{rel} {path} rest default")
    attr = geom.GetPointsAttr()
    assert [float(t) for t, _ in want["rest_samples"]] == list(attr.GetTimeSamples())
    for t, c in want["rest_samples"]:
        p = vec3(attr.Get(t))
        assert len(p) == len(points), f"{path} has {len(p)} points at {t}"
        assert_close(checksum(p), c, f"{rel} {path} rest at {t}")
    pv = UsdGeom.PrimvarsAPI(cage).GetPrimvar("curvenet:posedCageOffsets")
    if want["posed_offset_samples"]:
        assert pv.GetTypeName() == Sdf.ValueTypeNames.Point3fArray
        assert pv.GetInterpolation() == UsdGeom.Tokens.vertex
        assert [float(t) for t, _ in want["posed_offset_samples"]] == list(pv.GetAttr().GetTimeSamples())
        for t, c in want["posed_offset_samples"]:
            o = vec3(pv.Get(t))
            assert len(o) == len(points), f"{path} has {len(o)} offsets at {t}"
            assert_close(checksum(o), c, f"{rel} {path} posed offsets at {t}")
    else:
        assert not pv
    method = mesh.GetAttribute("curvenet:skinningMethod")
    if want["skinning_method"] is None:
        assert not method.HasAuthoredValue()
    else:
        assert method.GetVariability() == Sdf.VariabilityUniform
        assert method.GetTypeName() == Sdf.ValueTypeNames.Token
        assert method.Get() == want["skinning_method"]
    skel = UsdSkel.BindingAPI(mesh).GetSkeletonRel().GetTargets() if mesh.HasAPI(UsdSkel.BindingAPI) else []
    if want["n_joints"]:
        (skel_path,) = skel
        assert len(UsdSkel.Skeleton(s.GetPrimAtPath(skel_path)).GetJointsAttr().Get()) == want["n_joints"]
    else:
        assert not skel and not mesh.HasAttribute("primvars:skel:jointIndices")
        assert not any(p.IsA(UsdSkel.Skeleton) or p.IsA(UsdSkel.Root) for p in s.Traverse())


@pytest.mark.parametrize("rel", CAGE_STAGES)
def test_cage_is_closed_manifold_and_outward(rel):
    _, cage, points, tris = cage_of(rel)
    directed = {}
    for f, t in enumerate(tris.tolist()):
        assert len(set(t)) == 3, f"triangle {f} repeats a vertex"
        for e in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0])):
            assert e not in directed, f"edge {e} is used twice in one direction"
            directed[e] = f
    assert all((v, u) in directed for u, v in directed), "a boundary edge: the cage is not closed"
    for v in range(len(points)):  # one fan of triangles around every vertex
        ring = {t[(t.index(v) + 1) % 3]: t[(t.index(v) + 2) % 3] for t in tris.tolist() if v in t}
        start, at, n = next(iter(ring)), None, 0
        at = start
        while True:
            at, n = ring[at], n + 1
            if at == start:
                break
        assert n == len(ring), f"vertex {v} is not manifold"
    assert len(points) - len(directed) // 2 + len(tris) == 2, "not a sphere"
    # outward: positive signed volume at the default and at every rest-cage edit
    attr = UsdGeom.Mesh(cage).GetPointsAttr()
    for t in [Usd.TimeCode.Default()] + list(attr.GetTimeSamples()):
        p = vec3(attr.Get(t)).astype(np.float64)
        a, b, c = p[tris[:, 0]], p[tris[:, 1]], p[tris[:, 2]]
        assert np.einsum("ij,ij->", a, np.cross(b, c)) / 6.0 > 0.0, f"inside out at {t}"


@pytest.mark.parametrize("rel", CAGE_STAGES)
def test_cage_encloses_the_mesh_with_a_margin(rel):
    mesh, _, points, tris = cage_of(rel)
    hand = vec3(UsdGeom.Mesh(mesh).GetPointsAttr().Get(Usd.TimeCode.Default())).astype(np.float64)
    w = solid_angle_winding(points, tris, hand)
    assert np.abs(w - 1.0).max() < 1e-6, f"vertex {int(np.argmax(np.abs(w - 1.0)))} is not inside the cage"
    d = distance_to_triangles(points, tris, hand)
    assert d.min() >= CAGE_CLEARANCE, f"vertex {int(np.argmin(d))} is {d.min():.4f} from the cage"
    # a point outside is seen as outside (the winding test can fail)
    assert abs(solid_angle_winding(points, tris, np.array([[5.0, 0.5, 0.0]]))[0]) < 1e-9


def test_caged_shot_edits_rest_cage_pose_and_posed_cage_on_their_own_frames():
    s = stage(CAGED)
    assert list(s.GetRootLayer().subLayerPaths) == ["./cage.usda", "../../hand/hand_1k4.usda"]
    _, cage, rest0, _ = cage_of(CAGED)
    points = UsdGeom.Mesh(cage).GetPointsAttr()
    offsets = UsdGeom.PrimvarsAPI(cage).GetPrimvar("curvenet:posedCageOffsets")
    anim = UsdSkel.Animation(s.GetPrimAtPath("/Hand/Skel/Anim"))
    rest_pose = list(anim.GetRotationsAttr().Get(1))
    assert all(q == Gf.Quatf(1.0) for q in rest_pose)
    edited, posed, pushed = set(), set(), set()
    for t in range(1, 11):
        if np.abs(vec3(points.Get(t)) - rest0).max() > 1e-6:
            edited.add(t)
        if list(anim.GetRotationsAttr().Get(t)) != rest_pose:
            posed.add(t)
        if np.abs(vec3(offsets.Get(t))).max() > 1e-6:
            pushed.add(t)
    assert edited == {2, 3, 8, 10}
    assert posed == {4, 5, 8, 9, 10}
    assert pushed == {6, 7, 9, 10}
    # the full edits are those of frames 3, 5 and 7
    np.testing.assert_array_equal(vec3(points.Get(8)), vec3(points.Get(3)))
    np.testing.assert_array_equal(vec3(offsets.Get(10)), vec3(offsets.Get(7)))
    assert list(anim.GetRotationsAttr().Get(10)) == list(anim.GetRotationsAttr().Get(5))


def test_caged_shot_skeleton_and_weights_are_the_rigged_shots():
    caged, rigged = stage(CAGED), stage(RIGGED)
    for attr in ("joints", "bindTransforms", "restTransforms"):
        assert (caged.GetPrimAtPath("/Hand/Skel").GetAttribute(attr).Get()
                == rigged.GetPrimAtPath("/Hand/Skel").GetAttribute(attr).Get()), attr
    for attr in ("primvars:skel:jointIndices", "primvars:skel:jointWeights"):
        assert (caged.GetPrimAtPath("/Hand/Mesh").GetAttribute(attr).Get()
                == rigged.GetPrimAtPath("/Hand/Mesh").GetAttribute(attr).Get()), attr
    # its full pose is hand_rigged's last frame
    assert (list(caged.GetPrimAtPath("/Hand/Skel/Anim").GetAttribute("rotations").Get(5))
            == list(rigged.GetPrimAtPath("/Hand/Skel/Anim").GetAttribute("rotations").Get(12)))
    assert UsdSkel.BindingAPI(caged.GetPrimAtPath("/Hand/Mesh")).GetSkinningMethodAttr().Get() == "classicLinear"
    cache = UsdSkel.Cache()
    cache.Populate(UsdSkel.Root(caged.GetPrimAtPath("/Hand")), Usd.PrimDefaultPredicate)
    assert cache.GetSkinningQuery(caged.GetPrimAtPath("/Hand/Mesh")).HasJointInfluences()
    # UsdSkel binds the skeleton to the mesh only, never to the cage
    (binding,) = cache.ComputeSkelBindings(UsdSkel.Root(caged.GetPrimAtPath("/Hand")), Usd.PrimDefaultPredicate)
    assert [str(t.GetPrim().GetPath()) for t in binding.GetSkinningTargets()] == ["/Hand/Mesh"]


# ----------------------------------------------------------------------------
# the robustness corpus


def obj_counts(name):
    """(vertices, faces, sum of face sizes) of a vendored OBJ, read here without the generator."""
    import gzip
    v = f = corners = 0
    with gzip.open(FIXTURES / "meshes" / (name + ".obj.gz"), "rt", encoding="utf-8") as fh:
        for line in fh:
            if line.startswith("v "):
                v += 1
            elif line.startswith("f "):
                f += 1
                corners += len(line.split()) - 1
    return v, f, corners


# fixture -> (source mesh, Catmull-Clark levels, creature)
CORPUS_SOURCES = {
    "corpus/fish_cc2.usda": ("fish_control_mesh", 2, "Fish"),
    "corpus/fish_cc3.usdc": ("fish_control_mesh", 3, "Fish"),
    "corpus/penguin_cc2.usda": ("penguin_control_mesh", 2, "Penguin"),
    "corpus/penguin_cc3.usdc": ("penguin_control_mesh", 3, "Penguin"),
    "corpus/fish.usdc": ("fish", 0, "Fish"),
    "corpus/penguin.usda": ("penguin", 0, "Penguin"),
    "corpus/scorpion.usdc": ("scorpion_low_resolution", 0, "Scorpion"),
    "corpus/koala.usdc": ("koala", 0, "Koala"),
}


@pytest.mark.parametrize("rel", CORPUS_STAGES)
def test_corpus_mesh_counts_topology_and_attribution(rel):
    source, levels, creature = CORPUS_SOURCES[rel]
    s = stage(rel)
    assert s.GetDefaultPrim().GetPath() == Sdf.Path("/" + creature)
    mesh = UsdGeom.Mesh(s.GetPrimAtPath(f"/{creature}/Mesh"))
    counts = np.array(mesh.GetFaceVertexCountsAttr().Get(), dtype=np.int64)
    indices = np.array(mesh.GetFaceVertexIndicesAttr().Get(), dtype=np.int64)
    n_points = len(mesh.GetPointsAttr().Get())
    # Catmull-Clark on a closed mesh: V' = V + E + F, F' = sum of face sizes (all quads), E' = 2E + sum.
    v, f, corners = obj_counts(source)
    e = corners // 2
    for _ in range(levels):
        v, f, e, corners = v + e + f, corners, 2 * e + corners, 4 * corners
    assert (n_points, len(counts)) == (v, f)
    if levels:
        assert set(counts.tolist()) == {4}
    # closed and edge-manifold: every undirected edge in exactly two faces, once each way
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    local = np.arange(len(indices)) - np.repeat(starts, counts)
    nxt = indices[np.repeat(starts, counts) + (local + 1) % np.repeat(counts, counts)]
    directed = set(zip(indices.tolist(), nxt.tolist()))
    assert len(directed) == len(indices), "a directed edge appears twice (inconsistent orientation)"
    assert all((b, a) in directed for a, b in directed), "an edge with one face (a hole)"
    doc = s.GetRootLayer().documentation
    assert "odedstein/meshes" in doc and ("public domain" in doc or "CC BY" in doc)


def test_catmull_clark_of_a_cube():
    """One step on the cube [-1,1]^3: the rules give corner (5/9,5/9,5/9), edge (3/4,3/4,0), face (1,0,0)."""
    sys.path.insert(0, str(FIXTURES))
    from generate import catmull_clark
    pts = [(x, y, z) for x in (-1.0, 1.0) for y in (-1.0, 1.0) for z in (-1.0, 1.0)]
    idx = {p: i for i, p in enumerate(pts)}
    faces = []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            # the face's four corners, counter-clockwise seen from outside
            u, v = (axis + 1) % 3, (axis + 2) % 3
            ring = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
            if sign < 0:
                ring = ring[::-1]
            face = []
            for a, b in ring:
                p = [0.0, 0.0, 0.0]
                p[axis], p[u], p[v] = sign, a, b
                face.append(idx[tuple(p)])
            faces.append(face)
    points, counts, quads = catmull_clark(np.array(pts), [4] * 6, np.array(faces).ravel())
    assert len(points) == 8 + 12 + 6 and list(counts) == [4] * 24
    corner = points[idx[(1.0, 1.0, 1.0)]]
    np.testing.assert_allclose(corner, [5 / 9, 5 / 9, 5 / 9], atol=1e-15)
    assert any(np.allclose(p, [0.75, 0.75, 0.0], atol=1e-15) for p in points[8:20])
    assert any(np.allclose(p, [1.0, 0.0, 0.0], atol=1e-15) for p in points[20:])
    # every new quad keeps its parent face's outward orientation
    quads = np.asarray(quads).reshape(-1, 4)
    for q in quads:
        a, b, c = points[q[0]], points[q[1]], points[q[2]]
        centre = points[q].mean(axis=0)
        assert np.dot(np.cross(b - a, c - a), centre) > 0


@pytest.mark.parametrize("rel", CORPUS_STAGES)
def test_corpus_draft_record(rel):
    """The manifest records how each corpus curvenet was drafted; its counts agree with the curvenet."""
    want = MANIFEST["stages"][rel]
    d = want["draft"]
    (path, net), = want["curvenets"].items()
    pv = pool_primvar(stage(rel).GetPrimAtPath(path))
    indices = np.array(pv.GetIndices(), dtype=np.int64).reshape(-1, 4)
    val = valences(indices.ravel())
    assert sum(1 for v in val.values() if v >= 4) == d["intersections"]
    assert sum(1 for v in val.values() if v == 3) == d["t_junctions"]
    assert sum(1 for v in val.values() if v == 1) == d["anchors"]
    assert len(val) == d["knots"]
    assert 0.0 < d["options"]["offset"] <= 0.02
    assert len(d["rings"]) == d["options"]["rings"]
    assert abs(np.linalg.norm(d["axis"]) - 1.0) < 1e-12


# ----------------------------------------------------------------------------
# the generator


def run_generate(*args):
    return subprocess.run([sys.executable, str(GENERATE), *args], capture_output=True, text=True, timeout=600)


def test_generate_check_passes():
    r = run_generate("--check")
    assert r.returncode == 0, r.stdout + r.stderr


def test_generate_check_reports_every_difference(tmp_path):
    copy = tmp_path / "fixtures"
    shutil.copytree(FIXTURES, copy, ignore=shutil.ignore_patterns("__pycache__"))
    with open(copy / "grid" / "grid.usda", "a", encoding="utf-8") as fh:
        fh.write("\n")
    os.remove(copy / "hand" / "hand_lowres.usda")
    layer = Sdf.Layer.FindOrOpen(str(copy / "hand" / "hand_22k.usdc"))
    attr = layer.GetAttributeAtPath("/Hand/Mesh.points")
    pts = list(attr.default)
    pts[0] = pts[0] * 2.0
    attr.default = Vt.Vec3fArray(pts)
    layer.Save()
    (copy / "stray.usda").write_text("#usda 1.0\n", encoding="utf-8")
    r = run_generate("--check", "--dir", str(copy))
    assert r.returncode == 1, r.stdout + r.stderr
    out = r.stdout
    assert "differs: grid/grid.usda" in out
    assert "missing: hand/hand_lowres.usda" in out
    assert "differs: hand/hand_22k.usdc" in out and "bytes only" not in out
    assert "stray.usda" in out
    assert "cylinder" not in out and "manifest.json" not in out
