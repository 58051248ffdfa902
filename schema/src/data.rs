//! Plain data read from a stage: what the core needs, nothing USD-specific.
//! Positions are widened from USD's 32-bit floats to `f64`.

use serde::Serialize;

/// A mesh deformed by curvenets (a `UsdGeomMesh` with `rel curvenet:curvenets`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MeshData {
    /// Composed prim path, e.g. `/Hand/Mesh`.
    pub path: String,
    /// Corners per face.
    pub face_vertex_counts: Vec<u32>,
    /// Vertex indices, face after face, counter-clockwise (a `leftHanded`
    /// mesh has been reversed face by face).
    pub face_vertex_indices: Vec<u32>,
    /// The projection pose (`primvars:curvenet:projectionPoints`, else the
    /// default value of `points`).
    pub projection_points: Vec<[f64; 3]>,
    /// Time codes at which `points` (the rest pose) has samples; empty when
    /// the rest pose is the default value at every frame.
    pub rest_sample_times: Vec<f64>,
    /// Paths of the curvenet prims that deform this mesh, in order.
    pub curvenets: Vec<String>,
    /// Blend shapes bound to the mesh, in `skel:blendShapes` order.
    pub blend_shapes: Vec<BlendShapeData>,
    /// The `SkelAnimation` that carries the blend-shape weights, if any.
    pub blend_shape_animation: Option<String>,
}

/// A curvenet prim: a control-point pool and the cubic Bézier splines indexing it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CurvenetData {
    /// Composed prim path.
    pub path: String,
    /// The neutral pose of the pool (the default value of `primvars:curvenet:cv`).
    pub pool: Vec<[f64; 3]>,
    /// Four pool indices per spline: endpoint, handle, handle, endpoint.
    pub splines: Vec<[u32; 4]>,
    /// `curvenet:sampleDensity` (5 when not authored).
    pub sample_density: f64,
    /// Time codes at which the pool has posed samples (empty: not articulated).
    pub sample_times: Vec<f64>,
}

/// One UsdSkel blend shape bound to a mesh.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BlendShapeData {
    /// The name the mesh's `skel:blendShapes` gives it (the name weights refer to).
    pub name: String,
    /// Path of the `BlendShape` prim.
    pub prim: String,
    /// Offsets of the full shape (weight 1).
    pub offsets: Vec<[f64; 3]>,
    /// The vertex each offset applies to; `None` for a dense shape (one offset per vertex).
    pub point_indices: Option<Vec<u32>>,
    /// Inbetween shapes, sorted by weight.
    pub inbetweens: Vec<InbetweenData>,
}

/// An inbetween shape of a blend shape.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct InbetweenData {
    /// The name after `inbetweens:`.
    pub name: String,
    /// The weight at which this shape is reached exactly.
    pub weight: f64,
    /// Offsets, laid out like the parent's `offsets`.
    pub offsets: Vec<[f64; 3]>,
}

/// A `CurvenetAdjustment` prim (schema/README.md): one exposed knot of a
/// curvenet. Its animated values are read per frame with
/// `Stage::adjustments_at`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AdjustmentData {
    /// Composed prim path (a child of the curvenet prim).
    pub path: String,
    /// The curvenet prim it adjusts (its parent).
    pub curvenet: String,
    /// `curvenet:knot`: the knot's index in the curvenet's pool.
    pub knot: u32,
    /// `curvenet:attachTangents` (true when not authored).
    pub attach_tangents: bool,
    /// The knot's tangent control points (pool indices, increasing): the
    /// order of `curvenet:tangentTranslates`.
    pub tangents: Vec<u32>,
    /// Which rotate attribute is authored: `xformOp:rotateXYZ`,
    /// `xformOp:orient`, or neither.
    pub rotate: Option<String>,
    /// The authored attributes among `xformOp:translate`, the rotate,
    /// `xformOp:scale`, `curvenet:tangentTranslates`, with their time-sample
    /// times (empty: a static value).
    pub attributes: Vec<(String, Vec<f64>)>,
}

/// The one conversion from stage data to core's deformer input: the mesh in
/// its projection pose and its curvenets, with no blend shapes, no rig and
/// default options (add those with struct update syntax:
/// `DeformerInput { blend_shapes, ..deformer_input(&mesh, &curvenets) }`).
/// `curvenets` are [`CurvenetData::input`]s, in the mesh's order.
pub fn deformer_input<'a>(
    mesh: &'a MeshData,
    curvenets: &'a [curvenet_core::CurvenetInput<'a>],
) -> curvenet_core::DeformerInput<'a> {
    curvenet_core::DeformerInput {
        mesh: mesh.input(),
        curvenets,
        blend_shapes: Vec::new(),
        skinning: None,
        cage: None,
        options: Default::default(),
    }
}

impl MeshData {
    /// The mesh as core takes it: its faces and its projection pose.
    pub fn input(&self) -> curvenet_core::MeshInput<'_> {
        curvenet_core::MeshInput {
            face_vertex_counts: &self.face_vertex_counts,
            face_vertex_indices: &self.face_vertex_indices,
            projection_points: &self.projection_points,
        }
    }
}

impl CurvenetData {
    /// The curvenet as core takes it: splines, neutral pool, sampling density.
    pub fn input(&self) -> curvenet_core::CurvenetInput<'_> {
        curvenet_core::CurvenetInput { splines: &self.splines, pool: &self.pool, sample_density: self.sample_density }
    }
}

/// A mesh's cage (schema/README.md, "Cage"): a closed, outward-oriented
/// triangle `Mesh` reached through the mesh's `rel curvenet:cage`, read by
/// `Stage::cage`. Its time samples are held here (a cage is small), so a
/// frame is evaluated without the stage, in any thread:
/// [`CageData::frame`].
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CageData {
    /// The deformed mesh whose `curvenet:cage` targets this cage.
    pub mesh: String,
    /// Composed path of the cage prim.
    pub path: String,
    /// The rest cage at bind: the default value of the cage's `points`.
    pub rest_points: Vec<[f64; 3]>,
    /// The cage's triangles, counter-clockwise seen from outside (a
    /// `leftHanded` cage has been reversed).
    pub triangles: Vec<[u32; 3]>,
    /// Rest-cage edits: the `points` time samples (the rest cage C of a
    /// frame), sorted by time; empty when the rest cage is never edited.
    pub rest_samples: Vec<CageSample>,
    /// The default value of `primvars:curvenet:posedCageOffsets`, if authored.
    pub posed_offsets_default: Option<Vec<[f64; 3]>>,
    /// Posed-cage edits ∂C′: the `primvars:curvenet:posedCageOffsets` time
    /// samples, sorted by time.
    pub posed_offset_samples: Vec<CageSample>,
}

/// One time sample of a per-cage-vertex array.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CageSample {
    /// The time code.
    pub time: f64,
    /// One value per cage vertex.
    pub points: Vec<[f64; 3]>,
}

/// A cage evaluated at one time ([`CageData::frame`]): borrowed from the
/// samples when the time is on (or outside) them, interpolated otherwise.
#[derive(Debug, Clone, PartialEq)]
pub struct CageFrame<'a> {
    /// The rest cage C of the frame; `None` when the rest cage has no time
    /// samples (it is [`CageData::rest_points`], the bind cage).
    pub rest_cage: Option<std::borrow::Cow<'a, [[f64; 3]]>>,
    /// The posed-cage edits ∂C′ of the frame; `None` when none are authored.
    pub posed_cage_offsets: Option<std::borrow::Cow<'a, [[f64; 3]]>>,
}

impl CageFrame<'_> {
    /// The rest cage of the frame, for core's `Frame::rest_cage`.
    pub fn rest_cage(&self) -> Option<&[[f64; 3]]> {
        self.rest_cage.as_deref()
    }

    /// The posed-cage edits of the frame, for core's `Frame::posed_cage_offsets`.
    pub fn posed_cage_offsets(&self) -> Option<&[[f64; 3]]> {
        self.posed_cage_offsets.as_deref()
    }
}

impl CageData {
    /// The cage evaluated at `time` (`None`: the default values), as USD
    /// evaluates time samples (linear interpolation between the bracketing
    /// samples, the first or last sample held outside them, a sample's own
    /// value on it; the default value only when there are no samples).
    /// Interpolation is in `f64` from the widened samples.
    pub fn frame(&self, time: Option<f64>) -> CageFrame<'_> {
        let rest_cage = match time {
            Some(t) if !self.rest_samples.is_empty() => Some(evaluate(&self.rest_samples, t)),
            _ => None,
        };
        let posed_cage_offsets = match time {
            Some(t) if !self.posed_offset_samples.is_empty() => Some(evaluate(&self.posed_offset_samples, t)),
            _ => self.posed_offsets_default.as_deref().map(std::borrow::Cow::Borrowed),
        };
        CageFrame { rest_cage, posed_cage_offsets }
    }

    /// The rest cage at `time`: the frame's rest-cage edit, else the bind cage.
    pub fn rest_cage_at(&self, time: Option<f64>) -> std::borrow::Cow<'_, [[f64; 3]]> {
        self.frame(time).rest_cage.unwrap_or(std::borrow::Cow::Borrowed(&self.rest_points))
    }

    /// Every time code at which the cage has a sample (rest or posed edits),
    /// sorted, without repeats: the frames a bake takes by default.
    pub fn sample_times(&self) -> Vec<f64> {
        let mut t: Vec<f64> = self.rest_samples.iter().chain(&self.posed_offset_samples).map(|s| s.time).collect();
        t.sort_by(f64::total_cmp);
        t.dedup();
        t
    }
}

/// USD's evaluation of sorted, non-empty samples at `time`.
fn evaluate(samples: &[CageSample], time: f64) -> std::borrow::Cow<'_, [[f64; 3]]> {
    use std::borrow::Cow;
    let first = &samples[0];
    let last = &samples[samples.len() - 1];
    // A NaN time is ordered as USD orders it: past every number on its sign's side.
    if time <= first.time || (time.is_nan() && time.is_sign_negative()) {
        return Cow::Borrowed(&first.points);
    }
    if time >= last.time || time.is_nan() {
        return Cow::Borrowed(&last.points);
    }
    let hi = samples.partition_point(|s| s.time <= time);
    let (a, b) = (&samples[hi - 1], &samples[hi]);
    if a.time == time {
        return Cow::Borrowed(&a.points);
    }
    let u = (time - a.time) / (b.time - a.time);
    Cow::Owned(
        a.points
            .iter()
            .zip(&b.points)
            .map(|(p, q)| [p[0] + (q[0] - p[0]) * u, p[1] + (q[1] - p[1]) * u, p[2] + (q[2] - p[2]) * u])
            .collect(),
    )
}
