//! What a binding will cost, predicted before it is computed, and the
//! limits it is checked against (all configurable, see `Config`).
//!
//! # The cost of a binding
//!
//! A curvenet of density `d` (samples per mean mesh edge length) puts about
//! `d` segment pieces into every input face it crosses, and the cut-faces
//! beside it get about `d` corners each. Measured on the hand meshes
//! (`curvenet bench`'s fixtures, one curvenet), the binding's time grows
//! like segments × d² (the per-cut-face Laplacians are dense: 1.4k-vertex
//! hand at d = 50: 0.13 s; d = 200: 1.6 s; d = 400: 17 s and 400 MB) and its
//! memory like 320 bytes per input face corner plus 1-2.5 KB per segment.
//! Three limits bound it:
//!
//! - the **density** of each curvenet (`--max-sample-density`, default 50:
//!   ten times the paper's 5) bounds the work per face;
//! - the **segments** of all curvenets together, predicted exactly as the
//!   sampling plans them (`round(d × control polygon length ÷ mean edge
//!   length)` per spline, at least 1), relative to the mesh
//!   (`--max-segments-per-vertex`, default 10, and never fewer than
//!   [`MIN_SEGMENT_ALLOWANCE`]) bounds the total;
//! - the **time** (`--max-binding-seconds`, default 120): a binding still
//!   running then is cancelled. This is the backstop for what the
//!   prediction cannot see (a mesh whose faces are much larger than its mean
//!   edge where the curvenet crosses them).
//!
//! Beyond a limit the request gets 422 `limit_exceeded` naming the
//! curvenet, the predicted amount, the limit and its flag. A binding whose
//! predicted size (a lower bound: [`BYTES_PER_CORNER`] per input face
//! corner, [`BYTES_PER_SEGMENT`] per segment and, with a cage, its mean
//! value coordinates: 8 bytes per mesh vertex per cage vertex) is larger than the whole
//! cache gets 507 `cache_too_small` before any work.

use std::time::Duration;

use curvenet_schema::wire::BindingRequest;

use crate::error::{Code, ServiceError};

/// Default largest sample density of a curvenet.
pub const DEFAULT_MAX_SAMPLE_DENSITY: f64 = 50.0;
/// Default largest number of segments (all curvenets) per mesh vertex.
pub const DEFAULT_MAX_SEGMENTS_PER_VERTEX: f64 = 10.0;
/// Segments always allowed, however small the mesh.
pub const MIN_SEGMENT_ALLOWANCE: u64 = 20_000;
/// Default longest binding computation.
pub const DEFAULT_MAX_BINDING_TIME: Duration = Duration::from_secs(120);
/// Lower bound of a binding's bytes per input face corner (measured: 316-336).
pub const BYTES_PER_CORNER: u64 = 250;
/// Lower bound of a binding's bytes per curvenet segment (measured: 1000-2300).
pub const BYTES_PER_SEGMENT: u64 = 800;

/// The limits a binding is checked against.
#[derive(Debug, Clone, Copy)]
pub struct WorkLimits {
    pub max_sample_density: f64,
    pub max_segments_per_vertex: f64,
    pub max_binding_time: Duration,
}

impl Default for WorkLimits {
    fn default() -> Self {
        Self {
            max_sample_density: DEFAULT_MAX_SAMPLE_DENSITY,
            max_segments_per_vertex: DEFAULT_MAX_SEGMENTS_PER_VERTEX,
            max_binding_time: DEFAULT_MAX_BINDING_TIME,
        }
    }
}

impl WorkLimits {
    /// The segments allowed over a mesh of `vertices` vertices.
    pub fn max_segments(&self, vertices: usize) -> u64 {
        let relative = self.max_segments_per_vertex * vertices as f64;
        (relative.min(u64::MAX as f64) as u64).max(MIN_SEGMENT_ALLOWANCE)
    }
}

/// What a binding is predicted to cost.
#[derive(Debug, Clone)]
pub struct Prediction {
    /// Segments of each curvenet.
    pub segments: Vec<u64>,
    pub total_segments: u64,
    /// A lower bound of the binding's size in memory.
    pub bytes_at_least: u64,
}

/// Predicts the cost of `req` (validated: indices in range, points finite)
/// over a mesh of mean edge length `mean_edge_length`. Allocates one number
/// per curvenet.
pub fn predict(req: &BindingRequest, mean_edge_length: f64) -> Prediction {
    let segments: Vec<u64> = req
        .curvenets
        .iter()
        .map(|c| {
            let p = |i: u32| c.pool[i as usize];
            let dist = |a: [f64; 3], b: [f64; 3]| {
                ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
            };
            c.splines
                .iter()
                .map(|s| {
                    let polygon = dist(p(s[0]), p(s[1])) + dist(p(s[1]), p(s[2])) + dist(p(s[2]), p(s[3]));
                    let raw = (c.sample_density * polygon / mean_edge_length).round();
                    // At least 1 (the sampling gives a closed spline 3: immaterial
                    // here); NaN and infinities saturate.
                    if raw.is_nan() { u64::MAX } else { (raw.min(u64::MAX as f64) as u64).max(1) }
                })
                .fold(0u64, u64::saturating_add)
        })
        .collect();
    let total_segments = segments.iter().fold(0u64, |a, &b| a.saturating_add(b));
    let corners = req.face_vertex_indices.len() as u64;
    // A cage's mean value coordinates Φ: one f64 per mesh vertex and cage vertex.
    let phi = req
        .cage
        .as_ref()
        .map_or(0, |c| (req.projection_points.len() as u64).saturating_mul(c.points.len() as u64).saturating_mul(8));
    let bytes_at_least = corners
        .saturating_mul(BYTES_PER_CORNER)
        .saturating_add(total_segments.saturating_mul(BYTES_PER_SEGMENT))
        .saturating_add(phi);
    Prediction { segments, total_segments, bytes_at_least }
}

/// Checks `req` against the limits: each curvenet's density, then the
/// predicted segments. Returns the prediction.
pub fn check(req: &BindingRequest, mean_edge_length: f64, limits: &WorkLimits) -> Result<Prediction, ServiceError> {
    for (k, c) in req.curvenets.iter().enumerate() {
        if c.sample_density > limits.max_sample_density {
            return Err(ServiceError::new(
                Code::LimitExceeded,
                format!(
                    "curvenets[{k}].sample_density {} is above this server's limit of {} samples per mean edge length \
                     (--max-sample-density, CURVENET_MAX_SAMPLE_DENSITY)",
                    c.sample_density, limits.max_sample_density
                ),
            ));
        }
    }
    let prediction = predict(req, mean_edge_length);
    let vertices = req.projection_points.len();
    let max = limits.max_segments(vertices);
    if prediction.total_segments > max {
        let (k, most) =
            prediction.segments.iter().enumerate().max_by_key(|(_, s)| **s).map_or((0, 0), |(k, s)| (k, *s));
        return Err(ServiceError::new(
            Code::LimitExceeded,
            format!(
                "curvenets[{k}] would be sampled into {most} segments ({} over all curvenets), more than this server's \
                 limit of {max} for a mesh of {vertices} vertices ({} per vertex, at least {MIN_SEGMENT_ALLOWANCE}: \
                 --max-segments-per-vertex, CURVENET_MAX_SEGMENTS_PER_VERTEX); lower its sample_density",
                prediction.total_segments, limits.max_segments_per_vertex
            ),
        ));
    }
    Ok(prediction)
}

#[cfg(test)]
mod tests {
    use super::*;
    use curvenet_schema::wire::CurvenetSpec;

    fn request(density: f64, length: f64) -> BindingRequest {
        let c: CurvenetSpec = serde_json::from_value(serde_json::json!({
            "pool": [[0.0, 0.0, 0.0], [length / 3.0, 0.0, 0.0], [2.0 * length / 3.0, 0.0, 0.0], [length, 0.0, 0.0]],
            "splines": [[0, 1, 2, 3]],
            "sample_density": density,
        }))
        .unwrap();
        BindingRequest {
            face_vertex_counts: vec![3],
            face_vertex_indices: vec![0, 1, 2],
            projection_points: vec![[0.0; 3]; 3],
            curvenets: vec![c],
            blend_shapes: Vec::new(),
            skin: None,
            cage: None,
            options: Default::default(),
        }
    }

    #[test]
    fn segments_are_predicted_as_the_sampling_plans_them() {
        // 10 mean edge lengths of control polygon at density 5: 50 segments.
        assert_eq!(predict(&request(5.0, 10.0), 1.0).total_segments, 50);
        // A very short spline still gets its minimum.
        assert_eq!(predict(&request(5.0, 1e-9), 1.0).total_segments, 1);
        // Overflowing lengths saturate instead of wrapping.
        assert_eq!(predict(&request(50.0, 1e300), 1e-300).total_segments, u64::MAX);
    }

    #[test]
    fn a_cage_adds_its_phi_to_the_predicted_size() {
        let plain = predict(&request(5.0, 10.0), 1.0).bytes_at_least;
        let mut caged = request(5.0, 10.0);
        caged.cage = Some(curvenet_schema::wire::CageSpec { points: vec![[0.0; 3]; 100], triangles: Vec::new() });
        // 3 mesh vertices × 100 cage vertices × 8 bytes.
        assert_eq!(predict(&caged, 1.0).bytes_at_least, plain + 2400);
    }

    #[test]
    fn limits_name_the_curvenet_and_the_flag() {
        let limits = WorkLimits::default();
        let e = check(&request(3000.0, 10.0), 1.0, &limits).unwrap_err();
        assert_eq!(e.code, Code::LimitExceeded);
        assert!(e.message.contains("curvenets[0].sample_density 3000") && e.message.contains("--max-sample-density"));
        let e = check(&request(50.0, 1e6), 1.0, &limits).unwrap_err();
        assert!(e.message.contains("curvenets[0] would be sampled into 50000000 segments"), "{}", e.message);
        assert!(e.message.contains("--max-segments-per-vertex"));
        assert!(check(&request(50.0, 100.0), 1.0, &limits).is_ok());
    }
}
