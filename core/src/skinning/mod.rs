//! The rig underneath the curvenet: skinning of the mesh (linear blend and
//! dual quaternions, UsdSkel's semantics) and skinning of the curvenet's
//! Bézier splines (Liu, Jacobson, Gingold 2015), over plain arrays.
//!
//! ```text
//! Skeleton::new(parents, bind transforms)                 once per rig
//! Influences::new(#P, element size, joint indices, weights, #J)
//! Skin::new(influences, geomBindTransform, method)        once per mesh
//! SplineSkinning::new(pool, splines, &weights, ...)       once per curvenet (the O_i, spline.rs)
//! per frame:
//!   skeleton.skinning_transforms(joint local transforms)  (or from skel-space transforms)
//!   skin.skin_points(points, &transforms, &mut rest)      lbs.rs / dqs.rs
//!   spline.pose(&transforms, &mut pool)                   matrix products only
//! ```
//!
//! # Conventions (USD's)
//!
//! - A transform is a [`Mat4`]: 16 `f64`, **row-major**, acting on **row
//!   vectors**: `p' = [x y z 1] · M`. The translation is `m[12..15]`; an
//!   affine matrix has `m[3] = m[7] = m[11] = 0` and `m[15] = 1`. Products
//!   compose left to right: `mul(a, b)` applies `a` first, then `b`. These
//!   are the 16 numbers of a USD `matrix4d` in the order `usda` prints them.
//! - A **skinning transform** of joint `j` is `inverse(bindTransform_j) ·
//!   jointSkelTransform_j` (UsdSkel's `ComputeSkinningTransforms`): the
//!   identity in the bind pose.
//! - **Influences** are UsdSkel's `primvars:skel:jointIndices` and
//!   `jointWeights` with `vertex` interpolation: `element_size` (joint,
//!   weight) pairs per point, point after point. Joint indices are into the
//!   order the skinning transforms are given in (the Skeleton's `joints`, or
//!   the mesh's `skel:joints` after remapping).
//! - A point is skinned in skeleton space: `geomBindTransform` first, then
//!   the blend. Weights are used as given (UsdSkel does not normalise them
//!   either; see [`Influences::renormalize`]).

pub(crate) mod dqs;
pub(crate) mod influences;
mod lbs;
pub mod spline;
pub(crate) mod transform;
mod weights;

pub use crate::error::SkinningError;
pub use dqs::{DualQuat, SCALE_TOLERANCE, skin_points_dqs};
pub use influences::Influences;
pub use lbs::skin_points_lbs;
pub use spline::{Junction, JunctionKind, SplineEnd, SplineSkinning, SplineSkinningOptions};
pub use transform::{IDENTITY, Mat4, check_affine, inverse, mul, transform_point, transform_vector};
pub use weights::{ControlPointWeights, DERIVED_WEIGHT_SAMPLES, SurfaceWeights, WeightField};

use crate::error::{Error, Result};
use transform::check_finite;

/// How a mesh is skinned (UsdSkel's `skel:skinningMethod`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, serde::Serialize, serde::Deserialize)]
pub enum SkinningMethod {
    /// `classicLinear`: linear blend skinning, the UsdSkel default.
    #[default]
    ClassicLinear,
    /// `dualQuaternion`: dual-quaternion linear blending of the rotation and
    /// translation of each skinning transform, with any scale or shear of
    /// the transform blended linearly first (UsdSkel's semantics, [`skin_points_dqs`]).
    DualQuaternion,
    /// Optimised centres of rotation (Le and Hodgins 2016, as Corda et al.
    /// 2020 use it, [`crate::cage::cor`]): each point rotates by its blended
    /// quaternion about its own centre of rotation, which moves by linear
    /// blending. Not a UsdSkel token: USD spells it with the custom
    /// attribute `uniform token curvenet:skinningMethod = "centersOfRotation"`,
    /// which overrides `skel:skinningMethod` ([`Self::from_curvenet_token`]).
    /// Needs the points' centres ([`Skin::with_centers_of_rotation`]).
    CentersOfRotation,
}

impl SkinningMethod {
    /// The method's token: UsdSkel's for linear and dual-quaternion
    /// skinning, `centersOfRotation` (the `curvenet:skinningMethod`
    /// spelling) for centres of rotation.
    pub fn token(self) -> &'static str {
        match self {
            SkinningMethod::ClassicLinear => "classicLinear",
            SkinningMethod::DualQuaternion => "dualQuaternion",
            SkinningMethod::CentersOfRotation => "centersOfRotation",
        }
    }

    /// The method named by a `curvenet:skinningMethod` token: the UsdSkel
    /// tokens ([`Self::from_token`]) and `centersOfRotation`.
    pub fn from_curvenet_token(token: &str) -> Option<Self> {
        match token {
            "centersOfRotation" => Some(SkinningMethod::CentersOfRotation),
            t => Self::from_token(t),
        }
    }

    /// The method named by a UsdSkel token, if it is one (UsdSkel's
    /// `allowedTokens`: `centersOfRotation` is not one of them).
    pub fn from_token(token: &str) -> Option<Self> {
        match token {
            "classicLinear" => Some(SkinningMethod::ClassicLinear),
            "dualQuaternion" => Some(SkinningMethod::DualQuaternion),
            _ => None,
        }
    }
}

/// The joint hierarchy and bind pose of a skeleton: turns per-frame joint
/// transforms into skinning transforms.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Skeleton {
    parents: Vec<Option<u32>>,
    inverse_bind: Vec<Mat4>,
}

impl Skeleton {
    /// `parents[j]`: the parent of joint `j` (an earlier joint), `None` for a
    /// root. `bind_transforms`: each joint's bind transform in skeleton space
    /// (UsdSkel's `bindTransforms`), affine and invertible.
    pub fn new(parents: &[Option<u32>], bind_transforms: &[Mat4]) -> Result<Self> {
        if parents.len() != bind_transforms.len() {
            return Err(SkinningError::JointCount {
                what: "bind transforms",
                expected: parents.len(),
                got: bind_transforms.len(),
            }
            .into());
        }
        for (j, p) in parents.iter().enumerate() {
            if let Some(p) = p
                && *p as usize >= j
            {
                return Err(SkinningError::BadParent { joint: j, parent: *p as usize }.into());
            }
        }
        let inverse_bind = bind_transforms
            .iter()
            .enumerate()
            .map(|(j, m)| {
                check_affine(m, "bind transform of joint", j)?;
                inverse(m).ok_or(Error::Skinning(SkinningError::SingularBindTransform { joint: j }))
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(Self { parents: parents.to_vec(), inverse_bind })
    }

    /// Number of joints.
    pub fn n_joints(&self) -> usize {
        self.parents.len()
    }

    /// The parent of each joint.
    pub fn parents(&self) -> &[Option<u32>] {
        &self.parents
    }

    /// `inverse(bindTransform)` of each joint.
    pub fn inverse_bind_transforms(&self) -> &[Mat4] {
        &self.inverse_bind
    }

    /// Skinning transforms from joint transforms in skeleton space:
    /// `inverse(bind_j) · skel_j` for every joint, into `out`.
    pub fn skinning_transforms_from_skel(&self, skel: &[Mat4], out: &mut [Mat4]) -> Result<()> {
        self.check_count("skeleton-space joint transforms", skel.len())?;
        self.check_count("skinning transform buffer", out.len())?;
        for (j, (o, m)) in out.iter_mut().zip(skel).enumerate() {
            check_finite(m, "joint transform", j)?;
            *o = mul(&self.inverse_bind[j], m);
        }
        Ok(())
    }

    /// Skinning transforms from joint-local transforms (each relative to its
    /// parent, UsdSkel's `SkelAnimation` translations, rotations and scales
    /// composed): `skel_j = local_j · skel_parent(j)`, then as
    /// [`Self::skinning_transforms_from_skel`].
    pub fn skinning_transforms(&self, local: &[Mat4], out: &mut [Mat4]) -> Result<()> {
        self.check_count("joint-local transforms", local.len())?;
        let mut skel = vec![IDENTITY; local.len()];
        for j in 0..local.len() {
            skel[j] = match self.parents[j] {
                Some(p) => mul(&local[j], &skel[p as usize]),
                None => local[j],
            };
        }
        self.skinning_transforms_from_skel(&skel, out)
    }

    fn check_count(&self, what: &'static str, got: usize) -> Result<()> {
        if got != self.n_joints() {
            return Err(SkinningError::JointCount { what, expected: self.n_joints(), got }.into());
        }
        Ok(())
    }
}

/// A mesh's skinning: its influences, `geomBindTransform` and method.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Skin {
    influences: Influences,
    geom_bind: Mat4,
    method: SkinningMethod,
    /// Each point's centre of rotation, for [`SkinningMethod::CentersOfRotation`].
    centers: Option<Vec<[f64; 3]>>,
}

impl Skin {
    /// `geom_bind`: UsdSkel's `primvars:skel:geomBindTransform` (the identity
    /// when unauthored), affine.
    pub fn new(influences: Influences, geom_bind: Mat4, method: SkinningMethod) -> Result<Self> {
        check_affine(&geom_bind, "geomBindTransform", 0)?;
        Ok(Self { influences, geom_bind, method, centers: None })
    }

    pub fn influences(&self) -> &Influences {
        &self.influences
    }

    pub fn geom_bind_transform(&self) -> &Mat4 {
        &self.geom_bind
    }

    pub fn method(&self) -> SkinningMethod {
        self.method
    }

    /// Gives the skin each point's centre of rotation (mesh space), which
    /// [`SkinningMethod::CentersOfRotation`] needs: computed from the
    /// mesh's bind pose with [`crate::cage::CentersOfRotation::new`].
    pub fn with_centers_of_rotation(mut self, centers: Vec<[f64; 3]>) -> Result<Self> {
        if centers.len() != self.influences.n_points() {
            return Err(Error::CountMismatch {
                what: "centres of rotation",
                expected: self.influences.n_points(),
                got: centers.len(),
            });
        }
        crate::mesh::check_finite(&centers, "centre of rotation")?;
        self.centers = Some(centers);
        Ok(self)
    }

    /// The points' centres of rotation, when given.
    pub fn centers_of_rotation(&self) -> Option<&[[f64; 3]]> {
        self.centers.as_deref()
    }

    /// Skins `points` (the mesh's bind pose, one per influenced point) by the
    /// skinning transforms `transforms` (one per joint) into `out`. Centres
    /// of rotation need the skin's centres ([`Self::with_centers_of_rotation`]).
    pub fn skin_points(&self, points: &[[f64; 3]], transforms: &[Mat4], out: &mut [[f64; 3]]) -> Result<()> {
        match (self.method, &self.centers) {
            (SkinningMethod::CentersOfRotation, Some(c)) => {
                crate::cage::skin_points_cor(points, c, &self.influences, &self.geom_bind, transforms, out)
            }
            _ => skin_points(self.method, points, &self.influences, &self.geom_bind, transforms, out),
        }
    }
}

/// Skins `points` with `method`: [`skin_points_lbs`] or [`skin_points_dqs`];
/// centres of rotation need the points' centres ([`crate::cage::skin_points_cor`],
/// [`Skin::skin_points`]) and are refused here with [`Error::Unsupported`].
pub fn skin_points(
    method: SkinningMethod,
    points: &[[f64; 3]],
    influences: &Influences,
    geom_bind: &Mat4,
    transforms: &[Mat4],
    out: &mut [[f64; 3]],
) -> Result<()> {
    match method {
        SkinningMethod::ClassicLinear => skin_points_lbs(points, influences, geom_bind, transforms, out),
        SkinningMethod::DualQuaternion => skin_points_dqs(points, influences, geom_bind, transforms, out),
        SkinningMethod::CentersOfRotation => Err(Error::Unsupported {
            what: "centres-of-rotation skinning without the points' centres (Skin::with_centers_of_rotation)",
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rot_z(deg: f64, t: [f64; 3]) -> Mat4 {
        let (s, c) = deg.to_radians().sin_cos();
        // Row vectors: x -> (c, s, 0).
        [c, s, 0.0, 0.0, -s, c, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, t[0], t[1], t[2], 1.0]
    }

    #[test]
    fn row_vector_convention_and_inverse() {
        let m = rot_z(90.0, [1.0, 2.0, 3.0]);
        let p = transform_point(&m, [1.0, 0.0, 0.0]);
        assert!((p[0] - 1.0).abs() < 1e-15 && (p[1] - 3.0).abs() < 1e-15 && (p[2] - 3.0).abs() < 1e-15, "{p:?}");
        let i = inverse(&m).unwrap();
        let q = transform_point(&i, p);
        assert!((q[0] - 1.0).abs() < 1e-15 && q[1].abs() < 1e-15 && q[2].abs() < 1e-15);
        // a then b
        let b = rot_z(0.0, [5.0, 0.0, 0.0]);
        let ab = mul(&m, &b);
        assert_eq!(transform_point(&ab, [1.0, 0.0, 0.0]), transform_point(&b, transform_point(&m, [1.0, 0.0, 0.0])));
        let mut singular = IDENTITY;
        singular[5] = 0.0;
        assert!(inverse(&singular).is_none());
    }

    #[test]
    fn influences_name_the_bad_entry() {
        let err = Influences::new(2, 2, &[0, 1, 0, 3], &[0.5, 0.5, 1.0, 0.0], 2).unwrap_err();
        assert_eq!(
            err,
            Error::Skinning(SkinningError::JointOutOfRange { point: 1, influence: 1, joint: 3, n_joints: 2 })
        );
        let err = Influences::new(2, 2, &[0, 1, 0], &[0.5, 0.5, 1.0], 2).unwrap_err();
        assert!(matches!(err, Error::Skinning(SkinningError::InfluenceCount { what: "jointIndices", got: 3, .. })));
        let err = Influences::new(1, 2, &[0, 1], &[f64::NAN, 0.5], 2).unwrap_err();
        assert!(matches!(err, Error::Skinning(SkinningError::NonFiniteWeight { point: 0, influence: 0, .. })));
        let mut ok = Influences::new(3, 2, &[0, 1, 0, 1, 1, 0], &[0.3, 0.7000001, 0.5, 0.25, 1.0, 0.0], 2).unwrap();
        assert_eq!(ok.renormalize(1e-4), vec![1]);
        assert_eq!(ok.weight_sum(0), 1.0);
        assert_eq!(ok.weight_sum(1), 0.75);
    }

    #[test]
    fn skeleton_composes_parents_first() {
        let bind = [rot_z(0.0, [0.0, 1.0, 0.0]), rot_z(0.0, [0.0, 2.0, 0.0])];
        let sk = Skeleton::new(&[None, Some(0)], &bind).unwrap();
        // Rest: local = translation to parent; skinning transforms are identity.
        let local = [rot_z(0.0, [0.0, 1.0, 0.0]), rot_z(0.0, [0.0, 1.0, 0.0])];
        let mut out = [IDENTITY; 2];
        sk.skinning_transforms(&local, &mut out).unwrap();
        for m in &out {
            for (a, b) in m.iter().zip(&IDENTITY) {
                assert!((a - b).abs() < 1e-15);
            }
        }
        assert!(matches!(
            Skeleton::new(&[Some(1), None], &bind),
            Err(Error::Skinning(SkinningError::BadParent { joint: 0, parent: 1 }))
        ));
        let mut proj = IDENTITY;
        proj[3] = 0.5;
        assert!(matches!(
            Skeleton::new(&[None], &[proj]),
            Err(Error::Skinning(SkinningError::NotAffine { index: 0, .. }))
        ));
    }
}
