//! UsdSkel joint influences and the input checks every skinning method
//! shares: a leaf below the methods (lbs.rs, dqs.rs, the cage's cor.rs).

use super::transform::{Mat4, check_finite};
use crate::error::{Error, Result, SkinningError};

/// Validated joint influences of `#P` points (UsdSkel's `jointIndices` /
/// `jointWeights` primvars with vertex interpolation), `element_size` per point.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Influences {
    element_size: usize,
    #[serde(with = "crate::persist::pod")]
    indices: Vec<u32>,
    #[serde(with = "crate::persist::pod")]
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
