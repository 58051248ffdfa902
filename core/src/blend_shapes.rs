//! Blend shapes with UsdSkel semantics (sparse offsets with point indices,
//! inbetween shapes at their weights), applied either to the rest pose
//! before the curvenet deformation or, the default (paper §5, "Blend
//! Shapes"), after it in per-vertex frames.
//!
//! A shape's offsets at weight `w` interpolate linearly between its
//! sub-shapes sorted by weight: the implicit rest shape (no offset) at 0, the
//! inbetweens at their weights, the full shape at 1. Outside the range of
//! the sub-shapes the nearest two extrapolate linearly (as UsdSkel's
//! `BlendShapeQuery` does; checked against usd-core in the end-to-end tests).
//!
//! After the deformation, the offset of vertex `v` is mapped by that
//! vertex's interpolated deformation gradient `F_v` (from the harmonic solve
//! of Eq. 4): a sculpt rotates, and scales, with the surface around it. We
//! use `F_v` itself rather than its rotation part so a uniformly scaled
//! character scales its sculpts too. Changing only the weights reuses the
//! solved points and gradients: no curvenet solve.

use crate::error::{Error, Result};
use crate::mesh::check_finite;

/// One blend shape.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BlendShape {
    #[serde(with = "crate::persist::pod")]
    offsets: Vec<[f64; 3]>,
    point_indices: Option<Vec<u32>>,
    /// Sub-shapes sorted by weight, including the implicit 0 (empty) and 1 (full).
    #[serde(with = "crate::persist::pod")]
    weights: Vec<f64>,
    /// Offsets of each sub-shape (index-aligned with `weights`; the rest shape is empty).
    sub_offsets: Vec<Vec<[f64; 3]>>,
}

impl BlendShape {
    /// Heap bytes held by the shape: its offsets, indices and inbetweens (see [`crate::heap`]).
    pub fn heap_bytes(&self) -> usize {
        use crate::heap::{bytes, nested_bytes};
        bytes(&self.offsets)
            + self.point_indices.as_ref().map_or(0, bytes)
            + bytes(&self.weights)
            + nested_bytes(&self.sub_offsets)
    }

    /// A shape over a mesh of `n_points` points: `offsets` of the full shape
    /// (weight 1), the vertex of each offset (`None`: dense, one per point),
    /// and inbetweens as `(weight, offsets)` laid out like `offsets`.
    pub fn new(
        n_points: usize,
        offsets: Vec<[f64; 3]>,
        point_indices: Option<Vec<u32>>,
        inbetweens: Vec<(f64, Vec<[f64; 3]>)>,
    ) -> Result<Self> {
        let expected = point_indices.as_ref().map_or(n_points, Vec::len);
        if offsets.len() != expected {
            return Err(Error::CountMismatch { what: "blend shape offsets", expected, got: offsets.len() });
        }
        if let Some(ix) = &point_indices
            && let Some((i, &v)) = ix.iter().enumerate().find(|(_, v)| **v as usize >= n_points)
        {
            return Err(Error::IndexOutOfRange {
                what: "blend shape point index",
                index: i,
                target: "vertex",
                value: v,
                len: n_points,
            });
        }
        check_finite(&offsets, "blend shape offset")?;
        let mut subs: Vec<(f64, Vec<[f64; 3]>)> = vec![(0.0, Vec::new()), (1.0, offsets.clone())];
        for (w, o) in inbetweens {
            if !w.is_finite() || w == 0.0 || w == 1.0 {
                return Err(Error::InvalidParameter {
                    what: "blend shape inbetween weight (finite, not 0 or 1)",
                    value: w,
                });
            }
            if o.len() != expected {
                return Err(Error::CountMismatch { what: "blend shape inbetween offsets", expected, got: o.len() });
            }
            check_finite(&o, "blend shape inbetween offset")?;
            subs.push((w, o));
        }
        subs.sort_by(|a, b| a.0.total_cmp(&b.0));
        if let Some(w) = subs.windows(2).find(|p| p[0].0 == p[1].0) {
            return Err(Error::InvalidParameter { what: "blend shape inbetween weight (repeated)", value: w[0].0 });
        }
        let (weights, sub_offsets) = subs.into_iter().unzip();
        Ok(Self { offsets, point_indices, weights, sub_offsets })
    }

    /// The two sub-shapes bracketing `w` and the interpolation parameter.
    fn bracket(&self, w: f64) -> (usize, usize, f64) {
        let n = self.weights.len();
        let hi = self.weights.partition_point(|&x| x <= w).clamp(1, n - 1);
        let lo = hi - 1;
        let (a, b) = (self.weights[lo], self.weights[hi]);
        (lo, hi, (w - a) / (b - a))
    }

    fn offset(&self, sub: usize, k: usize) -> [f64; 3] {
        if self.sub_offsets[sub].is_empty() { [0.0; 3] } else { self.sub_offsets[sub][k] }
    }

    /// Calls `f(vertex, offset)` for every offset of the shape at weight `w`.
    pub fn for_each_offset(&self, w: f64, mut f: impl FnMut(usize, [f64; 3])) {
        if w == 0.0 {
            return;
        }
        let (lo, hi, t) = self.bracket(w);
        for k in 0..self.offsets.len() {
            let (a, b) = (self.offset(lo, k), self.offset(hi, k));
            let o = std::array::from_fn(|i| a[i] + t * (b[i] - a[i]));
            let v = self.point_indices.as_ref().map_or(k, |ix| ix[k] as usize);
            f(v, o);
        }
    }
}

/// The blend shapes of one mesh.
#[derive(Debug, Clone, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct BlendShapes {
    n_points: usize,
    shapes: Vec<BlendShape>,
}

impl BlendShapes {
    pub fn new(n_points: usize, shapes: Vec<BlendShape>) -> Self {
        Self { n_points, shapes }
    }

    pub fn len(&self) -> usize {
        self.shapes.len()
    }

    pub fn is_empty(&self) -> bool {
        self.shapes.is_empty()
    }

    fn check(&self, weights: &[f64], points: &[[f64; 3]]) -> Result<()> {
        if weights.len() != self.shapes.len() {
            return Err(Error::CountMismatch {
                what: "blend shape weights",
                expected: self.shapes.len(),
                got: weights.len(),
            });
        }
        if let Some((i, &w)) = weights.iter().enumerate().find(|(_, w)| !w.is_finite()) {
            return Err(Error::NonFinite { what: "blend shape weight", index: i, value: [w, 0.0, 0.0] });
        }
        if points.len() != self.n_points {
            return Err(Error::CountMismatch { what: "points", expected: self.n_points, got: points.len() });
        }
        Ok(())
    }

    /// Adds the weighted offsets to `points` (the rest-pose mode).
    pub fn add_to(&self, weights: &[f64], points: &mut [[f64; 3]]) -> Result<()> {
        self.check(weights, points)?;
        for (shape, &w) in self.shapes.iter().zip(weights) {
            shape.for_each_offset(w, |v, o| {
                for i in 0..3 {
                    points[v][i] += o[i];
                }
            });
        }
        Ok(())
    }

    /// Adds the weighted offsets mapped by each vertex's deformation
    /// gradient (row-major 3×3, from [`crate::Binding::deform`]) to the
    /// deformed `points` (the default, after-deformation mode).
    pub fn add_deformed(&self, weights: &[f64], gradients: &[[f64; 9]], points: &mut [[f64; 3]]) -> Result<()> {
        self.check(weights, points)?;
        if gradients.len() != self.n_points {
            return Err(Error::CountMismatch {
                what: "vertex deformation gradients",
                expected: self.n_points,
                got: gradients.len(),
            });
        }
        for (shape, &w) in self.shapes.iter().zip(weights) {
            shape.for_each_offset(w, |v, o| {
                let f = &gradients[v];
                for i in 0..3 {
                    points[v][i] += f[3 * i] * o[0] + f[3 * i + 1] * o[1] + f[3 * i + 2] * o[2];
                }
            });
        }
        Ok(())
    }
}

impl BlendShapes {
    /// Heap bytes held by the shapes, their offsets, indices and inbetweens (see [`crate::heap`]).
    pub fn heap_bytes(&self) -> usize {
        crate::heap::bytes(&self.shapes) + self.shapes.iter().map(BlendShape::heap_bytes).sum::<usize>()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shape() -> BlendShape {
        // Sparse over vertices 1 and 3 of 4; an inbetween at 0.5 that is not half the full shape.
        BlendShape::new(
            4,
            vec![[0.0, 0.0, 1.0], [2.0, 0.0, 0.0]],
            Some(vec![1, 3]),
            vec![(0.5, vec![[0.0, 0.0, 0.8], [0.0, 0.0, 0.0]])],
        )
        .unwrap()
    }

    #[test]
    fn inbetweens_interpolate_piecewise_linearly() {
        let s = BlendShapes::new(4, vec![shape()]);
        let at = |w: f64| {
            let mut p = vec![[0.0; 3]; 4];
            s.add_to(&[w], &mut p).unwrap();
            p
        };
        assert_eq!(at(0.0), vec![[0.0; 3]; 4]);
        assert_eq!(at(0.5)[1], [0.0, 0.0, 0.8]);
        assert!((at(0.25)[1][2] - 0.4).abs() < 1e-15);
        assert!((at(0.75)[1][2] - 0.9).abs() < 1e-15);
        assert!((at(0.75)[3][0] - 1.0).abs() < 1e-15);
        assert_eq!(at(1.0)[3], [2.0, 0.0, 0.0]);
        // Extrapolation from the last segment.
        assert!((at(1.5)[1][2] - 1.2).abs() < 1e-15);
    }

    #[test]
    fn deformed_offsets_follow_the_vertex_gradient() {
        let s = BlendShapes::new(4, vec![shape()]);
        // A 90° rotation about z at every vertex.
        let rz = [0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0];
        let mut p = vec![[0.0; 3]; 4];
        s.add_deformed(&[1.0], &[rz; 4], &mut p).unwrap();
        assert!((p[3][1] - 2.0).abs() < 1e-15 && p[3][0].abs() < 1e-15);
    }

    #[test]
    fn bad_shapes_and_weights_are_named() {
        assert!(matches!(
            BlendShape::new(4, vec![[0.0; 3]], Some(vec![9]), vec![]),
            Err(Error::IndexOutOfRange { value: 9, .. })
        ));
        assert!(matches!(BlendShape::new(4, vec![[0.0; 3]; 3], None, vec![]), Err(Error::CountMismatch { .. })));
        let s = BlendShapes::new(4, vec![shape()]);
        assert!(matches!(s.add_to(&[f64::NAN], &mut [[0.0; 3]; 4]), Err(Error::NonFinite { .. })));
        assert!(matches!(s.add_to(&[1.0, 1.0], &mut [[0.0; 3]; 4]), Err(Error::CountMismatch { .. })));
    }
}
