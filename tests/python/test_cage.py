"""`curvenet bake` of the caged hand (fixtures/shots/hand_caged: a cage coupled
with the rigged hand's skeleton, issue 18), read back by usd-core with the
baked layer composed over the shot, as a pipeline reads it: every frame's
points come from the bake (not the input's), are finite, and follow the
shot's edits. (server/tests/cage.rs compares the same bake with the core's
coupled rig evaluated in process.)"""

import math
import os
import pathlib
import subprocess

import pytest
from pxr import Sdf, Usd, UsdGeom

ROOT = pathlib.Path(__file__).resolve().parents[2]
SHOT = ROOT / "fixtures" / "shots" / "hand_caged" / "shot.usda"


def _binary() -> pathlib.Path:
    given = os.environ.get("CURVENET_BIN")
    return pathlib.Path(given) if given else ROOT / "target" / "debug" / "curvenet"


@pytest.fixture(scope="module")
def curvenet() -> pathlib.Path:
    binary = _binary()
    assert binary.exists(), f"{binary} is missing: build it first (cargo build --ignore-rust-version) or set CURVENET_BIN"
    return binary.resolve()


def _points(stage: Usd.Stage, t: float) -> list[tuple[float, float, float]]:
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/Hand/Mesh"))
    return [tuple(p) for p in mesh.GetPointsAttr().Get(Usd.TimeCode(t))]


def _dist(a: list[tuple[float, float, float]], b: list[tuple[float, float, float]]) -> float:
    assert len(a) == len(b)
    return max(math.dist(p, q) for p, q in zip(a, b))


def test_usd_core_reads_the_caged_bake_composed_over_the_shot(curvenet: pathlib.Path, tmp_path: pathlib.Path) -> None:
    out = tmp_path / "caged_bake.usda"
    run = subprocess.run([str(curvenet), "bake", str(SHOT), "--out", str(out), "--quiet"], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    # The bake layer above (stronger than) the shot, as the bake's doc says.
    root = Sdf.Layer.CreateAnonymous(".usda")
    root.subLayerPaths = [str(out), str(SHOT)]
    composed = Usd.Stage.Open(root)
    baked = Usd.Stage.Open(str(out))
    shot = Usd.Stage.Open(str(SHOT))
    rest = _points(shot, 1.0)
    lo = [min(p[k] for p in rest) for k in range(3)]
    hi = [max(p[k] for p in rest) for k in range(3)]
    diagonal = math.dist(lo, hi)
    moved = []
    for t in range(1, 11):
        points = _points(composed, float(t))
        assert len(points) == len(rest)
        assert all(math.isfinite(x) for p in points for x in p), f"frame {t}"
        # The composed stage shows the bake's samples.
        assert _dist(points, _points(baked, float(t))) == 0.0, f"frame {t}"
        moved.append(_dist(points, rest) / diagonal)
    # Frame 1 edits nothing: the input hand (the curvenet tracks it).
    assert moved[0] < 1e-5, moved
    # Rest-cage edits (2, 3), the pose (4, 5) and posed-cage edits (6, 7: 0.03 at full) move it.
    for frame in (2, 4, 7, 10):
        assert moved[frame - 1] > 1e-2, (frame, moved)
