//! Reading a composed stage that follows the contract.

use std::collections::HashSet;

use openusd::sdf::{self, Value};
use openusd::usd;

use super::error::UsdError;
use super::value;
use crate::data::{BlendShapeData, CurvenetData, InbetweenData, MeshData};

const CURVENETS_REL: &str = "curvenet:curvenets";
const PROJECTION: &str = "primvars:curvenet:projectionPoints";
const CV: &str = "primvars:curvenet:cv";
const CV_INDICES: &str = "primvars:curvenet:cv:indices";
const DENSITY: &str = "curvenet:sampleDensity";
/// The paper's default sample density (samples per mean mesh edge length).
pub const DEFAULT_SAMPLE_DENSITY: f64 = 5.0;

/// A composed USD stage, read through the curvenet contract.
///
/// Not `Send`: open it in the thread that reads it.
pub struct Stage {
    pub(super) stage: usd::Stage,
    path: String,
}

type Result<T> = std::result::Result<T, UsdError>;

impl Stage {
    /// Opens and composes `path` (.usda, .usdc or .usdz). Unresolved
    /// sublayers, references or payloads are errors: a bake that silently
    /// dropped a rest-pose sublayer would write a wrong mesh.
    pub fn open(path: impl AsRef<std::path::Path>) -> Result<Self> {
        Self::open_with(path.as_ref(), None)
    }

    /// Like [`Self::open`], but every layer and asset the stage opens (its
    /// root layer, sublayers, references, payloads, at any depth) must
    /// resolve, symlinks followed, inside one of `roots` (canonical
    /// directories); the first one outside is refused with
    /// [`UsdError::Forbidden`], before it is read.
    pub fn open_within(path: impl AsRef<std::path::Path>, roots: &[std::path::PathBuf]) -> Result<Self> {
        Self::open_with(path.as_ref(), Some(roots))
    }

    fn open_with(path: &std::path::Path, roots: Option<&[std::path::PathBuf]>) -> Result<Self> {
        let path = path.to_string_lossy().into_owned();
        let open_err = |message: String| UsdError::Open { path: path.clone(), message };
        if !std::path::Path::new(&path).is_file() {
            return Err(open_err("no such file".into()));
        }
        let refused = std::sync::Arc::new(std::sync::Mutex::new(None));
        let opened = match roots {
            None => usd::Stage::open(&path),
            Some(roots) => usd::Stage::builder()
                .resolver(super::confine::Confined::new(roots.to_vec(), refused.clone()))
                .open(&path),
        };
        let forbidden = || {
            refused.lock().unwrap_or_else(|e| e.into_inner()).take().map(|(asset, resolved): (String, String)| {
                UsdError::Forbidden {
                    path: path.clone(),
                    asset,
                    resolved,
                    roots: roots
                        .unwrap_or_default()
                        .iter()
                        .map(|r| r.display().to_string())
                        .collect::<Vec<_>>()
                        .join(", "),
                }
            })
        };
        let stage = match opened {
            Ok(stage) => stage,
            Err(e) => return Err(forbidden().unwrap_or_else(|| open_err(e.to_string()))),
        };
        let stage = Self { stage, path: path.clone() };
        // Composition diagnostics accrue as prims are composed: compose every
        // prim once, then refuse the stage if anything failed to resolve.
        let composed = stage.all_prims();
        if let Some(e) = forbidden() {
            return Err(e);
        }
        composed?;
        if let Some(diag) = stage.stage.composition_errors().first() {
            return Err(UsdError::Open { path, message: diag.to_string() });
        }
        Ok(stage)
    }

    /// The files of every layer the stage composed (its root layer,
    /// sublayers, and the layers behind references and payloads: all are
    /// loaded when it is opened), as their identifiers name them; in-memory
    /// layers (no file) are left out. A writer must not replace one of these
    /// with what it derived from them.
    pub fn layer_files(&self) -> Vec<std::path::PathBuf> {
        self.stage.layer_identifiers().into_iter().map(std::path::PathBuf::from).filter(|p| p.is_file()).collect()
    }

    /// The file this stage was opened from.
    pub fn path(&self) -> &str {
        &self.path
    }

    /// The authored `startTimeCode`/`endTimeCode`, if both are authored.
    pub fn time_code_range(&self) -> Option<(f64, f64)> {
        self.stage.has_authored_time_code_range().then(|| (self.stage.start_time_code(), self.stage.end_time_code()))
    }

    fn all_prims(&self) -> Result<Vec<sdf::Path>> {
        let mut paths = Vec::new();
        self.stage
            .traverse(usd::PrimPredicate::DEFAULT, |p| paths.push(p.clone()))
            .map_err(|e| UsdError::Open { path: self.path.clone(), message: e.to_string() })?;
        Ok(paths)
    }

    pub(super) fn prim(&self, path: &str) -> Result<usd::Prim> {
        let prim = self.stage.prim(path).map_err(|e| UsdError::contract(path, "", format!("bad prim path: {e}")))?;
        match prim.is_valid() {
            Ok(true) => Ok(prim),
            _ => Err(UsdError::contract(path, "", "no such prim on the stage")),
        }
    }

    pub(super) fn type_name(&self, prim: &usd::Prim) -> Result<String> {
        let t = prim.type_name().map_err(|e| UsdError::contract(prim.path(), "", e.to_string()))?;
        Ok(t.map(|t| t.as_str().to_string()).unwrap_or_default())
    }

    /// Every mesh the stage asks to deform: `Mesh` prims with an authored
    /// `rel curvenet:curvenets`, in traversal order.
    pub fn deformed_meshes(&self) -> Result<Vec<MeshData>> {
        let mut out = Vec::new();
        for path in self.all_prims()? {
            let prim = self.prim(path.as_str())?;
            if self.type_name(&prim)? == "Mesh"
                && prim.relationship(CURVENETS_REL).has_authored_targets().unwrap_or(false)
            {
                out.push(self.mesh(path.as_str())?);
            }
        }
        Ok(out)
    }

    /// The path of every `Mesh` prim on the stage, deformed or not, in
    /// traversal order.
    pub fn mesh_paths(&self) -> Result<Vec<String>> {
        let mut out = Vec::new();
        for path in self.all_prims()? {
            let prim = self.prim(path.as_str())?;
            if self.type_name(&prim)? == "Mesh" {
                out.push(path.as_str().to_string());
            }
        }
        Ok(out)
    }

    /// Whether the composed stage has a prim at `path`.
    pub fn has_prim(&self, path: &str) -> bool {
        self.prim(path).is_ok()
    }

    /// Every curvenet prim on the stage (`BasisCurves` with `primvars:curvenet:cv`).
    pub fn curvenets(&self) -> Result<Vec<CurvenetData>> {
        let mut out = Vec::new();
        for path in self.all_prims()? {
            let prim = self.prim(path.as_str())?;
            if self.type_name(&prim)? == "BasisCurves" && self.has_value(&prim, CV)? {
                out.push(self.curvenet(path.as_str())?);
            }
        }
        Ok(out)
    }

    pub(super) fn has_value(&self, prim: &usd::Prim, name: &str) -> Result<bool> {
        prim.attribute(name).has_authored_value().map_err(|e| UsdError::contract(prim.path(), name, e.to_string()))
    }

    /// The composed value of `prim.name` at `time` (`None`: the default value).
    pub(super) fn value(&self, prim: &usd::Prim, name: &str, time: Option<f64>) -> Result<Option<Value>> {
        prim.attribute(name)
            .get_at::<Value>(time.map(usd::TimeCode::new))
            .map_err(|e| UsdError::contract(prim.path(), name, e.to_string()))
    }

    pub(super) fn required(&self, prim: &usd::Prim, name: &str, time: Option<f64>) -> Result<Value> {
        self.value(prim, name, time)?.ok_or_else(|| UsdError::contract(prim.path(), name, "is missing"))
    }

    pub(super) fn sample_times(&self, prim: &usd::Prim, name: &str) -> Result<Vec<f64>> {
        prim.attribute(name).time_sample_times().map_err(|e| UsdError::contract(prim.path(), name, e.to_string()))
    }

    pub(super) fn static_value(&self, prim: &usd::Prim, name: &str) -> Result<Option<Value>> {
        if !self.sample_times(prim, name)?.is_empty() {
            return Err(UsdError::contract(prim.path(), name, "must not have time samples (it is static)"));
        }
        self.value(prim, name, None)
    }

    pub(super) fn points_value(&self, prim: &usd::Prim, name: &str, v: &Value) -> Result<Vec<[f64; 3]>> {
        value::points(v).ok_or_else(|| {
            UsdError::contract(prim.path(), name, format!("has type {}, expected point3f[]", value::kind(v)))
        })
    }

    pub(super) fn index_array(&self, prim: &usd::Prim, name: &str, v: &Value, len: usize) -> Result<Vec<u32>> {
        let ints = value::ints(v).ok_or_else(|| {
            UsdError::contract(prim.path(), name, format!("has type {}, expected int[]", value::kind(v)))
        })?;
        ints.iter()
            .enumerate()
            .map(|(i, &x)| {
                if x < 0 || x as u64 >= len as u64 {
                    Err(UsdError::contract(prim.path(), name, format!("entry {i} is {x}, outside 0..{len}")))
                } else {
                    Ok(x as u32)
                }
            })
            .collect()
    }

    /// Reads the mesh at `path`: topology, projection pose, curvenet targets
    /// and blend shapes. Per-frame data are read with [`Self::rest_points`]
    /// and [`Self::blend_shape_weights`].
    pub fn mesh(&self, path: &str) -> Result<MeshData> {
        let prim = self.prim(path)?;
        let ty = self.type_name(&prim)?;
        if ty != "Mesh" {
            return Err(UsdError::contract(path, "", format!("is a {ty:?}, expected a Mesh")));
        }
        let counts_v = self
            .static_value(&prim, "faceVertexCounts")?
            .ok_or_else(|| UsdError::contract(path, "faceVertexCounts", "is missing"))?;
        let counts = self.index_array(&prim, "faceVertexCounts", &counts_v, u32::MAX as usize)?;
        let rest_default_v = self.required(&prim, "points", None)?;
        let rest_default = self.points_value(&prim, "points", &rest_default_v)?;
        let n = rest_default.len();
        let indices_v = self
            .static_value(&prim, "faceVertexIndices")?
            .ok_or_else(|| UsdError::contract(path, "faceVertexIndices", "is missing"))?;
        let mut indices = self.index_array(&prim, "faceVertexIndices", &indices_v, n)?;
        let sum: u64 = counts.iter().map(|&c| c as u64).sum();
        if sum != indices.len() as u64 {
            return Err(UsdError::contract(
                path,
                "faceVertexIndices",
                format!("has {} entries but faceVertexCounts sum to {sum}", indices.len()),
            ));
        }
        if let Some(o) = self.value(&prim, "orientation", None)?.as_ref().and_then(value::token) {
            match o.as_str() {
                "rightHanded" => {}
                "leftHanded" => {
                    let mut at = 0usize;
                    for &c in &counts {
                        indices[at..at + c as usize].reverse();
                        at += c as usize;
                    }
                }
                other => {
                    return Err(UsdError::contract(
                        path,
                        "orientation",
                        format!("is {other:?}, expected rightHanded or leftHanded"),
                    ));
                }
            }
        }
        let projection_points = match self.static_value(&prim, PROJECTION)? {
            Some(v) => {
                let mut p = self.points_value(&prim, PROJECTION, &v)?;
                // An indexed primvar is flattened: entry i is values[indices[i]].
                let indices_name = format!("{PROJECTION}:indices");
                if let Some(ix) = self.static_value(&prim, &indices_name)? {
                    let ix = self.index_array(&prim, &indices_name, &ix, p.len())?;
                    p = ix.iter().map(|&i| p[i as usize]).collect();
                }
                if p.len() != n {
                    return Err(UsdError::contract(
                        path,
                        PROJECTION,
                        format!("has {} points, the mesh has {n}", p.len()),
                    ));
                }
                p
            }
            None => rest_default,
        };
        let rest_sample_times = self.sample_times(&prim, "points")?;
        let curvenets = self.targets(&prim, CURVENETS_REL)?;
        let (blend_shapes, blend_shape_animation) = self.blend_shapes(&prim, n)?;
        Ok(MeshData {
            path: path.to_string(),
            face_vertex_counts: counts,
            face_vertex_indices: indices,
            projection_points,
            rest_sample_times,
            curvenets,
            blend_shapes,
            blend_shape_animation,
        })
    }

    pub(super) fn targets(&self, prim: &usd::Prim, rel: &str) -> Result<Vec<String>> {
        let targets =
            prim.relationship(rel).targets().map_err(|e| UsdError::contract(prim.path(), rel, e.to_string()))?;
        Ok(targets.iter().map(|t| t.as_str().to_string()).collect())
    }

    /// The rest pose of `mesh` at `time` (`None`: the default value): its
    /// composed `points`.
    pub fn rest_points(&self, mesh: &MeshData, time: Option<f64>) -> Result<Vec<[f64; 3]>> {
        let prim = self.prim(&mesh.path)?;
        let v = self.required(&prim, "points", time)?;
        let p = self.points_value(&prim, "points", &v)?;
        if p.len() != mesh.projection_points.len() {
            return Err(UsdError::contract(
                &mesh.path,
                "points",
                format!("has {} points{}, the mesh has {}", p.len(), at(time), mesh.projection_points.len()),
            ));
        }
        Ok(p)
    }

    /// Reads the curvenet at `path`: the neutral pool, the splines, the
    /// sample density and the times of its posed samples.
    pub fn curvenet(&self, path: &str) -> Result<CurvenetData> {
        let prim = self.prim(path)?;
        let ty = self.type_name(&prim)?;
        if ty != "BasisCurves" {
            return Err(UsdError::contract(path, "", format!("is a {ty:?}, a curvenet must be a BasisCurves")));
        }
        for (name, want) in [("type", "cubic"), ("basis", "bezier"), ("wrap", "nonperiodic")] {
            // Unauthored means the schema fallback, which is the value we want.
            if let Some(v) = self.value(&prim, name, None)? {
                let got = value::token(&v).unwrap_or_default();
                if got != want {
                    return Err(UsdError::contract(path, name, format!("is {got:?}, a curvenet needs {want:?}")));
                }
            }
        }
        let pool_v = self.required(&prim, CV, None)?;
        let pool = self.points_value(&prim, CV, &pool_v)?;
        let indices_v =
            self.static_value(&prim, CV_INDICES)?.ok_or_else(|| UsdError::contract(path, CV_INDICES, "is missing"))?;
        let indices = self.index_array(&prim, CV_INDICES, &indices_v, pool.len())?;
        if let Some(v) = self.static_value(&prim, "curveVertexCounts")? {
            let counts = value::ints(&v).unwrap_or_default();
            if let Some(i) = counts.iter().position(|&c| c != 4) {
                return Err(UsdError::contract(
                    path,
                    "curveVertexCounts",
                    format!("entry {i} is {}, every spline needs 4", counts[i]),
                ));
            }
            if counts.len() * 4 != indices.len() {
                return Err(UsdError::contract(
                    path,
                    CV_INDICES,
                    format!("has {} entries, expected 4 per spline ({} splines)", indices.len(), counts.len()),
                ));
            }
        }
        if indices.len() % 4 != 0 {
            return Err(UsdError::contract(
                path,
                CV_INDICES,
                format!("has {} entries, not a multiple of 4", indices.len()),
            ));
        }
        let splines = indices.chunks_exact(4).map(|c| [c[0], c[1], c[2], c[3]]).collect();
        let sample_density = match self.value(&prim, DENSITY, None)? {
            None => DEFAULT_SAMPLE_DENSITY,
            Some(v) => match value::scalar(&v) {
                Some(d) if d.is_finite() && d > 0.0 => d,
                _ => return Err(UsdError::contract(path, DENSITY, format!("is {v:?}, expected a positive float"))),
            },
        };
        let sample_times = self.sample_times(&prim, CV)?;
        Ok(CurvenetData { path: path.to_string(), pool, splines, sample_density, sample_times })
    }

    /// The posed control-point pool of `curvenet` at `time`: `None` when the
    /// pool has no time samples (the curvenet is not articulated and tracks
    /// the surface instead).
    pub fn posed_pool(&self, curvenet: &CurvenetData, time: Option<f64>) -> Result<Option<Vec<[f64; 3]>>> {
        if curvenet.sample_times.is_empty() {
            return Ok(None);
        }
        let prim = self.prim(&curvenet.path)?;
        let v = self.required(&prim, CV, time)?;
        let p = self.points_value(&prim, CV, &v)?;
        if p.len() != curvenet.pool.len() {
            return Err(UsdError::contract(
                &curvenet.path,
                CV,
                format!("has {} control points{}, the neutral pose has {}", p.len(), at(time), curvenet.pool.len()),
            ));
        }
        Ok(Some(p))
    }

    fn blend_shapes(&self, mesh: &usd::Prim, n_points: usize) -> Result<(Vec<BlendShapeData>, Option<String>)> {
        let Some(names_v) = self.value(mesh, "skel:blendShapes", None)? else {
            return Ok((Vec::new(), None));
        };
        let names = value::tokens(&names_v)
            .ok_or_else(|| UsdError::contract(mesh.path(), "skel:blendShapes", "is not a token[]"))?;
        let targets = self.targets(mesh, "skel:blendShapeTargets")?;
        if targets.len() != names.len() {
            return Err(UsdError::contract(
                mesh.path(),
                "skel:blendShapeTargets",
                format!("has {} targets but skel:blendShapes names {}", targets.len(), names.len()),
            ));
        }
        let mut seen = HashSet::new();
        let mut shapes = Vec::with_capacity(names.len());
        for (name, target) in names.iter().zip(&targets) {
            if !seen.insert(name.as_str()) {
                return Err(UsdError::contract(mesh.path(), "skel:blendShapes", format!("names {name:?} twice")));
            }
            shapes.push(self.blend_shape(name, target, n_points)?);
        }
        let animation = self.blend_shape_animation(mesh)?;
        Ok((shapes, animation))
    }

    fn blend_shape(&self, name: &str, path: &str, n_points: usize) -> Result<BlendShapeData> {
        let prim = self.prim(path)?;
        let offsets_v = self.required(&prim, "offsets", None)?;
        let offsets = self.points_value(&prim, "offsets", &offsets_v)?;
        let point_indices = match self.value(&prim, "pointIndices", None)? {
            None => None,
            Some(v) => Some(self.index_array(&prim, "pointIndices", &v, n_points)?),
        };
        let expected = point_indices.as_ref().map_or(n_points, Vec::len);
        if offsets.len() != expected {
            let why = if point_indices.is_some() { "pointIndices has" } else { "the mesh has" };
            return Err(UsdError::contract(
                path,
                "offsets",
                format!("has {} entries, {why} {expected}", offsets.len()),
            ));
        }
        let mut inbetweens = Vec::new();
        let props = prim.authored_property_names().map_err(|e| UsdError::contract(path, "", e.to_string()))?;
        for prop in &props {
            let Some(ib_name) = prop.as_str().strip_prefix("inbetweens:") else { continue };
            if ib_name.contains(':') {
                continue; // inbetweens:NAME:normalOffsets
            }
            let attr = prim.attribute(prop.as_str());
            let weight = attr
                .get_metadata::<Value>("weight")
                .map_err(|e| UsdError::contract(path, prop.as_str(), e.to_string()))?
                .as_ref()
                .and_then(value::scalar)
                .ok_or_else(|| UsdError::contract(path, prop.as_str(), "has no weight metadata"))?;
            let v = self.required(&prim, prop.as_str(), None)?;
            let ib_offsets = self.points_value(&prim, prop.as_str(), &v)?;
            if ib_offsets.len() != offsets.len() {
                return Err(UsdError::contract(
                    path,
                    prop.as_str(),
                    format!("has {} offsets, the shape has {}", ib_offsets.len(), offsets.len()),
                ));
            }
            inbetweens.push(InbetweenData { name: ib_name.to_string(), weight, offsets: ib_offsets });
        }
        inbetweens.sort_by(|a, b| a.weight.total_cmp(&b.weight));
        Ok(BlendShapeData { name: name.to_string(), prim: path.to_string(), offsets, point_indices, inbetweens })
    }

    /// Follows `skel:skeleton` (on the mesh or inherited from an ancestor) to
    /// the Skeleton and its `skel:animationSource`.
    fn blend_shape_animation(&self, mesh: &usd::Prim) -> Result<Option<String>> {
        let mut at = Some(mesh.clone());
        while let Some(prim) = at {
            let skel = self.targets(&prim, "skel:skeleton")?;
            if let Some(skel_path) = skel.first() {
                let skel_prim = self.prim(skel_path)?;
                return Ok(self.targets(&skel_prim, "skel:animationSource")?.into_iter().next());
            }
            at = prim.parent();
        }
        Ok(None)
    }

    /// The blend-shape weights of `mesh` at `time`, one per entry of
    /// `mesh.blend_shapes` (0 for a shape the animation does not name, as in UsdSkel).
    pub fn blend_shape_weights(&self, mesh: &MeshData, time: Option<f64>) -> Result<Vec<f64>> {
        let mut weights = vec![0.0; mesh.blend_shapes.len()];
        let Some(anim_path) = &mesh.blend_shape_animation else { return Ok(weights) };
        let anim = self.prim(anim_path)?;
        let Some(names_v) = self.value(&anim, "blendShapes", None)? else { return Ok(weights) };
        let names =
            value::tokens(&names_v).ok_or_else(|| UsdError::contract(anim_path, "blendShapes", "is not a token[]"))?;
        let Some(w_v) = self.value(&anim, "blendShapeWeights", time)? else { return Ok(weights) };
        let w = value::floats(&w_v)
            .ok_or_else(|| UsdError::contract(anim_path, "blendShapeWeights", "is not a float[]"))?;
        if w.len() != names.len() {
            return Err(UsdError::contract(
                anim_path,
                "blendShapeWeights",
                format!("has {} weights{} but blendShapes names {}", w.len(), at(time), names.len()),
            ));
        }
        for (name, &x) in names.iter().zip(&w) {
            if !x.is_finite() {
                return Err(UsdError::contract(
                    anim_path,
                    "blendShapeWeights",
                    format!("weight of {name:?} is {x}{}", at(time)),
                ));
            }
            if let Some(k) = mesh.blend_shapes.iter().position(|s| &s.name == name) {
                weights[k] = x;
            }
        }
        Ok(weights)
    }
}

pub(super) fn at(time: Option<f64>) -> String {
    match time {
        Some(t) => format!(" at time {t}"),
        None => String::new(),
    }
}
