"""Reading a stage for the service, and writing the bake's layer (needs usd-core:
``pip install 'curvenet-client[usd]'``).

The stage follows the curvenet USD contract (``schema/README.md`` in the
curvenet repository); this module reads it the way ``curvenet bake`` does:

- **Mesh**: ``faceVertexCounts``/``faceVertexIndices`` (static), a
  ``leftHanded`` mesh read with every face reversed (the service wants
  counter-clockwise faces); the projection pose is
  ``primvars:curvenet:projectionPoints`` (flattened when it is an indexed
  primvar) or else the default value of ``points``.
- **Curvenets** (``rel curvenet:curvenets``, in order): the pool is the *raw*
  value of ``primvars:curvenet:cv`` — its ``:indices`` are the splines' pool
  indices (4 per spline), so the primvar is never flattened; the density is
  ``curvenet:sampleDensity`` (default 5).
- **Blend shapes**: UsdSkel's ``skel:blendShapes``/``skel:blendShapeTargets``
  (offsets, sparse ``pointIndices``, inbetweens sorted by weight), weights from
  the ``SkelAnimation`` behind ``skel:skeleton`` → ``skel:animationSource``.
- **Per frame**: the posed pool of each curvenet whose ``primvars:curvenet:cv``
  has time samples (else not articulated), the rest pose (``points`` at the
  time code) when ``points`` is animated or differs from the projection pose,
  and the blend-shape weights when the mesh has blend shapes.

Errors name the prim and the attribute (:class:`UsdContractError`).
"""

from __future__ import annotations

import math
import os
import tempfile
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
try:
    from pxr import Sdf, Usd, UsdGeom, UsdSkel, Vt
except ImportError as e:  # pragma: no cover - depends on the installation
    raise ImportError(
        f"curvenet_client.usd needs usd-core: pip install 'curvenet-client[usd]' ({e})"
    ) from e

from .frames import Frame
from .request import DEFAULT_SAMPLE_DENSITY, BindingRequest, BlendShape, CurvenetSpec, Inbetween

__all__ = [
    "StageMesh",
    "UsdContractError",
    "binding_request",
    "deformed_meshes",
    "frame_inputs",
    "frame_range",
    "open_stage",
    "write_bake_layer",
    "write_points_layer",
]

CURVENETS_REL = "curvenet:curvenets"
PROJECTION = "primvars:curvenet:projectionPoints"
CV = "primvars:curvenet:cv"
CV_INDICES = "primvars:curvenet:cv:indices"
DENSITY = "curvenet:sampleDensity"
#: Longest frame range :func:`frame_range` accepts (as ``curvenet bake``).
MAX_FRAMES = 1_000_000


class UsdContractError(ValueError):
    """The stage breaks the curvenet contract; the message names the prim and attribute."""

    def __init__(self, prim: str, attribute: str, problem: str) -> None:
        where = f"{prim}: {attribute}" if attribute else prim
        super().__init__(f"{where} {problem}" if attribute else f"{where}: {problem}")
        self.prim = prim
        self.attribute = attribute
        self.problem = problem


def open_stage(stage: Any) -> Any:
    """A ``Usd.Stage``: the one given, or the file opened (composition
    errors such as an unresolved sublayer are refused, like the bake does)."""
    if isinstance(stage, Usd.Stage):
        return stage
    path = os.fspath(stage)
    if not os.path.isfile(path):
        raise FileNotFoundError(f"{path}: no such file")
    opened = Usd.Stage.Open(path)
    if opened is None:
        raise UsdContractError(path, "", "usd-core cannot open it")
    errors = opened.GetCompositionErrors() if hasattr(opened, "GetCompositionErrors") else []
    if errors:
        raise UsdContractError(path, "", f"composition failed: {errors[0]}")
    return opened


def _time(t: float | None) -> Any:
    return Usd.TimeCode.Default() if t is None else Usd.TimeCode(t)


def _points(prim: Any, name: str, value: Any) -> npt.NDArray[np.float64]:
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise UsdContractError(str(prim.GetPath()), name, f"has type {type(value).__name__}, expected point3f[]")
    if a.size == 0:
        a = a.reshape(0, 3)
    if a.ndim != 2 or a.shape[1] != 3:
        raise UsdContractError(str(prim.GetPath()), name, f"has shape {a.shape}, expected point3f[]")
    return a


def _f32_points(prim: Any, name: str, value: Any) -> npt.NDArray[np.float32]:
    return _points(prim, name, value).astype(np.float32)


def _static(prim: Any, name: str) -> Any:
    attr = prim.GetAttribute(name)
    if not attr or not attr.HasAuthoredValue():
        return None
    if attr.GetNumTimeSamples() > 0:
        raise UsdContractError(str(prim.GetPath()), name, "must not have time samples (it is static)")
    return attr.Get()


def _indices(prim: Any, name: str, value: Any, length: int) -> npt.NDArray[np.int64]:
    a = np.asarray(value, dtype=np.int64).reshape(-1)
    bad = np.flatnonzero((a < 0) | (a >= length))
    if bad.size:
        i = int(bad[0])
        raise UsdContractError(str(prim.GetPath()), name, f"entry {i} is {int(a[i])}, outside 0..{length}")
    return a


def deformed_meshes(stage: Any) -> list[str]:
    """The paths of every ``Mesh`` with an authored ``rel curvenet:curvenets``,
    in traversal order (the meshes ``curvenet bake`` deforms)."""
    st = open_stage(stage)
    out = []
    for prim in st.Traverse():
        if prim.GetTypeName() == "Mesh":
            rel = prim.GetRelationship(CURVENETS_REL)
            if rel and rel.GetTargets():
                out.append(str(prim.GetPath()))
    return out


class StageMesh:
    """One curvenet-deformed mesh of a stage: its :class:`BindingRequest` and
    its per-frame inputs. The static data are read once, here."""

    def __init__(self, stage: Any, mesh_path: str) -> None:
        self.stage = open_stage(stage)
        self.path = str(mesh_path)
        prim = self.stage.GetPrimAtPath(self.path)
        if not prim or not prim.IsValid():
            raise UsdContractError(self.path, "", "no such prim on the stage")
        if prim.GetTypeName() != "Mesh":
            raise UsdContractError(self.path, "", f"is a {prim.GetTypeName()!r}, expected a Mesh")
        self._prim = prim
        counts_v = _static(prim, "faceVertexCounts")
        if counts_v is None:
            raise UsdContractError(self.path, "faceVertexCounts", "is missing")
        counts = np.asarray(counts_v, dtype=np.int64).reshape(-1)
        if counts.size and counts.min() < 0:
            raise UsdContractError(self.path, "faceVertexCounts", "has a negative entry")
        points_attr = prim.GetAttribute("points")
        default_points = points_attr.Get(Usd.TimeCode.Default()) if points_attr else None
        if default_points is None:
            raise UsdContractError(self.path, "points", "is missing")
        rest_default = _points(prim, "points", default_points)
        n = rest_default.shape[0]
        indices_v = _static(prim, "faceVertexIndices")
        if indices_v is None:
            raise UsdContractError(self.path, "faceVertexIndices", "is missing")
        indices = _indices(prim, "faceVertexIndices", indices_v, n)
        if int(counts.sum()) != indices.size:
            raise UsdContractError(
                self.path,
                "faceVertexIndices",
                f"has {indices.size} entries but faceVertexCounts sum to {int(counts.sum())}",
            )
        orientation = prim.GetAttribute("orientation")
        if orientation and orientation.HasAuthoredValue():
            o = orientation.Get()
            if o == UsdGeom.Tokens.leftHanded:
                # The contract: faces are counter-clockwise. A leftHanded face is
                # read reversed, exactly as the Rust reader does (the whole face).
                starts = np.concatenate([[0], np.cumsum(counts)[:-1]]) if counts.size else counts
                indices = np.concatenate(
                    [indices[s : s + c][::-1] for s, c in zip(starts.tolist(), counts.tolist())]
                ).astype(np.int64)
            elif o != UsdGeom.Tokens.rightHanded:
                raise UsdContractError(self.path, "orientation", f"is {o!r}, expected rightHanded or leftHanded")
        projection = rest_default
        proj_primvar = UsdGeom.PrimvarsAPI(prim).GetPrimvar(PROJECTION)
        if proj_primvar and proj_primvar.HasAuthoredValue():
            if proj_primvar.GetAttr().GetNumTimeSamples() > 0:
                raise UsdContractError(self.path, PROJECTION, "must not have time samples (it is static)")
            projection = _points(prim, PROJECTION, proj_primvar.ComputeFlattened())
            if projection.shape[0] != n:
                raise UsdContractError(self.path, PROJECTION, f"has {projection.shape[0]} points, the mesh has {n}")
        self.rest_sample_times: list[float] = list(points_attr.GetTimeSamples())
        # The rest pose goes with each frame when it can differ from the projection pose.
        self.reads_rest = bool(self.rest_sample_times) or not np.array_equal(rest_default, projection)
        self.curvenet_paths = [str(p) for p in prim.GetRelationship(CURVENETS_REL).GetTargets()]
        if not self.curvenet_paths:
            raise UsdContractError(self.path, CURVENETS_REL, "has no targets: the mesh is not curvenet-deformed")
        self.curvenets = [self._curvenet(p) for p in self.curvenet_paths]
        self._cv_attrs = [self.stage.GetPrimAtPath(p).GetAttribute(CV) for p in self.curvenet_paths]
        self.articulated = [a.GetNumTimeSamples() > 0 for a in self._cv_attrs]
        self.curvenet_sample_times = sorted({t for a in self._cv_attrs for t in a.GetTimeSamples()})
        self.blend_shape_names, shapes = self._blend_shapes(n)
        self._anim = self._animation() if shapes else None
        self.request = BindingRequest(
            face_vertex_counts=counts,
            face_vertex_indices=indices,
            projection_points=projection,
            curvenets=self.curvenets,
            blend_shapes=shapes,
        )
        self._points_attr = points_attr

    @property
    def vertices(self) -> int:
        return self.request.vertices

    def _curvenet(self, path: str) -> CurvenetSpec:
        prim = self.stage.GetPrimAtPath(path)
        if not prim or not prim.IsValid():
            raise UsdContractError(path, "", "no such prim on the stage")
        if prim.GetTypeName() != "BasisCurves":
            raise UsdContractError(path, "", f"is a {prim.GetTypeName()!r}, a curvenet must be a BasisCurves")
        for name, want in (("type", "cubic"), ("basis", "bezier"), ("wrap", "nonperiodic")):
            attr = prim.GetAttribute(name)
            if attr and attr.HasAuthoredValue() and attr.Get() != want:
                raise UsdContractError(path, name, f"is {attr.Get()!r}, a curvenet needs {want!r}")
        cv = prim.GetAttribute(CV)
        pool_v = cv.Get(Usd.TimeCode.Default()) if cv else None
        if pool_v is None:
            raise UsdContractError(path, CV, "is missing")
        pool = _points(prim, CV, pool_v)
        indices_v = _static(prim, CV_INDICES)
        if indices_v is None:
            raise UsdContractError(path, CV_INDICES, "is missing")
        indices = _indices(prim, CV_INDICES, indices_v, pool.shape[0])
        counts_v = _static(prim, "curveVertexCounts")
        if counts_v is not None:
            counts = np.asarray(counts_v, dtype=np.int64).reshape(-1)
            bad = np.flatnonzero(counts != 4)
            if bad.size:
                i = int(bad[0])
                raise UsdContractError(path, "curveVertexCounts", f"entry {i} is {int(counts[i])}, every spline needs 4")
            if counts.size * 4 != indices.size:
                raise UsdContractError(
                    path, CV_INDICES, f"has {indices.size} entries, expected 4 per spline ({counts.size} splines)"
                )
        if indices.size % 4:
            raise UsdContractError(path, CV_INDICES, f"has {indices.size} entries, not a multiple of 4")
        density = DEFAULT_SAMPLE_DENSITY
        d = prim.GetAttribute(DENSITY)
        if d and d.HasAuthoredValue():
            value = d.Get()
            if not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
                raise UsdContractError(path, DENSITY, f"is {value!r}, expected a positive float")
            density = float(value)
        return CurvenetSpec(pool, indices.reshape(-1, 4), density)

    def _blend_shapes(self, n: int) -> tuple[list[str], list[BlendShape]]:
        names_attr = self._prim.GetAttribute("skel:blendShapes")
        if not names_attr or not names_attr.HasAuthoredValue():
            return [], []
        names = [str(x) for x in names_attr.Get()]
        rel = self._prim.GetRelationship("skel:blendShapeTargets")
        targets = [str(t) for t in rel.GetTargets()] if rel else []
        if len(targets) != len(names):
            raise UsdContractError(
                self.path,
                "skel:blendShapeTargets",
                f"has {len(targets)} targets but skel:blendShapes names {len(names)}",
            )
        if len(set(names)) != len(names):
            twice = next(x for x in names if names.count(x) > 1)
            raise UsdContractError(self.path, "skel:blendShapes", f"names {twice!r} twice")
        shapes = []
        for name, target in zip(names, targets):
            prim = self.stage.GetPrimAtPath(target)
            if not prim or not prim.IsValid():
                raise UsdContractError(target, "", "no such prim on the stage")
            shape = UsdSkel.BlendShape(prim)
            offsets_v = shape.GetOffsetsAttr().Get()
            if offsets_v is None:
                raise UsdContractError(target, "offsets", "is missing")
            offsets = _points(prim, "offsets", offsets_v)
            point_indices = None
            pi = shape.GetPointIndicesAttr()
            if pi and pi.HasAuthoredValue():
                point_indices = _indices(prim, "pointIndices", pi.Get(), n)
            expected = n if point_indices is None else point_indices.size
            if offsets.shape[0] != expected:
                why = "pointIndices has" if point_indices is not None else "the mesh has"
                raise UsdContractError(target, "offsets", f"has {offsets.shape[0]} entries, {why} {expected}")
            inbetweens = []
            for ib in shape.GetAuthoredInbetweens():
                attr = ib.GetAttr()
                weight = ib.GetWeight()
                if weight is None:
                    raise UsdContractError(target, attr.GetName(), "has no weight metadata")
                ib_offsets = _points(prim, attr.GetName(), attr.Get())
                if ib_offsets.shape[0] != offsets.shape[0]:
                    raise UsdContractError(
                        target,
                        attr.GetName(),
                        f"has {ib_offsets.shape[0]} offsets, the shape has {offsets.shape[0]}",
                    )
                inbetweens.append(Inbetween(float(weight), ib_offsets))
            inbetweens.sort(key=lambda i: i.weight)
            shapes.append(BlendShape(offsets, point_indices, inbetweens, name))
        return names, shapes

    def _animation(self) -> Any:
        """The SkelAnimation behind ``skel:skeleton`` (on the mesh or an
        ancestor) → ``skel:animationSource``, or None."""
        prim = self._prim
        while prim and prim.IsValid() and not prim.IsPseudoRoot():
            rel = prim.GetRelationship("skel:skeleton")
            targets = rel.GetTargets() if rel else []
            if targets:
                skel = self.stage.GetPrimAtPath(targets[0])
                if not skel or not skel.IsValid():
                    raise UsdContractError(str(targets[0]), "", "no such prim on the stage")
                src = skel.GetRelationship("skel:animationSource")
                anim = src.GetTargets() if src else []
                return self.stage.GetPrimAtPath(anim[0]) if anim else None
            prim = prim.GetParent()
        return None

    # ------------------------------------------------------------------ per frame

    def posed(self, time: float | None) -> list[npt.NDArray[np.float32] | None]:
        """The posed pool of each curvenet at ``time`` (``None`` for a curvenet
        without time samples: not articulated)."""
        out: list[npt.NDArray[np.float32] | None] = []
        for path, attr, articulated, net in zip(self.curvenet_paths, self._cv_attrs, self.articulated, self.curvenets):
            if not articulated:
                out.append(None)
                continue
            pool = _f32_points(attr.GetPrim(), CV, attr.Get(_time(time)))
            if pool.shape[0] != net.pool.shape[0]:
                raise UsdContractError(
                    path, CV, f"has {pool.shape[0]} control points at time {time}, the neutral pose has {net.pool.shape[0]}"
                )
            self._finite(pool, path, CV, "control point", time)
            out.append(pool)
        return out

    def rest(self, time: float | None) -> npt.NDArray[np.float32]:
        """The rest pose at ``time``: the composed ``points``."""
        rest = _f32_points(self._prim, "points", self._points_attr.Get(_time(time)))
        if rest.shape[0] != self.vertices:
            raise UsdContractError(
                self.path, "points", f"has {rest.shape[0]} points at time {time}, the mesh has {self.vertices}"
            )
        self._finite(rest, self.path, "points", "point", time)
        return rest

    def blend_shape_weights(self, time: float | None) -> npt.NDArray[np.float32]:
        """One weight per blend shape at ``time`` (0 for a shape the animation
        does not name, as in UsdSkel)."""
        weights = np.zeros(len(self.blend_shape_names), dtype=np.float32)
        if self._anim is None:
            return weights
        anim = UsdSkel.Animation(self._anim)
        anim_path = str(self._anim.GetPath())
        names_v = anim.GetBlendShapesAttr().Get()
        w_v = anim.GetBlendShapeWeightsAttr().Get(_time(time))
        if names_v is None or w_v is None:
            return weights
        names = [str(x) for x in names_v]
        w = np.asarray(w_v, dtype=np.float32).reshape(-1)
        if w.size != len(names):
            raise UsdContractError(
                anim_path, "blendShapeWeights", f"has {w.size} weights at time {time} but blendShapes names {len(names)}"
            )
        for name, x in zip(names, w.tolist()):
            if not math.isfinite(x):
                raise UsdContractError(anim_path, "blendShapeWeights", f"weight of {name!r} is {x} at time {time}")
            if name in self.blend_shape_names:
                weights[self.blend_shape_names.index(name)] = x
        return weights

    def frame(self, time: float | None) -> Frame:
        """The frame's input at ``time``, as ``curvenet bake`` sends it to the
        solve: posed pools, the rest pose when it can differ from the
        projection pose, blend-shape weights when the mesh has blend shapes."""
        return Frame(
            posed=self.posed(time),
            rest=self.rest(time) if self.reads_rest else None,
            blend_shape_weights=self.blend_shape_weights(time) if self.blend_shape_names else None,
        )

    @staticmethod
    def _finite(points: npt.NDArray[np.float32], prim: str, attribute: str, what: str, time: float | None) -> None:
        bad = np.flatnonzero(~np.isfinite(points).all(axis=1))
        if bad.size:
            i = int(bad[0])
            more = f" ({bad.size} non-finite {what}s in all)" if bad.size > 1 else ""
            raise UsdContractError(prim, attribute, f"{what} {i} is {points[i].tolist()} at time {time}, not finite{more}")


def binding_request(stage: Any, mesh_path: str) -> BindingRequest:
    """The :class:`BindingRequest` of ``mesh_path`` on ``stage`` (a ``Usd.Stage`` or a file)."""
    return StageMesh(stage, mesh_path).request


def frame_inputs(stage: Any, mesh_path: str, time: float | None) -> Frame:
    """The frame input of ``mesh_path`` at ``time`` (``None``: the default
    value). For many frames, make one :class:`StageMesh` and call its ``frame``."""
    return StageMesh(stage, mesh_path).frame(time)


def frame_range(stage: Any, meshes: Sequence[StageMesh] | None = None) -> list[float]:
    """The frames ``curvenet bake`` bakes without ``--frames``: every integer
    time code from ``startTimeCode`` to ``endTimeCode`` when both are authored,
    else the union of the time samples of the meshes' ``points`` and their
    curvenets' pools."""
    st = open_stage(stage)
    if st.HasAuthoredTimeCodeRange():
        start, end = st.GetStartTimeCode(), st.GetEndTimeCode()
        first, last = math.ceil(start), math.floor(end)
        if not first <= last or last - first >= MAX_FRAMES:
            raise UsdContractError(
                str(st.GetRootLayer().realPath),
                "",
                f"startTimeCode {start} .. endTimeCode {end} holds no bakeable frame range; give the frames",
            )
        return [float(t) for t in range(first, last + 1)]
    if meshes is None:
        meshes = [StageMesh(st, p) for p in deformed_meshes(st)]
    times = sorted({t for m in meshes for t in [*m.rest_sample_times, *m.curvenet_sample_times]})
    if not times:
        raise UsdContractError(
            str(st.GetRootLayer().realPath),
            "",
            "the stage authors no startTimeCode/endTimeCode and no time samples on its meshes or curvenets; "
            "give the frames",
        )
    return [float(t) for t in times]


# ---------------------------------------------------------------------- writing


def write_bake_layer(
    out_path: str | os.PathLike[str],
    meshes: Mapping[str, Iterable[tuple[float, npt.ArrayLike]]],
    *,
    doc: str,
    time_range: tuple[float, float] | None = None,
) -> None:
    """Writes the bake's kind of layer with usd-core: ``over`` opinions only
    (the mesh and each ancestor), one ``point3f[] points`` attribute per mesh
    with a float32 time sample per frame, and the layer metadata ``doc``,
    ``startTimeCode`` and ``endTimeCode`` (default: the first and last frame).
    ``.usda`` or ``.usdc`` by the extension. The file is replaced atomically: the layer
    goes to a temporary file beside ``out_path`` that is renamed over it, so a
    failure leaves ``out_path`` as it was and no temporary file.
    """
    out = Path(out_path)
    ext = out.suffix.lower()
    if ext not in (".usda", ".usdc"):
        raise ValueError(f"{out}: the output must end in .usda or .usdc")
    if not out.parent.is_dir():
        raise FileNotFoundError(f"{out}: directory {out.parent} does not exist")
    layer = Sdf.Layer.CreateAnonymous(ext)
    all_times: list[float] = []
    for mesh_path, samples in meshes.items():
        path = Sdf.Path(mesh_path)
        if not path.IsAbsolutePath() or not path.IsPrimPath():
            raise ValueError(f"{mesh_path!r} is not an absolute prim path")
        spec = Sdf.CreatePrimInLayer(layer, path)
        # CreatePrimInLayer makes the prim and its ancestors `over`s without
        # authoring the field (over is its fallback); author it, as the bake does.
        for prefix in path.GetPrefixes():
            layer.GetPrimAtPath(prefix).specifier = Sdf.SpecifierOver
        attr = Sdf.AttributeSpec(spec, "points", Sdf.ValueTypeNames.Point3fArray)
        seen = set()
        for t, points in sorted(((float(t), p) for t, p in samples), key=lambda s: s[0]):
            if not math.isfinite(t):
                raise ValueError(f"{mesh_path}: time code {t} is not finite")
            if t in seen:
                raise ValueError(f"{mesh_path}: two samples at time code {t}")
            seen.add(t)
            a = np.ascontiguousarray(points, dtype=np.float32)
            if a.ndim != 2 or a.shape[1] != 3:
                raise ValueError(f"{mesh_path}: the points at time {t} have shape {a.shape}; expected (n, 3)")
            layer.SetTimeSample(attr.path, t, _vec3f_array(a))
            all_times.append(t)
        del attr
    if time_range is None:
        if not all_times:
            raise ValueError("no frames to write")
        time_range = (min(all_times), max(all_times))
    layer.documentation = doc
    layer.startTimeCode = float(time_range[0])
    layer.endTimeCode = float(time_range[1])
    fd, temp = tempfile.mkstemp(prefix=f".{out.name}.tmp-", suffix=ext, dir=out.parent)
    os.close(fd)
    try:
        if not layer.Export(temp):
            raise OSError(f"usd-core could not write {temp}")
        with open(temp, "rb") as f:
            os.fsync(f.fileno())
        os.replace(temp, out)
    except BaseException:
        if os.path.exists(temp):
            os.unlink(temp)
        raise


def _vec3f_array(a: npt.NDArray[np.float32]) -> Any:
    return Vt.Vec3fArray.FromNumpy(a)


def write_points_layer(
    stage_path: str | os.PathLike[str],
    mesh_path: str,
    frames: Mapping[float, npt.ArrayLike] | Iterable[tuple[float, npt.ArrayLike]],
    out_path: str | os.PathLike[str],
    *,
    doc: str | None = None,
) -> None:
    """Writes the deformed points of one mesh (``frames``: time code → ``(V, 3)``
    points, or ``(time, points)`` pairs) as the bake's kind of ``over`` layer,
    to sublayer above ``stage_path``. ``doc`` defaults to a line naming the
    stage and the mesh. See :func:`write_bake_layer`."""
    samples = list(frames.items()) if isinstance(frames, Mapping) else list(frames)
    text = doc if doc is not None else (
        f"The deformed points of {mesh_path} from {os.fspath(stage_path)} from startTimeCode to endTimeCode, "
        "as over opinions only. Sublayer above (stronger than) the input."
    )
    write_bake_layer(out_path, {mesh_path: samples}, doc=text)
