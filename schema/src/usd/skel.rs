//! UsdSkel read into plain data for `curvenet_core::skinning`: a mesh's
//! skeleton, animation, skin weights, `geomBindTransform` and skinning
//! method ([`Stage::skin_rig`], then [`Stage::joint_local_transforms`] per
//! frame), and how each curvenet is spline-skinned ([`Stage::curvenet_skinning`]).
//! The encoding is documented in schema/README.md ("Skinning").

use openusd::sdf::Value;
use openusd::usd;
use openusd_schemas::skel::AnimMapper;

use super::error::UsdError;
use super::read::{Stage, at};
use super::value;
use crate::data::{CurvenetData, MeshData};
use curvenet_core::{MAT4_IDENTITY, Mat4, SkinningMethod};

type Result<T> = std::result::Result<T, UsdError>;

const JOINT_INDICES: &str = "primvars:skel:jointIndices";
const JOINT_WEIGHTS: &str = "primvars:skel:jointWeights";
const GEOM_BIND: &str = "primvars:skel:geomBindTransform";
/// UsdSkel's skinning method: `primvars:skel:skinningMethod` in current
/// UsdSkel (usd-core writes this one), `skel:skinningMethod` in older files.
const METHODS: [&str; 2] = ["primvars:skel:skinningMethod", "skel:skinningMethod"];
const MESH_JOINTS: &str = "skel:joints";
/// Per-control-point joint indices of a curvenet, indexed like its pool.
pub const CURVENET_JOINT_INDICES: &str = "primvars:curvenet:skel:jointIndices";
/// Per-control-point joint weights of a curvenet, indexed like its pool.
pub const CURVENET_JOINT_WEIGHTS: &str = "primvars:curvenet:skel:jointWeights";
/// `uniform token curvenet:skinning`: `weights`, `mesh` or `none`.
pub const CURVENET_SKINNING: &str = "curvenet:skinning";
/// `uniform token curvenet:blendShapeOrder` on a mesh: `beforeSkinning` or `afterSolve`.
pub const BLEND_SHAPE_ORDER: &str = "curvenet:blendShapeOrder";
/// `uniform token curvenet:skinningMethod` on a skinned mesh: our tools'
/// skinning method, overriding UsdSkel's `primvars:skel:skinningMethod`
/// (whose allowed tokens cannot grow to `centersOfRotation`).
pub const CURVENET_SKINNING_METHOD: &str = "curvenet:skinningMethod";

/// A mesh's `curvenet:skinningMethod` (schema/README.md, "Cage"): the
/// skinning method our tools use instead of UsdSkel's token.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CurvenetSkinningMethod {
    /// `classicLinear`: linear blend skinning, as UsdSkel's token of that name.
    ClassicLinear,
    /// `dualQuaternion`: dual quaternions, as UsdSkel's token of that name.
    DualQuaternion,
    /// `centersOfRotation`: optimised centres of rotation (Le and Hodgins 2016).
    CentersOfRotation,
}

impl CurvenetSkinningMethod {
    /// The token as authored.
    pub fn token(self) -> &'static str {
        match self {
            Self::ClassicLinear => "classicLinear",
            Self::DualQuaternion => "dualQuaternion",
            Self::CentersOfRotation => "centersOfRotation",
        }
    }

    /// The method a token names, if any.
    pub fn from_token(token: &str) -> Option<Self> {
        [Self::ClassicLinear, Self::DualQuaternion, Self::CentersOfRotation].into_iter().find(|m| m.token() == token)
    }
}

/// The UsdSkel rig of a mesh: everything `curvenet_core::skinning` needs
/// but the per-frame joint transforms.
#[derive(Debug, Clone, PartialEq)]
pub struct SkinRig {
    /// The skinned mesh.
    pub mesh: String,
    /// Its `SkelRoot` ancestor.
    pub skel_root: String,
    /// The bound `Skeleton` (the mesh's `skel:skeleton`, or an ancestor's).
    pub skeleton: String,
    /// The Skeleton's `skel:animationSource` (`None`: the rest pose, every frame).
    pub animation: Option<String>,
    /// The Skeleton's `joints` (paths), the order of every per-joint array here.
    pub joints: Vec<String>,
    /// Each joint's parent (an earlier joint), from the joint paths.
    pub parents: Vec<Option<u32>>,
    /// `bindTransforms` (skeleton space, row-major, row vectors).
    pub bind_transforms: Vec<Mat4>,
    /// `restTransforms` (joint-local), when authored.
    pub rest_transforms: Option<Vec<Mat4>>,
    /// Influences per mesh point.
    pub element_size: usize,
    /// `jointIndices`, one run of `element_size` per mesh point, **into
    /// `joints`** (a `skel:joints` subset is remapped; `constant`
    /// interpolation expanded to every point).
    pub joint_indices: Vec<i64>,
    /// `jointWeights`, as authored.
    pub joint_weights: Vec<f64>,
    /// `primvars:skel:geomBindTransform` (the identity when unauthored).
    pub geom_bind_transform: Mat4,
    /// `primvars:skel:skinningMethod` (or the older `skel:skinningMethod`;
    /// `classicLinear` when unauthored).
    pub method: SkinningMethod,
    /// `curvenet:skinningMethod`, when authored: the method our tools use
    /// instead of [`Self::method`] (which stays UsdSkel's, for comparison).
    pub curvenet_method: Option<CurvenetSkinningMethod>,
    /// Whether the influences were authored `constant` (rigid) and expanded.
    pub constant_influences: bool,
    /// Time codes at which the animation's joint transforms have samples.
    pub time_samples: Vec<f64>,
    /// Animation joint → Skeleton joint.
    anim_joints: Vec<Option<usize>>,
}

/// How a curvenet follows the skeleton (schema/README.md, "Skinning").
#[derive(Debug, Clone, PartialEq)]
pub enum CurvenetSkinning {
    /// Not spline-skinned: its own time samples, else knot tracking.
    None,
    /// Per-control-point weights authored on the curvenet, into the
    /// Skeleton's `joints` (`element_size` per pool point).
    Weights { element_size: usize, joint_indices: Vec<i64>, joint_weights: Vec<f64> },
    /// Weights taken from the mesh's skin weights at the closest surface points.
    FromMesh,
}

/// Where blend shapes go for a mesh (`curvenet:blendShapeOrder`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BlendShapeOrder {
    /// UsdSkel's order: added to the mesh's points before skinning (before
    /// the curvenet solve when the mesh is not skinned in process).
    BeforeSkinning,
    /// Added after the curvenet solve, mapped by each vertex's deformation gradient.
    AfterSolve,
}

impl Stage {
    /// The UsdSkel rig that skins `mesh` in process, or `None` when the mesh
    /// has no `primvars:skel:jointIndices` (blend shapes alone need no rig).
    ///
    /// Follows the mesh's `skel:skeleton` (or the nearest ancestor's) to the
    /// Skeleton and its `skel:animationSource`. Refused, naming the prim and
    /// attribute: influences without a Skeleton or outside a `SkelRoot`
    /// (usd-core would not skin them), a Skeleton without `bindTransforms`,
    /// joints whose paths list a child before its parent, influence arrays
    /// of the wrong size, `skel:joints` naming a joint the Skeleton lacks,
    /// an unknown skinning method, a non-affine `geomBindTransform`.
    pub fn skin_rig(&self, mesh: &MeshData) -> Result<Option<SkinRig>> {
        let prim = self.prim(&mesh.path)?;
        let curvenet_method = self.curvenet_skinning_method(mesh)?;
        if !self.has_value(&prim, JOINT_INDICES)? {
            if curvenet_method.is_some() {
                return Err(UsdError::contract(
                    &mesh.path,
                    CURVENET_SKINNING_METHOD,
                    format!("is authored but the mesh has no skin ({JOINT_INDICES} is not authored)"),
                ));
            }
            return Ok(None);
        }
        let n_points = mesh.projection_points.len();
        let skeleton = self.inherited_target(&prim, "skel:skeleton")?.ok_or_else(|| {
            UsdError::contract(&mesh.path, JOINT_INDICES, "is authored but no skel:skeleton binds a Skeleton")
        })?;
        let skel_root = self.skel_root(&prim)?.ok_or_else(|| {
            UsdError::contract(
                &mesh.path,
                JOINT_INDICES,
                "is authored but the mesh is not under a SkelRoot, so UsdSkel would not skin it \
                 (make an ancestor a SkelRoot, or remove the binding)",
            )
        })?;
        let skel_prim = self.prim(&skeleton)?;
        let ty = self.type_name(&skel_prim)?;
        if ty != "Skeleton" {
            return Err(UsdError::contract(
                &skeleton,
                "",
                format!("is a {ty:?}, skel:skeleton must target a Skeleton"),
            ));
        }
        let joints = match self.value(&skel_prim, "joints", None)? {
            Some(v) => value::tokens(&v).ok_or_else(|| UsdError::contract(&skeleton, "joints", "is not a token[]"))?,
            None => return Err(UsdError::contract(&skeleton, "joints", "is missing")),
        };
        let parents = joint_parents(&skeleton, &joints)?;
        let bind_transforms = self
            .matrices(&skel_prim, "bindTransforms", None)?
            .ok_or_else(|| UsdError::contract(&skeleton, "bindTransforms", "is missing"))?;
        let rest_transforms = self.matrices(&skel_prim, "restTransforms", None)?;
        for (name, got) in [
            ("bindTransforms", Some(bind_transforms.len())),
            ("restTransforms", rest_transforms.as_ref().map(Vec::len)),
        ] {
            if let Some(got) = got
                && got != joints.len()
            {
                return Err(UsdError::contract(
                    &skeleton,
                    name,
                    format!("has {got} matrices, the Skeleton has {} joints", joints.len()),
                ));
            }
        }

        // Influences.
        let indices_attr = prim.attribute(JOINT_INDICES);
        let meta = |name: &str| {
            indices_attr
                .get_metadata::<Value>(name)
                .map_err(|e| UsdError::contract(&mesh.path, JOINT_INDICES, e.to_string()))
        };
        let element_size = match meta("elementSize")? {
            None => 1,
            Some(v) => match value::scalar(&v) {
                Some(x) if x >= 1.0 && x.fract() == 0.0 => x as usize,
                _ => return Err(UsdError::contract(&mesh.path, JOINT_INDICES, format!("elementSize is {v:?}"))),
            },
        };
        let constant = match meta("interpolation")?.as_ref().and_then(value::token).as_deref() {
            None | Some("constant") => true,
            Some("vertex") => false,
            Some(other) => {
                return Err(UsdError::contract(
                    &mesh.path,
                    JOINT_INDICES,
                    format!("has interpolation {other:?}, UsdSkel takes vertex or constant"),
                ));
            }
        };
        let indices_v = self.static_value(&prim, JOINT_INDICES)?.expect("authored");
        let mut joint_indices =
            value::ints(&indices_v).ok_or_else(|| UsdError::contract(&mesh.path, JOINT_INDICES, "is not an int[]"))?;
        let weights_v = self
            .static_value(&prim, JOINT_WEIGHTS)?
            .ok_or_else(|| UsdError::contract(&mesh.path, JOINT_WEIGHTS, "is missing (jointIndices is authored)"))?;
        let mut joint_weights = value::floats(&weights_v)
            .ok_or_else(|| UsdError::contract(&mesh.path, JOINT_WEIGHTS, "is not a float[]"))?;
        let expected = if constant { element_size } else { element_size * n_points };
        for (name, got) in [(JOINT_INDICES, joint_indices.len()), (JOINT_WEIGHTS, joint_weights.len())] {
            if got != expected {
                let per = if constant { "constant".to_string() } else { format!("{n_points} points") };
                return Err(UsdError::contract(
                    &mesh.path,
                    name,
                    format!("has {got} entries, expected {expected} ({per} x elementSize {element_size})"),
                ));
            }
        }
        if constant {
            joint_indices = joint_indices.repeat(n_points);
            joint_weights = joint_weights.repeat(n_points);
        }
        // skel:joints: the influences index this subset of the Skeleton's joints.
        if let Some(v) = self.static_value(&prim, MESH_JOINTS)? {
            let subset =
                value::tokens(&v).ok_or_else(|| UsdError::contract(&mesh.path, MESH_JOINTS, "is not a token[]"))?;
            let mapper = AnimMapper::new(&joints, &subset);
            let mut to_skel = Vec::with_capacity(subset.len());
            for (k, name) in subset.iter().enumerate() {
                match mapper.source_index(k) {
                    Some(j) => to_skel.push(j as i64),
                    None => {
                        return Err(UsdError::contract(
                            &mesh.path,
                            MESH_JOINTS,
                            format!("names joint {name:?}, which the Skeleton {skeleton} does not have"),
                        ));
                    }
                }
            }
            for (k, j) in joint_indices.iter_mut().enumerate() {
                if *j < 0 || *j as usize >= to_skel.len() {
                    return Err(UsdError::contract(
                        &mesh.path,
                        JOINT_INDICES,
                        format!("entry {k} is {j}, outside the {} joints of skel:joints", to_skel.len()),
                    ));
                }
                *j = to_skel[*j as usize];
            }
        }
        let geom_bind_transform = match self.static_value(&prim, GEOM_BIND)? {
            None => MAT4_IDENTITY,
            Some(Value::Matrix4d(m)) => m.0,
            Some(v) => {
                return Err(UsdError::contract(
                    &mesh.path,
                    GEOM_BIND,
                    format!("has type {}, expected matrix4d", value::kind(&v)),
                ));
            }
        };
        curvenet_core::check_affine(&geom_bind_transform, "geomBindTransform", 0)
            .map_err(|e| UsdError::contract(&mesh.path, GEOM_BIND, e.to_string()))?;
        let mut method = SkinningMethod::ClassicLinear;
        for name in METHODS {
            if let Some(v) = self.value(&prim, name, None)? {
                let t = value::token(&v).unwrap_or_default();
                method = SkinningMethod::from_token(&t).ok_or_else(|| {
                    UsdError::contract(&mesh.path, name, format!("is {t:?}, expected classicLinear or dualQuaternion"))
                })?;
                break;
            }
        }

        // The animation.
        let animation = self.targets(&skel_prim, "skel:animationSource")?.into_iter().next();
        let (anim_joints, time_samples) = match &animation {
            None => (Vec::new(), Vec::new()),
            Some(anim) => {
                let anim_prim = self.prim(anim)?;
                let ty = self.type_name(&anim_prim)?;
                if ty != "SkelAnimation" {
                    return Err(UsdError::contract(
                        &skeleton,
                        "skel:animationSource",
                        format!("targets {anim}, a {ty:?}, not a SkelAnimation"),
                    ));
                }
                let names = match self.value(&anim_prim, "joints", None)? {
                    Some(v) => {
                        value::tokens(&v).ok_or_else(|| UsdError::contract(anim, "joints", "is not a token[]"))?
                    }
                    None => Vec::new(),
                };
                let mapper = AnimMapper::new(&joints, &names);
                let map: Vec<Option<usize>> = (0..names.len()).map(|k| mapper.source_index(k)).collect();
                let mut times = Vec::new();
                for name in ["translations", "rotations", "scales"] {
                    times.extend(self.sample_times(&anim_prim, name)?);
                }
                times.sort_by(f64::total_cmp);
                times.dedup();
                (map, times)
            }
        };
        let animated: Vec<bool> = (0..joints.len()).map(|j| anim_joints.contains(&Some(j))).collect();
        if rest_transforms.is_none()
            && let Some(j) = animated.iter().position(|a| !a)
        {
            return Err(UsdError::contract(
                &skeleton,
                "restTransforms",
                format!("is missing, and joint {:?} has no animation to take its transform from", joints[j]),
            ));
        }
        Ok(Some(SkinRig {
            mesh: mesh.path.clone(),
            skel_root,
            skeleton,
            animation,
            joints,
            parents,
            bind_transforms,
            rest_transforms,
            element_size,
            joint_indices,
            joint_weights,
            geom_bind_transform,
            method,
            curvenet_method,
            constant_influences: constant,
            time_samples,
            anim_joints,
        }))
    }

    /// The joint-local transforms of `rig`'s joints (in `rig.joints` order)
    /// at `time`: the animation's `scale · rotation · translation` (USD's row
    /// vectors; quaternions normalised) for the joints it animates, the
    /// Skeleton's `restTransforms` for the others.
    pub fn joint_local_transforms(&self, rig: &SkinRig, time: Option<f64>) -> Result<Vec<Mat4>> {
        let mut local = rig.rest_transforms.clone().unwrap_or_else(|| vec![MAT4_IDENTITY; rig.joints.len()]);
        let Some(anim) = &rig.animation else { return Ok(local) };
        let prim = self.prim(anim)?;
        let n = rig.anim_joints.len();
        let read = |name: &str| -> Result<Option<Value>> {
            let v = self.value(&prim, name, time)?;
            Ok(v)
        };
        let translations = match read("translations")? {
            None => vec![[0.0; 3]; n],
            Some(v) => value::points(&v)
                .ok_or_else(|| UsdError::contract(anim, "translations", format!("has type {}", value::kind(&v))))?,
        };
        let scales = match read("scales")? {
            None => vec![[1.0; 3]; n],
            Some(v) => value::points(&v)
                .ok_or_else(|| UsdError::contract(anim, "scales", format!("has type {}", value::kind(&v))))?,
        };
        let rotations = match read("rotations")? {
            None => vec![[1.0, 0.0, 0.0, 0.0]; n],
            Some(v) => quaternions(&v)
                .ok_or_else(|| UsdError::contract(anim, "rotations", format!("has type {}", value::kind(&v))))?,
        };
        for (name, got) in
            [("translations", translations.len()), ("rotations", rotations.len()), ("scales", scales.len())]
        {
            if got != n {
                return Err(UsdError::contract(anim, name, format!("has {got} entries{}, joints names {n}", at(time))));
            }
        }
        for (k, target) in rig.anim_joints.iter().enumerate() {
            let Some(j) = target else { continue };
            let [w, x, y, z] = rotations[k];
            let len = (w * w + x * x + y * y + z * z).sqrt();
            let finite =
                len > 0.0 && translations[k].iter().chain(&scales[k]).all(|c| c.is_finite()) && len.is_finite();
            if !finite {
                return Err(UsdError::contract(
                    anim,
                    "rotations",
                    format!("joint {k} has no valid transform{}", at(time)),
                ));
            }
            local[*j] = trs(translations[k], [w / len, x / len, y / len, z / len], scales[k]);
        }
        Ok(local)
    }

    /// The transform from the Skeleton's space to the mesh's at `time`:
    /// `skelLocalToWorld · inverse(meshLocalToWorld)` (skinned points come
    /// out in skeleton space; the curvenet works in the mesh's).
    pub fn skel_to_mesh_transform(&self, rig: &SkinRig, time: Option<f64>) -> Result<Mat4> {
        let world = |path: &str| -> Result<Mat4> {
            let prim = self.prim(path)?;
            let mut cache = openusd_schemas::geom::XformCache::new(time.map(usd::TimeCode::new));
            let m = cache
                .local_to_world_transform(&prim)
                .map_err(|e| UsdError::contract(path, "xformOpOrder", e.to_string()))?;
            Ok(m.0)
        };
        let (skel, mesh) = (world(&rig.skeleton)?, world(&rig.mesh)?);
        if skel == mesh {
            return Ok(MAT4_IDENTITY);
        }
        let inv = curvenet_core::mat4_inverse(&mesh).ok_or_else(|| {
            UsdError::contract(&rig.mesh, "xformOpOrder", "the mesh's local-to-world transform is singular")
        })?;
        Ok(curvenet_core::mat4_mul(&skel, &inv))
    }

    /// How `curvenet` is spline-skinned: `curvenet:skinning` (`weights`,
    /// `mesh`, `none`), else `weights` when the per-control-point weights are
    /// authored, else not at all. The weights' joint indices are into the
    /// Skeleton's joints of the mesh it deforms; they are checked against
    /// it when the curvenet is bound.
    pub fn curvenet_skinning(&self, curvenet: &CurvenetData) -> Result<CurvenetSkinning> {
        let prim = self.prim(&curvenet.path)?;
        let mode = match self.value(&prim, CURVENET_SKINNING, None)? {
            None => None,
            Some(v) => Some(
                value::token(&v)
                    .ok_or_else(|| UsdError::contract(&curvenet.path, CURVENET_SKINNING, "is not a token"))?,
            ),
        };
        let authored =
            self.has_value(&prim, CURVENET_JOINT_INDICES)? || self.has_value(&prim, CURVENET_JOINT_WEIGHTS)?;
        match (mode.as_deref(), authored) {
            (Some("none"), _) | (None, false) => Ok(CurvenetSkinning::None),
            (Some("mesh"), false) => Ok(CurvenetSkinning::FromMesh),
            (Some("mesh"), true) => Err(UsdError::contract(
                &curvenet.path,
                CURVENET_SKINNING,
                format!("is \"mesh\" but {CURVENET_JOINT_INDICES} / jointWeights are authored too: keep one"),
            )),
            (Some("weights") | None, _) => self.curvenet_weights(curvenet, &prim),
            (Some(other), _) => Err(UsdError::contract(
                &curvenet.path,
                CURVENET_SKINNING,
                format!("is {other:?}, expected \"weights\", \"mesh\" or \"none\""),
            )),
        }
    }

    fn curvenet_weights(&self, curvenet: &CurvenetData, prim: &usd::Prim) -> Result<CurvenetSkinning> {
        let path = &curvenet.path;
        let indices_v = self.static_value(prim, CURVENET_JOINT_INDICES)?.ok_or_else(|| {
            UsdError::contract(path, CURVENET_JOINT_INDICES, "is missing (the curvenet asks for weights)")
        })?;
        let weights_v = self.static_value(prim, CURVENET_JOINT_WEIGHTS)?.ok_or_else(|| {
            UsdError::contract(path, CURVENET_JOINT_WEIGHTS, "is missing (the curvenet asks for weights)")
        })?;
        let joint_indices = value::ints(&indices_v)
            .ok_or_else(|| UsdError::contract(path, CURVENET_JOINT_INDICES, "is not an int[]"))?;
        let joint_weights = value::floats(&weights_v)
            .ok_or_else(|| UsdError::contract(path, CURVENET_JOINT_WEIGHTS, "is not a float[]"))?;
        let element_size = match prim
            .attribute(CURVENET_JOINT_INDICES)
            .get_metadata::<Value>("elementSize")
            .map_err(|e| UsdError::contract(path, CURVENET_JOINT_INDICES, e.to_string()))?
        {
            None => 1,
            Some(v) => match value::scalar(&v) {
                Some(x) if x >= 1.0 && x.fract() == 0.0 => x as usize,
                _ => return Err(UsdError::contract(path, CURVENET_JOINT_INDICES, format!("elementSize is {v:?}"))),
            },
        };
        let expected = element_size * curvenet.pool.len();
        for (name, got) in
            [(CURVENET_JOINT_INDICES, joint_indices.len()), (CURVENET_JOINT_WEIGHTS, joint_weights.len())]
        {
            if got != expected {
                return Err(UsdError::contract(
                    path,
                    name,
                    format!(
                        "has {got} entries, expected {expected} ({} control points x elementSize {element_size})",
                        curvenet.pool.len()
                    ),
                ));
            }
        }
        if !curvenet.sample_times.is_empty() {
            return Err(UsdError::contract(
                path,
                "primvars:curvenet:cv",
                "has time samples and the curvenet is spline-skinned: keep one (remove the samples, or set \
                 curvenet:skinning = \"none\")",
            ));
        }
        Ok(CurvenetSkinning::Weights { element_size, joint_indices, joint_weights })
    }

    /// `curvenet:skinningMethod` of `mesh`, if authored (also in
    /// [`SkinRig::curvenet_method`]). Refused: time samples, a value that is
    /// not a token, a token other than `classicLinear`, `dualQuaternion` or
    /// `centersOfRotation`.
    pub fn curvenet_skinning_method(&self, mesh: &MeshData) -> Result<Option<CurvenetSkinningMethod>> {
        let prim = self.prim(&mesh.path)?;
        let Some(v) = self.static_value(&prim, CURVENET_SKINNING_METHOD)? else { return Ok(None) };
        let Value::Token(t) = &v else {
            return Err(UsdError::contract(
                &mesh.path,
                CURVENET_SKINNING_METHOD,
                format!("has type {}, expected a uniform token", value::kind(&v)),
            ));
        };
        CurvenetSkinningMethod::from_token(t.as_str()).map(Some).ok_or_else(|| {
            UsdError::contract(
                &mesh.path,
                CURVENET_SKINNING_METHOD,
                format!("is {:?}, expected classicLinear, dualQuaternion or centersOfRotation", t.as_str()),
            )
        })
    }

    /// `curvenet:blendShapeOrder` of `mesh`, if authored.
    pub fn blend_shape_order(&self, mesh: &MeshData) -> Result<Option<BlendShapeOrder>> {
        let prim = self.prim(&mesh.path)?;
        match self.value(&prim, BLEND_SHAPE_ORDER, None)? {
            None => Ok(None),
            Some(v) => match value::token(&v).as_deref() {
                Some("beforeSkinning") => Ok(Some(BlendShapeOrder::BeforeSkinning)),
                Some("afterSolve") => Ok(Some(BlendShapeOrder::AfterSolve)),
                _ => Err(UsdError::contract(
                    &mesh.path,
                    BLEND_SHAPE_ORDER,
                    format!("is {v:?}, expected \"beforeSkinning\" or \"afterSolve\""),
                )),
            },
        }
    }

    fn inherited_target(&self, prim: &usd::Prim, rel: &str) -> Result<Option<String>> {
        let mut at = Some(prim.clone());
        while let Some(p) = at {
            if let Some(t) = self.targets(&p, rel)?.into_iter().next() {
                return Ok(Some(t));
            }
            at = p.parent();
        }
        Ok(None)
    }

    fn skel_root(&self, prim: &usd::Prim) -> Result<Option<String>> {
        let mut at = prim.parent();
        while let Some(p) = at {
            if self.type_name(&p)? == "SkelRoot" {
                return Ok(Some(p.path().as_str().to_string()));
            }
            at = p.parent();
        }
        Ok(None)
    }

    fn matrices(&self, prim: &usd::Prim, name: &str, time: Option<f64>) -> Result<Option<Vec<Mat4>>> {
        match self.value(prim, name, time)? {
            None => Ok(None),
            Some(Value::Matrix4dVec(v)) => Ok(Some(v.iter().map(|m| m.0).collect())),
            Some(v) => {
                Err(UsdError::contract(prim.path(), name, format!("has type {}, expected matrix4d[]", value::kind(&v))))
            }
        }
    }
}

/// Parents from the joint paths (`"A/B"`'s parent is `"A"`); a parent must
/// come before its child, as UsdSkel requires.
fn joint_parents(skeleton: &str, joints: &[String]) -> Result<Vec<Option<u32>>> {
    let mut parents = Vec::with_capacity(joints.len());
    for (j, name) in joints.iter().enumerate() {
        let parent = match name.rsplit_once('/') {
            None => None,
            Some((p, _)) => match joints.iter().position(|x| x == p) {
                Some(i) if i < j => Some(i as u32),
                Some(_) => {
                    return Err(UsdError::contract(
                        skeleton,
                        "joints",
                        format!("lists joint {name:?} before its parent {p:?}"),
                    ));
                }
                None => None,
            },
        };
        if joints[..j].contains(name) {
            return Err(UsdError::contract(skeleton, "joints", format!("lists joint {name:?} twice")));
        }
        parents.push(parent);
    }
    Ok(parents)
}

/// `(w, x, y, z)` quaternions of any precision.
fn quaternions(v: &Value) -> Option<Vec<[f64; 4]>> {
    Some(match v {
        Value::QuatfVec(q) => q.iter().map(|q| [q.w as f64, q.x as f64, q.y as f64, q.z as f64]).collect(),
        Value::QuatdVec(q) => q.iter().map(|q| [q.w, q.x, q.y, q.z]).collect(),
        Value::QuathVec(q) => q.iter().map(|q| [q.w.to_f64(), q.x.to_f64(), q.y.to_f64(), q.z.to_f64()]).collect(),
        _ => return None,
    })
}

/// `scale · rotation · translation`, row vectors (UsdSkel's `MakeTransform`).
fn trs(t: [f64; 3], q: [f64; 4], s: [f64; 3]) -> Mat4 {
    let [w, x, y, z] = q;
    // Rows are the images of the axes under the rotation (row vectors).
    let r = [
        [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y + w * z), 2.0 * (x * z - w * y)],
        [2.0 * (x * y - w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z + w * x)],
        [2.0 * (x * z + w * y), 2.0 * (y * z - w * x), 1.0 - 2.0 * (x * x + y * y)],
    ];
    let mut m = MAT4_IDENTITY;
    for row in 0..3 {
        for c in 0..3 {
            m[4 * row + c] = s[row] * r[row][c];
        }
    }
    m[12..15].copy_from_slice(&t);
    m
}
