"""`curvenet draft` output read back through usd-core: the layer sublayers the
input, binds the drafted curvenet to the mesh and follows the curvenet
contract of schema/README.md, in both formats; its pool is the one
`--json` prints.

Needs the debug binary (`cargo test --workspace` builds it; scripts/test
runs the Rust tests first). CURVENET_BIN overrides its path."""

import json
import os
import pathlib
import subprocess

import numpy as np
import pytest
from pxr import Sdf, Usd, UsdGeom

ROOT = pathlib.Path(__file__).resolve().parents[2]
PENGUIN = ROOT / "fixtures" / "corpus" / "penguin.usda"


@pytest.fixture(scope="module")
def curvenet():
    if os.environ.get("CURVENET_BIN"):
        binary = pathlib.Path(os.environ["CURVENET_BIN"])
    else:
        binary = pathlib.Path(os.environ.get("CARGO_TARGET_DIR", ROOT / "target")) / "debug" / "curvenet"
    assert binary.exists(), f"{binary} is missing: build it first (cargo build --ignore-rust-version) or set CURVENET_BIN"
    return binary.resolve()


@pytest.mark.parametrize("ext", ["usda", "usdc"])
def test_draft_layer_composes_and_follows_the_contract(curvenet, tmp_path, ext):
    out = tmp_path / f"penguin.draft.{ext}"
    r = subprocess.run([str(curvenet), "draft", str(PENGUIN), "--out", str(out), "--json", "--rings", "4",
                        "--lines", "3", "--offset", "0.01"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    drafted = json.loads(r.stdout)
    layer = Sdf.Layer.FindOrOpen(str(out))
    (sub,) = layer.subLayerPaths
    assert pathlib.Path(layer.ComputeAbsolutePath(sub)).resolve() == PENGUIN.resolve()
    assert "curvenet draft" in layer.documentation
    stage = Usd.Stage.Open(str(out))
    mesh = stage.GetPrimAtPath("/Penguin/Mesh")
    # The fixture's own curvenet keeps its prim; the mesh now points at the draft only.
    assert [str(t) for t in mesh.GetRelationship("curvenet:curvenets").GetTargets()] == ["/Penguin/Curvenet1"]
    assert stage.GetPrimAtPath("/Penguin/Curvenet").IsValid()
    prim = stage.GetPrimAtPath("/Penguin/Curvenet1")
    curves = UsdGeom.BasisCurves(prim)
    assert prim.GetTypeName() == "BasisCurves" and prim.GetSpecifier() == Sdf.SpecifierDef
    assert (curves.GetTypeAttr().Get(), curves.GetBasisAttr().Get(), curves.GetWrapAttr().Get()) == \
        ("cubic", "bezier", "nonperiodic")
    pv = UsdGeom.PrimvarsAPI(prim).GetPrimvar("curvenet:cv")
    assert pv.GetTypeName() == Sdf.ValueTypeNames.Point3fArray
    assert pv.GetInterpolation() == UsdGeom.Tokens.vertex and pv.IsIndexed()
    pool = np.array(pv.Get(), dtype=np.float32)
    indices = np.array(pv.GetIndices(), dtype=np.int64)
    np.testing.assert_array_equal(pool, np.array(drafted["pool"], dtype=np.float32))
    np.testing.assert_array_equal(indices, np.array(drafted["splines"], dtype=np.int64).ravel())
    assert list(curves.GetCurveVertexCountsAttr().Get()) == [4] * len(drafted["splines"])
    np.testing.assert_array_equal(np.array(curves.GetPointsAttr().Get(), dtype=np.float32), pool[indices])
    density = prim.GetAttribute("curvenet:sampleDensity")
    assert density.GetVariability() == Sdf.VariabilityUniform and density.Get() == 5.0
    # Every control point lies within the bounds the layer authors.
    lo, hi = np.array(curves.GetExtentAttr().Get(), dtype=np.float32)
    assert np.all(pool >= lo) and np.all(pool <= hi)
