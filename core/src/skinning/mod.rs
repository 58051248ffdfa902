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

mod dqs;
mod lbs;
pub mod spline;
mod weights;

pub use dqs::{DualQuat, SCALE_TOLERANCE, skin_points_dqs};
pub use lbs::skin_points_lbs;
pub use spline::{Junction, JunctionKind, SplineEnd, SplineSkinning, SplineSkinningOptions};
pub use weights::{ControlPointWeights, DERIVED_WEIGHT_SAMPLES, SurfaceWeights, WeightField};

use crate::error::{Error, Result};

/// A 4×4 transform, row-major, acting on row vectors (see the module docs).
pub type Mat4 = [f64; 16];

/// The 4×4 identity.
pub const IDENTITY: Mat4 = [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0];

/// How a mesh is skinned (UsdSkel's `skel:skinningMethod`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
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

/// Why skinning input was refused. Every variant names the element.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum SkinningError {
    /// `element_size` is zero.
    #[error("the influences' element size must be at least 1")]
    ZeroElementSize,
    /// The influence arrays do not hold `element_size` entries per point.
    #[error("{what} has {got} entries, expected {expected} ({points} points x element size {element_size})")]
    InfluenceCount { what: &'static str, got: usize, expected: usize, points: usize, element_size: usize },
    /// A joint index is negative or past the last joint.
    #[error("point {point}, influence {influence}: joint index {joint} is outside 0..{n_joints}")]
    JointOutOfRange { point: usize, influence: usize, joint: i64, n_joints: usize },
    /// A weight is NaN or infinite.
    #[error("point {point}, influence {influence}: weight {weight} is not finite")]
    NonFiniteWeight { point: usize, influence: usize, weight: f64 },
    /// A transform has a non-finite entry.
    #[error("{what} {index} has a non-finite entry")]
    NonFiniteTransform { what: &'static str, index: usize },
    /// A transform that must be affine has a last column other than (0, 0, 0, 1).
    #[error("{what} {index} is not affine (its last column is {column:?}, expected [0, 0, 0, 1])")]
    NotAffine { what: &'static str, index: usize, column: [f64; 4] },
    /// A bind transform cannot be inverted.
    #[error("the bind transform of joint {joint} is singular")]
    SingularBindTransform { joint: usize },
    /// A joint's parent is not an earlier joint (UsdSkel orders parents first).
    #[error("joint {joint} has parent {parent}, which does not come before it")]
    BadParent { joint: usize, parent: usize },
    /// The number of transforms does not match the skeleton.
    #[error("{what}: expected {expected} joints, got {got}")]
    JointCount { what: &'static str, expected: usize, got: usize },
    /// A curvenet control point that no weight reaches (all its weights are zero).
    #[error("{what} {index} has no joint weight (all its weights are zero)")]
    Unweighted { what: &'static str, index: usize },
    /// The skinned tangents of an angle-constrained knot are parallel, so the
    /// rotation axis of the constraint is undefined.
    #[error("the skinned tangents at knot {knot} (control point) are parallel: its angle constraint has no axis")]
    DegenerateAngleAxis { knot: u32 },
}

impl From<SkinningError> for Error {
    fn from(e: SkinningError) -> Self {
        Error::Skinning(e)
    }
}

/// Validated joint influences of `#P` points (UsdSkel's `jointIndices` /
/// `jointWeights` primvars with vertex interpolation), `element_size` per point.
#[derive(Debug, Clone, PartialEq)]
pub struct Influences {
    element_size: usize,
    indices: Vec<u32>,
    weights: Vec<f64>,
    n_joints: usize,
}

impl Influences {
    /// Checks and stores the influences of `n_points` points: `joint_indices`
    /// and `joint_weights` have `n_points × element_size` entries; every index
    /// is in `0..n_joints` (an index whose weight is 0 too: UsdSkel refuses
    /// those as well) and every weight is finite. Weights are kept as given.
    pub fn new(
        n_points: usize,
        element_size: usize,
        joint_indices: &[i64],
        joint_weights: &[f64],
        n_joints: usize,
    ) -> Result<Self> {
        if element_size == 0 {
            return Err(SkinningError::ZeroElementSize.into());
        }
        let expected = n_points * element_size;
        for (what, got) in [("jointIndices", joint_indices.len()), ("jointWeights", joint_weights.len())] {
            if got != expected {
                return Err(
                    SkinningError::InfluenceCount { what, got, expected, points: n_points, element_size }.into()
                );
            }
        }
        let mut indices = Vec::with_capacity(expected);
        for (k, (&j, &w)) in joint_indices.iter().zip(joint_weights).enumerate() {
            let (point, influence) = (k / element_size, k % element_size);
            if j < 0 || j as u64 >= n_joints as u64 {
                return Err(SkinningError::JointOutOfRange { point, influence, joint: j, n_joints }.into());
            }
            if !w.is_finite() {
                return Err(SkinningError::NonFiniteWeight { point, influence, weight: w }.into());
            }
            indices.push(j as u32);
        }
        Ok(Self { element_size, indices, weights: joint_weights.to_vec(), n_joints })
    }

    /// Influences that give every one of `n_points` points the same
    /// `element_size` pairs (UsdSkel's `constant` interpolation, expanded).
    pub fn constant(n_points: usize, joint_indices: &[i64], joint_weights: &[f64], n_joints: usize) -> Result<Self> {
        let element_size = joint_indices.len();
        let one = Self::new(1, element_size.max(1), joint_indices, joint_weights, n_joints)?;
        Ok(Self {
            element_size: one.element_size,
            indices: one.indices.repeat(n_points),
            weights: one.weights.repeat(n_points),
            n_joints,
        })
    }

    /// Number of points.
    pub fn n_points(&self) -> usize {
        self.indices.len() / self.element_size
    }

    /// Influences per point.
    pub fn element_size(&self) -> usize {
        self.element_size
    }

    /// Number of joints the indices refer to.
    pub fn n_joints(&self) -> usize {
        self.n_joints
    }

    /// The (joint, weight) pairs of point `p`, zero weights included.
    pub fn point(&self, p: usize) -> impl Iterator<Item = (u32, f64)> + '_ {
        let r = p * self.element_size..(p + 1) * self.element_size;
        self.indices[r.clone()].iter().copied().zip(self.weights[r].iter().copied())
    }

    /// The sum of point `p`'s weights.
    pub fn weight_sum(&self, p: usize) -> f64 {
        self.weights[p * self.element_size..(p + 1) * self.element_size].iter().sum()
    }

    /// Rescales the weights of every point whose weights already sum to 1
    /// within `tolerance` so that they sum to 1 exactly (in `f64`), and
    /// returns the points left as they were because their sum is further
    /// from 1. Authored weights are `float`: a row meant to sum to 1 sums to
    /// 1 ± 1e-7 or so, which would keep identity transforms from reproducing
    /// the rest pose exactly; rows far from 1 are the asset's own intent (or
    /// mistake) and are skinned as authored, as usd-core does.
    pub fn renormalize(&mut self, tolerance: f64) -> Vec<usize> {
        let mut left = Vec::new();
        for p in 0..self.n_points() {
            let r = p * self.element_size..(p + 1) * self.element_size;
            let sum: f64 = self.weights[r.clone()].iter().sum();
            if sum != 1.0 && (sum - 1.0).abs() <= tolerance {
                self.weights[r].iter_mut().for_each(|w| *w /= sum);
            } else if sum != 1.0 {
                left.push(p);
            }
        }
        left
    }
}

/// The joint hierarchy and bind pose of a skeleton: turns per-frame joint
/// transforms into skinning transforms.
#[derive(Debug, Clone, PartialEq)]
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
#[derive(Debug, Clone, PartialEq)]
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

/// Checks the sizes and values shared by both skinning methods.
pub(crate) fn check_skinning_input(
    points: &[[f64; 3]],
    influences: &Influences,
    transforms: &[Mat4],
    out: &[[f64; 3]],
) -> Result<()> {
    if points.len() != influences.n_points() {
        return Err(Error::CountMismatch {
            what: "skinned points",
            expected: influences.n_points(),
            got: points.len(),
        });
    }
    if out.len() != points.len() {
        return Err(Error::CountMismatch { what: "skinning output", expected: points.len(), got: out.len() });
    }
    if transforms.len() != influences.n_joints() {
        return Err(SkinningError::JointCount {
            what: "skinning transforms",
            expected: influences.n_joints(),
            got: transforms.len(),
        }
        .into());
    }
    for (j, m) in transforms.iter().enumerate() {
        check_finite(m, "skinning transform of joint", j)?;
    }
    crate::mesh::check_finite(points, "skinned point")
}

/// Points per rayon task in the per-vertex passes.
pub(crate) const PAR_CHUNK: usize = 2048;

fn check_finite(m: &Mat4, what: &'static str, index: usize) -> Result<()> {
    if m.iter().all(|x| x.is_finite()) { Ok(()) } else { Err(SkinningError::NonFiniteTransform { what, index }.into()) }
}

/// Refuses a non-finite matrix or one whose last column is not (0, 0, 0, 1).
pub fn check_affine(m: &Mat4, what: &'static str, index: usize) -> Result<()> {
    check_finite(m, what, index)?;
    let column = [m[3], m[7], m[11], m[15]];
    let tol = 1e-9 * m.iter().fold(1.0f64, |a, x| a.max(x.abs()));
    if column[0].abs() > tol || column[1].abs() > tol || column[2].abs() > tol || (column[3] - 1.0).abs() > tol {
        return Err(SkinningError::NotAffine { what, index, column }.into());
    }
    Ok(())
}

/// `a · b` (row vectors: `a` applies first).
pub fn mul(a: &Mat4, b: &Mat4) -> Mat4 {
    let mut m = [0.0; 16];
    for r in 0..4 {
        for c in 0..4 {
            m[4 * r + c] = (0..4).map(|k| a[4 * r + k] * b[4 * k + c]).sum();
        }
    }
    m
}

/// `[p 1] · m`, dropping the last column (an affine transform of a point,
/// UsdSkel's `TransformAffine`).
#[inline]
pub fn transform_point(m: &Mat4, p: [f64; 3]) -> [f64; 3] {
    [
        p[0] * m[0] + p[1] * m[4] + p[2] * m[8] + m[12],
        p[0] * m[1] + p[1] * m[5] + p[2] * m[9] + m[13],
        p[0] * m[2] + p[1] * m[6] + p[2] * m[10] + m[14],
    ]
}

/// `[v 0] · m`: a direction, without the translation.
#[inline]
pub fn transform_vector(m: &Mat4, v: [f64; 3]) -> [f64; 3] {
    [
        v[0] * m[0] + v[1] * m[4] + v[2] * m[8],
        v[0] * m[1] + v[1] * m[5] + v[2] * m[9],
        v[0] * m[2] + v[1] * m[6] + v[2] * m[10],
    ]
}

/// The inverse of an affine transform, `None` when its linear part is
/// singular (determinant below 1e-12 of its scale cubed).
pub fn inverse(m: &Mat4) -> Option<Mat4> {
    let a = [[m[0], m[1], m[2]], [m[4], m[5], m[6]], [m[8], m[9], m[10]]];
    let det = a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1]) - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
        + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]);
    let scale = a.iter().flatten().fold(0.0f64, |s, x| s.max(x.abs()));
    if !(det.abs() > 1e-12 * scale.powi(3)) {
        return None;
    }
    let mut inv = [[0.0; 3]; 3];
    for r in 0..3 {
        for c in 0..3 {
            // inverse = adjugate / det; adj[r][c] = cofactor[c][r]
            let (r1, r2) = ((c + 1) % 3, (c + 2) % 3);
            let (c1, c2) = ((r + 1) % 3, (r + 2) % 3);
            inv[r][c] = (a[r1][c1] * a[r2][c2] - a[r1][c2] * a[r2][c1]) / det;
        }
    }
    let t = [m[12], m[13], m[14]];
    let mut out = IDENTITY;
    for r in 0..3 {
        for c in 0..3 {
            out[4 * r + c] = inv[r][c];
        }
    }
    for c in 0..3 {
        out[12 + c] = -(t[0] * inv[0][c] + t[1] * inv[1][c] + t[2] * inv[2][c]);
    }
    Some(out)
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
