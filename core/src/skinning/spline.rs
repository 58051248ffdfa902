//! Spline skinning: the least-squares fit of linear-blend-skinned cubic
//! Bézier splines (Liu, Jacobson, Gingold 2015, Eq. 4 and §4).
//!
//! Linear blend skinning of a Bézier curve is no Bézier curve; the control
//! points `C'` whose curves are closest to it minimise
//!
//! ```text
//! Σ_j ℓ_j ∫₀¹ ‖B_{C'_j}(t) − Σ_i w_i(t) [B_{C_j}(t) 1]·M_i‖² dt
//! ```
//!
//! over the splines `j` (rest lengths `ℓ_j`), subject to the continuity of
//! the neutral curvenet. The energy is quadratic in the pool, so with `Q =
//! Σ_j ℓ_j P_jᵀ Â P_j` (`Â = ∫ m mᵀ`, `m` the Bernstein basis, `P_j` the
//! spline's pool rows) and `G_i = Σ_j ℓ_j P_jᵀ Ŵ_i^j P_j C̃` (`Ŵ_i^j = ∫ w_i
//! m mᵀ`, `C̃` the homogeneous neutral pool), the constrained minimiser is
//! `C' = Σ_i O_i · M_i[:, 0..3]` with `O_i` the pool rows of `K⁻¹ [G_i; B_i]`
//! (`K` the KKT matrix of `Q` and the constraints). The `O_i` (`#P × 4`
//! each, only for joints that weigh on the curvenet) are precomputed by
//! [`SplineSkinning::new`]; [`SplineSkinning::pose`] is matrix products.
//!
//! # Decisions (where the paper is silent or 2D)
//!
//! - **Pool unknowns.** The unknowns are the pool's points, so splines that
//!   share a knot share it after the fit: C⁰ at shared knots always holds.
//!   Pool points used by no spline are skinned naively (their own weights).
//! - **Quadrature.** `Â` and every `Ŵ_i` are integrated with the same
//!   composite 5-point Gauss–Legendre rule ([`SplineSkinningOptions::quadrature_intervals`]
//!   intervals per spline, 4 by default), as the paper's footnote asks; it
//!   is exact for `Â` and for Bernstein-interpolated control-point weights.
//!   Rest lengths use the same rule.
//! - **Weights** are rescaled to sum to 1 wherever they are evaluated, so
//!   identity transforms reproduce the neutral curvenet and a single joint
//!   moves it rigidly; a curve point with no weight at all is an error.
//! - **Junction detection** ([`Junction`]), at every knot, over every pair
//!   of spline ends there, with `u = handle − knot` each end's outgoing
//!   tangent (ends whose handle coincides with the knot, within 1e-9 of the
//!   pool's diagonal, have no tangent and are skipped):
//!   G¹ when the tangents are opposite within [`G1_TOLERANCE`] (the sine of
//!   the angle between `u_a` and `−u_b`), C¹ when in addition their lengths
//!   agree within [`C1_TOLERANCE`] (relative); a fixed angle when the angle
//!   between the tangents is within [`RIGHT_ANGLE_TOLERANCE`] of 90° (the
//!   right angles the paper detects on SVG import; the constrained angle is
//!   the neutral one). Pairs are taken G¹/C¹ first (most nearly opposite
//!   first), then angles (closest to 90° first), skipping a pair whose two
//!   ends are already linked at that knot, so the constraints never repeat
//!   each other (a valence-4 crossing of two smooth curves gets 2 G¹ and 1
//!   angle constraint).
//! - **G¹ and C¹ constraints** are Eq. 5 per coordinate, `u_a' + ρ u_b' =
//!   L_k δ`, with `ρ = ‖u_a‖/‖u_b‖` (1 for C¹), `δ = u_a + ρ u_b` the
//!   neutral curvenet's own (tolerated) deviation and `L_k` the
//!   linear part of the knot's blended skinning transform: `δ` is 0 for an
//!   exactly smooth junction (the paper's constraint) and is otherwise
//!   carried along as the skinning carries the knot, so that identity and
//!   rigid transforms reproduce the authored curvenet exactly. It is linear
//!   in the `M_i`, so it only adds the rows `B_i` to the `O_i`.
//! - **Angle constraints** in 3D rotate about an axis that must follow the
//!   pose. It is the normal `n` of the plane of the two tangents of the fit
//!   without the angle constraints (the `O_i` fit), and the ratio `ρ` is
//!   theirs too: the constraint turns the fitted tangents into the neutral
//!   angle `θ` and changes nothing else. (Measured on the cylinder net of
//!   core/tests/skinning.rs bent 60°, as fitting energy over naive
//!   control-point skinning's: the skinned normal of the neutral tangents,
//!   `(L_k u_a) × (L_k u_b)`, with the neutral ratio as in the paper's 2D
//!   Eq. 13: 5.9×; the fitted plane with the neutral ratio: 3.1×; the fitted
//!   plane and ratio: 0.045×; no angle constraints: 0.021×. A fixed ratio
//!   between two different curves fights the skinning's stretch.) For
//!   identity and rigid transforms `n` is the
//!   skinned normal and `ρ` the neutral ratio; where the fitted tangents are
//!   parallel, the skinned normal and the neutral ratio are used. With the
//!   rotation `R(n, θ)` by the neutral angle, the constraint is
//!   `R u_a' = ρ u_b'` (Eq. 13) together with
//!   `n · u_a' = 0`: in 3D a rotation about `n` keeps the angle only for
//!   vectors in the plane normal to `n`, so both tangents are kept in the
//!   skinned tangents' plane (4 rows). It depends on the frame, so it is
//!   added per frame by a Schur complement on the precomputed constrained
//!   inverse (only its columns at the constrained points are kept): a frame
//!   with `a` angle constraints also solves one dense `4a × 4a` system.
//! - **G¹ flexibility** ([`SplineSkinning::pose_flexible`], §4): after the
//!   fixed-ratio fit, iterations alternate the paper's two linear forms
//!   (odd: tangent directions fixed, magnitudes `α, β` free; even: the
//!   current magnitude ratio fixed, directions free), each a dense KKT solve
//!   over all coordinates. C¹ junctions relax to G¹ there (the paper treats
//!   smooth junctions as G¹ when editing), `δ` is dropped (exact G¹), angle
//!   junctions keep their skinned rotation, and `α, β ≤ 0` are clamped to
//!   1e-3 of the neutral tangent's length, as the paper clamps them.
//! - **Space.** The neutral pool is mapped by `geomBindTransform` first, like
//!   the mesh's points; the posed pool is in skeleton space, like the
//!   skinned mesh.

use faer::Mat;
use faer::linalg::solvers::Solve;
use glam::{DMat3, DVec3};

use super::transform::{Mat4, transform_point};
use super::weights::WeightField;
use super::weights::normalize;
use crate::error::SkinningError;
use crate::error::{Error, Result};

/// Sine of the largest angle between `u_a` and `−u_b` detected as G¹.
pub const G1_TOLERANCE: f64 = 1e-4;
/// Largest relative difference of the tangent lengths of a G¹ junction detected as C¹.
pub const C1_TOLERANCE: f64 = 1e-3;
/// Largest difference (radians, 2°) from a right angle detected as a fixed-angle junction.
pub const RIGHT_ANGLE_TOLERANCE: f64 = 2.0 * std::f64::consts::PI / 180.0;

/// Options of [`SplineSkinning::new`].
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub struct SplineSkinningOptions {
    /// Gauss–Legendre intervals (5 points each) per spline for `Â`, `Ŵ_i`
    /// and the rest lengths.
    pub quadrature_intervals: usize,
    /// Samples per spline (midpoints of equal parameter steps) of the
    /// integrated distance to the densely skinned curve.
    pub distance_samples: usize,
    /// Whether right-angle junctions are detected and kept (G¹ and C¹ always are).
    pub angle_constraints: bool,
}

impl Default for SplineSkinningOptions {
    fn default() -> Self {
        Self { quadrature_intervals: 4, distance_samples: 64, angle_constraints: true }
    }
}

impl SplineSkinningOptions {
    pub fn with_quadrature_intervals(mut self, n: usize) -> Self {
        self.quadrature_intervals = n;
        self
    }

    pub fn with_distance_samples(mut self, n: usize) -> Self {
        self.distance_samples = n;
        self
    }

    pub fn with_angle_constraints(mut self, on: bool) -> Self {
        self.angle_constraints = on;
        self
    }
}

/// One end of a spline at a knot: the spline and the handle next to the knot.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub struct SplineEnd {
    pub spline: u32,
    pub handle: u32,
}

/// What a junction keeps.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum JunctionKind {
    /// Equal opposite tangents: `u_a' = −u_b'`.
    C1,
    /// Opposite tangents with the neutral length ratio: `u_a' = −ρ u_b'`.
    G1,
    /// The neutral angle (radians) between the tangents, and the ratio:
    /// `R(n, angle) u_a' = ρ u_b'` about the skinned normal `n`.
    Angle(f64),
}

/// A continuity constraint detected at a knot of the neutral curvenet.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Junction {
    /// The knot (pool index).
    pub knot: u32,
    /// The two spline ends, `a` then `b`.
    pub ends: [SplineEnd; 2],
    pub kind: JunctionKind,
    /// `‖u_a‖ / ‖u_b‖` in the neutral pose (1 for C¹).
    pub ratio: f64,
}

/// What [`SplineSkinning::pose_flexible`] did.
#[derive(Debug, Clone, PartialEq)]
pub struct FlexibleReport {
    /// Linear solves done after the fixed-ratio fit.
    pub iterations: usize,
    /// The energy after the fixed-ratio fit, then after each iteration.
    pub energies: Vec<f64>,
    /// Tangent magnitudes clamped because they came out non-positive.
    pub clamped: usize,
}

/// The integrated distance between a posed pool's curves and the densely
/// skinned neutral curves.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CurveDistance {
    /// `Σ_j ℓ_j ∫‖B'_j(t) − s_j(t)‖dt / Σ_j ℓ_j` (midpoint rule).
    pub mean: f64,
    /// The largest distance at any sample.
    pub max: f64,
}

/// A curve point with its quadrature weight, neutral position and joint weights.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
struct Node {
    spline: u32,
    /// Bernstein basis at the node's parameter.
    basis: [f64; 4],
    /// The neutral (skeleton-space) point.
    neutral: [f64; 3],
    /// `ℓ_j ω` (quadrature) or `ℓ_j / n` (distance samples).
    weight: f64,
    joints: Vec<(u32, f64)>,
}

#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
struct JunctionRow {
    /// Unknown indices of handle a, handle b, knot.
    a: usize,
    b: usize,
    k: usize,
    /// Neutral tangents (skeleton space).
    ua: DVec3,
    ub: DVec3,
    /// The knot's normalised joint weights.
    knot_joints: Vec<(u32, f64)>,
}

/// The per-frame Schur complement data of the angle constraints.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
struct AngleBlock {
    /// Junction indices of the angle constraints.
    #[serde(with = "crate::persist::pod")]
    junctions: Vec<usize>,
    /// Unknown indices of the constrained points (handles and knots).
    #[serde(with = "crate::persist::pod")]
    points: Vec<usize>,
    /// Local index in `points` of (a, b, k) per angle constraint.
    local: Vec<[usize; 3]>,
    /// Constrained inverse columns at `points`: `n_unknowns × points.len()`, row-major.
    #[serde(with = "crate::persist::pod")]
    zc: Vec<f64>,
}

/// The precomputed spline skinning of one curvenet (see the module docs).
/// Immutable, `Send + Sync`.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct SplineSkinning {
    n_joints: usize,
    #[serde(with = "crate::persist::pod")]
    splines: Vec<[u32; 4]>,
    /// The neutral pool in skeleton space (`geomBindTransform` applied).
    #[serde(with = "crate::persist::pod")]
    neutral: Vec<[f64; 3]>,
    /// Pool index → unknown index (`u32::MAX`: unused by every spline).
    #[serde(with = "crate::persist::pod")]
    unknown_of: Vec<u32>,
    /// Unknown index → pool index.
    #[serde(with = "crate::persist::pod")]
    used: Vec<u32>,
    /// Joints with an `O_i`, increasing.
    #[serde(with = "crate::persist::pod")]
    joints: Vec<u32>,
    /// `O_i` per joint of `joints`: `n_unknowns` rows of 4.
    o: Vec<Vec<[f64; 4]>>,
    /// `G_i` per joint of `joints` (for the flexible iterations).
    g: Vec<Vec<[f64; 4]>>,
    /// `Q` as (row, column, value) entries, duplicates summed.
    q: Vec<(u32, u32, f64)>,
    /// Normalised weights of each pool point for naive skinning (empty: unweighted, unused point).
    naive: Vec<Vec<(u32, f64)>>,
    junctions: Vec<Junction>,
    rows: Vec<JunctionRow>,
    angles: Option<AngleBlock>,
    #[serde(with = "crate::persist::pod")]
    rest_lengths: Vec<f64>,
    quadrature: Vec<Node>,
    samples: Vec<Node>,
}

/// Gauss–Legendre nodes and weights on [−1, 1], 5 points.
const GL5: [(f64, f64); 5] = [
    (0.0, 0.568_888_888_888_888_9),
    (-0.538_469_310_105_683_1, 0.478_628_670_499_366_5),
    (0.538_469_310_105_683_1, 0.478_628_670_499_366_5),
    (-0.906_179_845_938_664, 0.236_926_885_056_189_08),
    (0.906_179_845_938_664, 0.236_926_885_056_189_08),
];

/// Rows of one angle constraint: `R u_a − ρ u_b = 0` (3) and `n · u_a = 0`.
const ANGLE_ROWS: usize = 4;

fn bernstein(t: f64) -> [f64; 4] {
    let s = 1.0 - t;
    [s * s * s, 3.0 * s * s * t, 3.0 * s * t * t, t * t * t]
}

fn bernstein_derivative(t: f64) -> [f64; 4] {
    let s = 1.0 - t;
    [-3.0 * s * s, 3.0 * s * s - 6.0 * s * t, 6.0 * s * t - 3.0 * t * t, 3.0 * t * t]
}

fn eval(pool: &[[f64; 3]], s: [u32; 4], basis: [f64; 4]) -> [f64; 3] {
    let mut p = [0.0; 3];
    for (k, b) in s.iter().zip(basis) {
        for c in 0..3 {
            p[c] += b * pool[*k as usize][c];
        }
    }
    p
}

fn v(p: [f64; 3]) -> DVec3 {
    DVec3::from_array(p)
}

/// The linear part of `M` as a column-vector matrix (`L u` maps a direction).
fn linear(m: &Mat4) -> DMat3 {
    DMat3::from_cols_array(&[m[0], m[1], m[2], m[4], m[5], m[6], m[8], m[9], m[10]])
}

/// The rotation by `angle` about the unit axis `n` (column vectors).
fn rotation(n: DVec3, angle: f64) -> DMat3 {
    DMat3::from_axis_angle(n, angle)
}

impl SplineSkinning {
    /// Precomputes the spline skinning of a curvenet.
    ///
    /// - `pool`: `#P` neutral control points (mesh space);
    /// - `splines`: `#S` control-point quadruples (valid indices, as
    ///   [`crate::Curvenet::new`] checks);
    /// - `weights`: the joint weights along the splines, over `#J` joints;
    /// - `geom_bind`: the `geomBindTransform` (mesh space → skeleton space).
    pub fn new(
        pool: &[[f64; 3]],
        splines: &[[u32; 4]],
        weights: &dyn WeightField,
        geom_bind: &Mat4,
        options: &SplineSkinningOptions,
    ) -> Result<Self> {
        let curvenet = crate::Curvenet::new(splines, pool)?;
        super::transform::check_affine(geom_bind, "geomBindTransform", 0)?;
        if options.quadrature_intervals == 0 || options.distance_samples == 0 {
            return Err(Error::InvalidParameter { what: "spline skinning quadrature and sample counts", value: 0.0 });
        }
        let n_joints = weights.n_joints();
        let neutral: Vec<[f64; 3]> = pool.iter().map(|p| transform_point(geom_bind, *p)).collect();
        let mut unknown_of = vec![u32::MAX; pool.len()];
        let mut used = Vec::new();
        for s in splines {
            for &k in s {
                if unknown_of[k as usize] == u32::MAX {
                    unknown_of[k as usize] = used.len() as u32;
                    used.push(k);
                }
            }
        }
        let n = used.len();
        let unk = |p: u32| unknown_of[p as usize] as usize;

        // Quadrature nodes, rest lengths, Q and the G_i.
        let mut rule = Vec::new();
        let h = 1.0 / options.quadrature_intervals as f64;
        for i in 0..options.quadrature_intervals {
            for (x, w) in GL5 {
                rule.push((h * (i as f64 + 0.5 * (x + 1.0)), 0.5 * h * w));
            }
        }
        let mut rest_lengths = Vec::with_capacity(splines.len());
        let mut quadrature = Vec::with_capacity(splines.len() * rule.len());
        let mut scratch = Vec::new();
        for (j, s) in splines.iter().enumerate() {
            let length: f64 =
                rule.iter().map(|&(t, w)| w * v(eval(&neutral, *s, bernstein_derivative(t))).length()).sum();
            if !(length > 0.0) {
                return Err(Error::ZeroLengthSpline { spline: j });
            }
            rest_lengths.push(length);
            for &(t, w) in &rule {
                let basis = bernstein(t);
                weights.along(*s, t, eval(pool, *s, basis), &mut scratch)?;
                normalize(&mut scratch, "the curve point of spline", j)?;
                let joints = scratch.clone();
                quadrature.push(Node {
                    spline: j as u32,
                    basis,
                    neutral: eval(&neutral, *s, basis),
                    weight: length * w,
                    joints,
                });
            }
        }
        let mut joint_slot = vec![u32::MAX; n_joints];
        let mut joints: Vec<u32> = Vec::new();
        let mut q = Vec::with_capacity(splines.len() * 16);
        for node in &quadrature {
            for &(jt, _) in &node.joints {
                if joint_slot[jt as usize] == u32::MAX {
                    joint_slot[jt as usize] = 0;
                    joints.push(jt);
                }
            }
        }
        // Junctions need the knots' weights: their joints need slots too.
        let (junctions, rows) = detect_junctions(&curvenet, &neutral, pool, weights, &unk, options.angle_constraints)?;
        for r in &rows {
            for &(jt, _) in &r.knot_joints {
                if joint_slot[jt as usize] == u32::MAX {
                    joint_slot[jt as usize] = 0;
                    joints.push(jt);
                }
            }
        }
        joints.sort_unstable();
        for (i, &jt) in joints.iter().enumerate() {
            joint_slot[jt as usize] = i as u32;
        }
        let mut g = vec![vec![[0.0; 4]; n]; joints.len()];
        for node in &quadrature {
            let s = splines[node.spline as usize];
            let hom = [node.neutral[0], node.neutral[1], node.neutral[2], 1.0];
            for a in 0..4 {
                for b in 0..4 {
                    q.push((unk(s[a]) as u32, unk(s[b]) as u32, node.weight * node.basis[a] * node.basis[b]));
                }
                for &(jt, w) in &node.joints {
                    let row = &mut g[joint_slot[jt as usize] as usize][unk(s[a])];
                    for d in 0..4 {
                        row[d] += node.weight * w * node.basis[a] * hom[d];
                    }
                }
            }
        }
        q = merge(q);

        // The scalar KKT system: Q and the G¹/C¹ rows (angle rows come per frame).
        let lin: Vec<usize> =
            (0..junctions.len()).filter(|&r| !matches!(junctions[r].kind, JunctionKind::Angle(_))).collect();
        let size = n + lin.len();
        let mut k = Mat::<f64>::zeros(size, size);
        for &(r, c, x) in &q {
            k[(r as usize, c as usize)] += x;
        }
        for (l, &r) in lin.iter().enumerate() {
            let (row, rho) = (&rows[r], junctions[r].ratio);
            for (col, coef) in [(row.a, 1.0), (row.b, rho), (row.k, -(1.0 + rho))] {
                k[(n + l, col)] += coef;
                k[(col, n + l)] += coef;
            }
        }
        // Right-hand sides: [G_i; B_i] per joint (4 columns each), then the
        // unit vectors of the angle-constrained points.
        let angle_junctions: Vec<usize> =
            (0..junctions.len()).filter(|&r| matches!(junctions[r].kind, JunctionKind::Angle(_))).collect();
        let mut angle_points: Vec<usize> = Vec::new();
        let mut local = Vec::new();
        for &r in &angle_junctions {
            let row = &rows[r];
            let mut l = [0; 3];
            for (slot, p) in [row.a, row.b, row.k].into_iter().enumerate() {
                l[slot] = match angle_points.iter().position(|&x| x == p) {
                    Some(i) => i,
                    None => {
                        angle_points.push(p);
                        angle_points.len() - 1
                    }
                };
            }
            local.push(l);
        }
        let n_rhs = 4 * joints.len() + angle_points.len();
        let mut rhs = Mat::<f64>::zeros(size, n_rhs);
        for (i, gi) in g.iter().enumerate() {
            for (u, row) in gi.iter().enumerate() {
                for d in 0..4 {
                    rhs[(u, 4 * i + d)] = row[d];
                }
            }
        }
        for (l, &r) in lin.iter().enumerate() {
            let row = &rows[r];
            let delta = row.ua + junctions[r].ratio * row.ub;
            for &(jt, w) in &row.knot_joints {
                let i = joint_slot[jt as usize] as usize;
                for d in 0..3 {
                    rhs[(n + l, 4 * i + d)] += w * delta[d];
                }
            }
        }
        for (c, &p) in angle_points.iter().enumerate() {
            rhs[(p, 4 * joints.len() + c)] = 1.0;
        }
        let x = solve_checked(&k, &rhs)?;
        let o =
            (0..joints.len()).map(|i| (0..n).map(|u| std::array::from_fn(|d| x[(u, 4 * i + d)])).collect()).collect();
        let angles = (!angle_junctions.is_empty()).then(|| {
            let m = angle_points.len();
            let mut zc = vec![0.0; n * m];
            for u in 0..n {
                for c in 0..m {
                    zc[u * m + c] = x[(u, 4 * joints.len() + c)];
                }
            }
            AngleBlock { junctions: angle_junctions, points: angle_points, local, zc }
        });

        // Naive weights of every pool point, and the distance samples.
        let mut naive = vec![Vec::new(); pool.len()];
        for (p, w) in naive.iter_mut().enumerate() {
            weights.at_control_point(p, pool[p], &mut scratch)?;
            if scratch.iter().map(|x| x.1).sum::<f64>().abs() > 1e-12 {
                normalize(&mut scratch, "control point", p)?;
            } else if unknown_of[p] != u32::MAX {
                return Err(SkinningError::Unweighted { what: "control point", index: p }.into());
            } else {
                scratch.clear();
            }
            w.clone_from(&scratch);
        }
        let ns = options.distance_samples;
        let mut samples = Vec::with_capacity(splines.len() * ns);
        for (j, s) in splines.iter().enumerate() {
            for i in 0..ns {
                let t = (i as f64 + 0.5) / ns as f64;
                let basis = bernstein(t);
                weights.along(*s, t, eval(pool, *s, basis), &mut scratch)?;
                normalize(&mut scratch, "the curve point of spline", j)?;
                samples.push(Node {
                    spline: j as u32,
                    basis,
                    neutral: eval(&neutral, *s, basis),
                    weight: rest_lengths[j] / ns as f64,
                    joints: scratch.clone(),
                });
            }
        }
        Ok(Self {
            n_joints,
            splines: splines.to_vec(),
            neutral,
            unknown_of,
            used,
            joints,
            o,
            g,
            q,
            naive,
            junctions,
            rows,
            angles,
            rest_lengths,
            quadrature,
            samples,
        })
    }

    /// Number of control points of the pool (the length of a pose).
    pub fn n_points(&self) -> usize {
        self.neutral.len()
    }

    /// The number of skinning transforms a pose takes (the skeleton's joints).
    pub fn n_joints(&self) -> usize {
        self.n_joints
    }

    /// The joints that weigh on the curvenet (one `O_i` each), increasing.
    pub fn joints(&self) -> &[u32] {
        &self.joints
    }

    /// The detected junction constraints.
    pub fn junctions(&self) -> &[Junction] {
        &self.junctions
    }

    /// The neutral rest length `ℓ_j` of each spline (skeleton space).
    pub fn rest_lengths(&self) -> &[f64] {
        &self.rest_lengths
    }

    /// The neutral pool in skeleton space.
    pub fn neutral(&self) -> &[[f64; 3]] {
        &self.neutral
    }

    fn check_transforms(&self, transforms: &[Mat4], out: Option<usize>) -> Result<()> {
        if transforms.len() != self.n_joints {
            return Err(SkinningError::JointCount {
                what: "spline skinning transforms",
                expected: self.n_joints,
                got: transforms.len(),
            }
            .into());
        }
        for (j, m) in transforms.iter().enumerate() {
            if !m.iter().all(|x| x.is_finite()) {
                return Err(SkinningError::NonFiniteTransform { what: "skinning transform of joint", index: j }.into());
            }
        }
        if let Some(len) = out
            && len != self.n_points()
        {
            return Err(Error::CountMismatch { what: "posed control points", expected: self.n_points(), got: len });
        }
        Ok(())
    }

    /// The spline-skinned pool for the skinning transforms `transforms` (one
    /// per joint, [`super::Mat4`] convention), into `out` (`#P`): `Σ_i O_i ·
    /// M_i[:, 0..3]`, plus the per-frame angle constraints.
    pub fn pose(&self, transforms: &[Mat4], out: &mut [[f64; 3]]) -> Result<()> {
        self.check_transforms(transforms, Some(out.len()))?;
        let mut x = self.fit_without_angles(transforms);
        if let Some(block) = &self.angles {
            let rots = self.angle_rotations(block, transforms, &x)?;
            self.apply_angles(block, &rots, &mut x)?;
        }
        self.scatter(&x, transforms, out);
        Ok(())
    }

    /// `Σ_i O_i · M_i[:, 0..3]`: the fit with the G¹ and C¹ constraints, per unknown.
    fn fit_without_angles(&self, transforms: &[Mat4]) -> Vec<[f64; 3]> {
        let mut x = vec![[0.0; 3]; self.used.len()];
        for (i, &jt) in self.joints.iter().enumerate() {
            let m = &transforms[jt as usize];
            for (xu, o) in x.iter_mut().zip(&self.o[i]) {
                for c in 0..3 {
                    xu[c] += o[0] * m[c] + o[1] * m[4 + c] + o[2] * m[8 + c] + o[3] * m[12 + c];
                }
            }
        }
        x
    }

    /// Each angle junction of `block` this frame: the rotation `R(n, θ)`,
    /// the ratio `ρ` and the axis `n`, from the two tangents of `x0` (the fit
    /// without the angle constraints): `n` the normal of their plane, `ρ`
    /// their length ratio. Where they are parallel, `n` is the normal of the
    /// two neutral tangents mapped by the knot's blended linear transform and
    /// `ρ` the neutral ratio (see the module docs).
    fn angle_rotations(
        &self,
        block: &AngleBlock,
        transforms: &[Mat4],
        x0: &[[f64; 3]],
    ) -> Result<Vec<(DMat3, f64, DVec3)>> {
        block
            .junctions
            .iter()
            .map(|&r| {
                let (row, jn) = (&self.rows[r], &self.junctions[r]);
                let JunctionKind::Angle(angle) = jn.kind else { unreachable!("an angle junction") };
                let plane_normal = |ua: DVec3, ub: DVec3| {
                    let axis = ua.cross(ub);
                    let len = axis.length();
                    (len > 1e-9 * ua.length() * ub.length()).then(|| axis / len)
                };
                let (ua, ub) = (v(x0[row.a]) - v(x0[row.k]), v(x0[row.b]) - v(x0[row.k]));
                if let Some(axis) = plane_normal(ua, ub) {
                    return Ok((rotation(axis, angle), ua.length() / ub.length(), axis));
                }
                let l = knot_linear(&row.knot_joints, transforms);
                let axis =
                    plane_normal(l * row.ua, l * row.ub).ok_or(SkinningError::DegenerateAngleAxis { knot: jn.knot })?;
                Ok((rotation(axis, angle), jn.ratio, axis))
            })
            .collect()
    }

    /// Adds the angle constraints `R u_a = ρ u_b` and `n · u_a = 0` to the
    /// fit `x` (which satisfies the others) by the Schur complement on the
    /// constrained inverse.
    fn apply_angles(&self, block: &AngleBlock, rots: &[(DMat3, f64, DVec3)], x: &mut [[f64; 3]]) -> Result<()> {
        let m = block.points.len();
        let rows = ANGLE_ROWS * rots.len();
        // E: rows × (3 coordinates × m points), column c * m + p.
        let mut e = vec![0.0; rows * 3 * m];
        for (r, ((rot, rho, n), l)) in rots.iter().zip(&block.local).enumerate() {
            let [a, b, k] = *l;
            for row in 0..3 {
                let er = &mut e[(ANGLE_ROWS * r + row) * 3 * m..(ANGLE_ROWS * r + row + 1) * 3 * m];
                for c in 0..3 {
                    let rc = rot.col(c)[row]; // R[row][c]
                    er[c * m + a] += rc;
                    er[c * m + k] -= rc;
                }
                er[row * m + b] -= rho;
                er[row * m + k] += rho;
            }
            let er = &mut e[(ANGLE_ROWS * r + 3) * 3 * m..(ANGLE_ROWS * r + 4) * 3 * m];
            for c in 0..3 {
                er[c * m + a] += n[c];
                er[c * m + k] -= n[c];
            }
        }
        // S = E (I3 ⊗ Zs) Eᵀ with Zs the constrained inverse among the points.
        let zs = |p: usize, q: usize| block.zc[block.points[p] * m + q];
        let mut ez = vec![0.0; rows * 3 * m];
        for r in 0..rows {
            for c in 0..3 {
                for q in 0..m {
                    ez[r * 3 * m + c * m + q] = (0..m).map(|p| e[r * 3 * m + c * m + p] * zs(p, q)).sum();
                }
            }
        }
        let mut s = Mat::<f64>::zeros(rows, rows);
        let mut rhs = Mat::<f64>::zeros(rows, 1);
        for r in 0..rows {
            for t in 0..rows {
                s[(r, t)] = (0..3 * m).map(|i| ez[r * 3 * m + i] * e[t * 3 * m + i]).sum();
            }
            rhs[(r, 0)] =
                (0..3).map(|c| (0..m).map(|p| e[r * 3 * m + c * m + p] * x[block.points[p]][c]).sum::<f64>()).sum();
        }
        let mu = solve_checked(&s, &rhs)?;
        // x -= (I3 ⊗ Zc) Eᵀ μ
        let mut y = vec![0.0; 3 * m];
        for r in 0..rows {
            for i in 0..3 * m {
                y[i] += e[r * 3 * m + i] * mu[(r, 0)];
            }
        }
        for (u, xu) in x.iter_mut().enumerate() {
            let zrow = &block.zc[u * m..(u + 1) * m];
            for c in 0..3 {
                xu[c] -= (0..m).map(|q| zrow[q] * y[c * m + q]).sum::<f64>();
            }
        }
        Ok(())
    }

    /// Unknowns to the pool; unused pool points skinned naively.
    fn scatter(&self, x: &[[f64; 3]], transforms: &[Mat4], out: &mut [[f64; 3]]) {
        for (p, o) in out.iter_mut().enumerate() {
            *o = match self.unknown_of[p] {
                u32::MAX => naive_point(self.neutral[p], &self.naive[p], transforms),
                u => x[u as usize],
            };
        }
    }

    /// Naive control-point skinning (Liu et al.'s first comparison): every
    /// pool point skinned by its own weights, as if it were a mesh vertex.
    pub fn pose_naive(&self, transforms: &[Mat4], out: &mut [[f64; 3]]) -> Result<()> {
        self.check_transforms(transforms, Some(out.len()))?;
        for (p, o) in out.iter_mut().enumerate() {
            *o = naive_point(self.neutral[p], &self.naive[p], transforms);
        }
        Ok(())
    }

    /// The integrated distance of `pool`'s curves to the densely skinned
    /// neutral curves (each sample skinned by its own weights).
    pub fn distance_to_skinned(&self, pool: &[[f64; 3]], transforms: &[Mat4]) -> Result<CurveDistance> {
        self.check_transforms(transforms, Some(pool.len()))?;
        let (mut sum, mut max) = (0.0, 0.0f64);
        for node in &self.samples {
            let d = self.node_error(node, pool, transforms).length();
            sum += node.weight * d;
            max = max.max(d);
        }
        Ok(CurveDistance { mean: sum / self.rest_lengths.iter().sum::<f64>(), max })
    }

    /// The fitting energy of `pool`: `Σ_j ℓ_j ∫‖B'_j − s_j‖² dt` by the quadrature.
    pub fn energy(&self, pool: &[[f64; 3]], transforms: &[Mat4]) -> Result<f64> {
        self.check_transforms(transforms, Some(pool.len()))?;
        Ok(self
            .quadrature
            .iter()
            .map(|node| node.weight * self.node_error(node, pool, transforms).length_squared())
            .sum())
    }

    fn node_error(&self, node: &Node, pool: &[[f64; 3]], transforms: &[Mat4]) -> DVec3 {
        let fit = eval(pool, self.splines[node.spline as usize], node.basis);
        let target = naive_point(node.neutral, &node.joints, transforms);
        v(fit) - v(target)
    }

    /// The fit with flexible G¹ tangent ratios (§4): [`Self::pose`], then up
    /// to `max_iterations` alternating solves (see the module docs), stopping
    /// early once an odd/even pair lowers the energy by less than 1e-10 of it.
    pub fn pose_flexible(
        &self,
        transforms: &[Mat4],
        max_iterations: usize,
        out: &mut [[f64; 3]],
    ) -> Result<FlexibleReport> {
        self.pose(transforms, out)?;
        let mut report = FlexibleReport { iterations: 0, energies: vec![self.energy(out, transforms)?], clamped: 0 };
        if self.junctions.is_empty() {
            return Ok(report);
        }
        let rots: Vec<Option<(DMat3, DVec3)>> = match &self.angles {
            None => vec![None; self.junctions.len()],
            Some(block) => {
                let mut all = vec![None; self.junctions.len()];
                let x0 = self.fit_without_angles(transforms);
                for (&r, (rot, _, n)) in block.junctions.iter().zip(self.angle_rotations(block, transforms, &x0)?) {
                    all[r] = Some((rot, n));
                }
                all
            }
        };
        let n = self.used.len();
        // g = Σ_i G_i M_i[:, 0..3], coordinate-major.
        let mut g = vec![0.0; 3 * n];
        for (i, &jt) in self.joints.iter().enumerate() {
            let m = &transforms[jt as usize];
            for (u, row) in self.g[i].iter().enumerate() {
                for c in 0..3 {
                    g[c * n + u] += row[0] * m[c] + row[1] * m[4 + c] + row[2] * m[8 + c] + row[3] * m[12 + c];
                }
            }
        }
        let mut x: Vec<[f64; 3]> = self.used.iter().map(|&p| out[p as usize]).collect();
        for it in 0..max_iterations {
            let odd = it % 2 == 0;
            // Odd: one magnitude per constrained handle, `x_h − x_k = α_h d_h`,
            // the directions d_h propagated through the junctions from the
            // current fit (a handle in two junctions gets one direction).
            let mut ends: Vec<(usize, usize, DVec3, f64)> = Vec::new();
            if odd {
                for (r, jr) in self.rows.iter().enumerate() {
                    let ua = v(x[jr.a]) - v(x[jr.k]);
                    let ub = v(x[jr.b]) - v(x[jr.k]);
                    let known = |h: usize, ends: &[(usize, usize, DVec3, f64)]| {
                        ends.iter().find(|e| e.0 == h && e.1 == jr.k).map(|e| e.2)
                    };
                    let (da, db) = match (rots[r].map(|x| x.0), known(jr.a, &ends), known(jr.b, &ends)) {
                        (_, Some(da), Some(db)) => (da, db),
                        (Some(rot), Some(da), None) => (da, rot * da),
                        (Some(rot), None, Some(db)) => (rot.transpose() * db, db),
                        (Some(rot), None, None) => {
                            let da = ua.normalize_or_zero();
                            (da, rot * da)
                        }
                        (None, Some(da), None) => (da, -da),
                        (None, None, Some(db)) => (-db, db),
                        (None, None, None) => {
                            let db = (ub - ua).normalize_or_zero();
                            (-db, db)
                        }
                    };
                    for (h, d, neutral) in [(jr.a, da, jr.ua), (jr.b, db, jr.ub)] {
                        if known(h, &ends).is_none() {
                            ends.push((h, jr.k, d, 1e-3 * neutral.length()));
                        }
                    }
                }
            }
            let extra = ends.len();
            let n_angles = rots.iter().filter(|r| r.is_some()).count();
            let n_rows = if odd { 3 * ends.len() } else { 3 * self.junctions.len() + n_angles };
            let size = 3 * n + extra + n_rows;
            let mut k = Mat::<f64>::zeros(size, size);
            let mut rhs = Mat::<f64>::zeros(size, 1);
            for c in 0..3 {
                for &(r, col, val) in &self.q {
                    k[(c * n + r as usize, c * n + col as usize)] += val;
                }
                for u in 0..n {
                    rhs[(c * n + u, 0)] = g[c * n + u];
                }
            }
            let mut row_at = 3 * n + extra;
            let put = |k: &mut Mat<f64>, row: usize, col: usize, val: f64| {
                k[(row, col)] += val;
                k[(col, row)] += val;
            };
            if odd {
                for (e, &(h, kn, d, _)) in ends.iter().enumerate() {
                    for c in 0..3 {
                        put(&mut k, row_at, c * n + h, 1.0);
                        put(&mut k, row_at, c * n + kn, -1.0);
                        put(&mut k, row_at, 3 * n + e, -d[c]);
                        row_at += 1;
                    }
                }
            } else {
                // Eq. 5 / Eq. 13 with the current magnitude ratio.
                for (r, jr) in self.rows.iter().enumerate() {
                    let ua = v(x[jr.a]) - v(x[jr.k]);
                    let ub = v(x[jr.b]) - v(x[jr.k]);
                    let rho = ua.length() / ub.length().max(f64::MIN_POSITIVE);
                    let rot = rots[r].map_or(-DMat3::IDENTITY, |x| x.0);
                    for row in 0..3 {
                        for c in 0..3 {
                            let rc = rot.col(c)[row];
                            put(&mut k, row_at, c * n + jr.a, rc);
                            put(&mut k, row_at, c * n + jr.k, -rc);
                        }
                        put(&mut k, row_at, row * n + jr.b, -rho);
                        put(&mut k, row_at, row * n + jr.k, rho);
                        row_at += 1;
                    }
                    if let Some((_, axis)) = rots[r] {
                        for c in 0..3 {
                            put(&mut k, row_at, c * n + jr.a, axis[c]);
                            put(&mut k, row_at, c * n + jr.k, -axis[c]);
                        }
                        row_at += 1;
                    }
                }
            }
            let sol = solve_checked(&k, &rhs)?;
            for (u, xu) in x.iter_mut().enumerate() {
                for c in 0..3 {
                    xu[c] = sol[(c * n + u, 0)];
                }
            }
            for (e, &(h, kn, d, floor)) in ends.iter().enumerate() {
                if !(sol[(3 * n + e, 0)] >= floor) {
                    report.clamped += 1;
                    x[h] = (v(x[kn]) + d * floor).to_array();
                }
            }
            self.scatter(&x, transforms, out);
            report.iterations += 1;
            report.energies.push(self.energy(out, transforms)?);
            let e = &report.energies;
            if !odd && e.len() >= 3 && e[e.len() - 3] - e[e.len() - 1] <= 1e-10 * e[e.len() - 3].abs() {
                break;
            }
        }
        Ok(report)
    }

    /// For tests and reports: each junction's constraint residual for a
    /// posed `pool`: `‖u_a' + ρ u_b' − L_k δ‖` (G¹, C¹) or `‖R u_a' − ρ
    /// u_b'‖ + |n · u_a'|` (angle), in skeleton-space units.
    pub fn junction_residuals(&self, pool: &[[f64; 3]], transforms: &[Mat4]) -> Result<Vec<f64>> {
        self.check_transforms(transforms, Some(pool.len()))?;
        let rots = match &self.angles {
            Some(block) => {
                let x0 = self.fit_without_angles(transforms);
                block.junctions.iter().copied().zip(self.angle_rotations(block, transforms, &x0)?).collect()
            }
            None => Vec::new(),
        };
        Ok(self
            .junctions
            .iter()
            .zip(&self.rows)
            .enumerate()
            .map(|(r, (jn, row))| {
                let p = |u: usize| v(pool[self.used[u] as usize]);
                let (ua, ub) = (p(row.a) - p(row.k), p(row.b) - p(row.k));
                match jn.kind {
                    JunctionKind::Angle(_) => {
                        let (rot, rho, n) = rots.iter().find(|(i, _)| *i == r).expect("every angle junction").1;
                        (rot * ua - rho * ub).length() + n.dot(ua).abs()
                    }
                    _ => {
                        let l = knot_linear(&row.knot_joints, transforms);
                        (ua + jn.ratio * ub - l * (row.ua + jn.ratio * row.ub)).length()
                    }
                }
            })
            .collect())
    }
}

/// `Σ_i w_i · ([p 1] · M_i)`.
fn naive_point(p: [f64; 3], joints: &[(u32, f64)], transforms: &[Mat4]) -> [f64; 3] {
    if joints.is_empty() {
        return p;
    }
    let mut acc = [0.0; 3];
    for &(j, w) in joints {
        let x = transform_point(&transforms[j as usize], p);
        for c in 0..3 {
            acc[c] += w * x[c];
        }
    }
    acc
}

/// The linear part of the knot's blended transform, `Σ_i w_i L_i`.
fn knot_linear(joints: &[(u32, f64)], transforms: &[Mat4]) -> DMat3 {
    joints.iter().fold(DMat3::ZERO, |acc, &(j, w)| acc + linear(&transforms[j as usize]) * w)
}

/// Sums duplicate (row, column) entries.
fn merge(mut entries: Vec<(u32, u32, f64)>) -> Vec<(u32, u32, f64)> {
    entries.sort_unstable_by_key(|e| (e.0, e.1));
    let mut out: Vec<(u32, u32, f64)> = Vec::with_capacity(entries.len());
    for e in entries {
        match out.last_mut() {
            Some(last) if last.0 == e.0 && last.1 == e.1 => last.2 += e.2,
            _ => out.push(e),
        }
    }
    out
}

/// Solves `k x = rhs` by LU with partial pivoting and refuses a result whose
/// residual shows `k` singular (repeated constraints) or that is not finite.
fn solve_checked(k: &Mat<f64>, rhs: &Mat<f64>) -> Result<Mat<f64>> {
    let x = k.partial_piv_lu().solve(rhs);
    let residual = k * &x - rhs;
    let scale = |m: &Mat<f64>| {
        let mut s = 0.0f64;
        for c in 0..m.ncols() {
            for r in 0..m.nrows() {
                s = s.max(m[(r, c)].abs());
            }
        }
        s
    };
    let (res, kx) = (scale(&residual), scale(k) * scale(&x) + scale(rhs));
    if !(res <= 1e-9 * kx) {
        return Err(Error::Internal {
            what: format!("spline skinning: the constrained fit is singular (residual {res:e} of {kx:e})"),
        });
    }
    Ok(x)
}

/// Finds the junction constraints of the neutral curvenet (module docs).
fn detect_junctions(
    curvenet: &crate::Curvenet,
    neutral: &[[f64; 3]],
    pool: &[[f64; 3]],
    weights: &dyn WeightField,
    unk: &dyn Fn(u32) -> usize,
    angles: bool,
) -> Result<(Vec<Junction>, Vec<JunctionRow>)> {
    let splines = curvenet.splines();
    let tiny = 1e-9 * crate::mesh::bounding_box_diagonal(neutral);
    // Spline ends per knot: (spline, handle, t of the knot on the spline).
    let mut ends: Vec<Vec<(u32, u32, f64)>> = vec![Vec::new(); neutral.len()];
    for (s, sp) in splines.iter().enumerate() {
        ends[sp[0] as usize].push((s as u32, sp[1], 0.0));
        ends[sp[3] as usize].push((s as u32, sp[2], 1.0));
    }
    let mut junctions = Vec::new();
    let mut rows = Vec::new();
    let mut scratch = Vec::new();
    for (knot, at) in ends.iter().enumerate() {
        if at.len() < 2 {
            continue;
        }
        let tangent = |h: u32| v(neutral[h as usize]) - v(neutral[knot]);
        let live: Vec<usize> = (0..at.len()).filter(|&e| tangent(at[e].1).length() > tiny).collect();
        // Candidate pairs: (class, closeness, a, b, kind, ratio).
        let mut smooth = Vec::new();
        let mut corners = Vec::new();
        let mut group: Vec<usize> = (0..at.len()).collect();
        for (i, &ea) in live.iter().enumerate() {
            for &eb in &live[i + 1..] {
                if at[ea].1 == at[eb].1 {
                    union(&mut group, ea, eb); // one handle: one tangent
                    continue;
                }
                let (ua, ub) = (tangent(at[ea].1), tangent(at[eb].1));
                let (la, lb) = (ua.length(), ub.length());
                let (da, db) = (ua / la, ub / lb);
                let sine = da.cross(db).length();
                let cosine = da.dot(db);
                if cosine < 0.0 && sine <= G1_TOLERANCE {
                    let kind = if (la / lb - 1.0).abs() <= C1_TOLERANCE { JunctionKind::C1 } else { JunctionKind::G1 };
                    smooth.push((sine, ea, eb, kind));
                } else {
                    let angle = sine.atan2(cosine);
                    let off = (angle - std::f64::consts::FRAC_PI_2).abs();
                    if angles && off <= RIGHT_ANGLE_TOLERANCE {
                        corners.push((off, ea, eb, JunctionKind::Angle(angle)));
                    }
                }
            }
        }
        smooth.sort_by(|a, b| a.0.total_cmp(&b.0));
        corners.sort_by(|a, b| a.0.total_cmp(&b.0));
        for (_, ea, eb, kind) in smooth.into_iter().chain(corners) {
            if find(&mut group, ea) == find(&mut group, eb) {
                continue;
            }
            union(&mut group, ea, eb);
            let (sa, ha, ta) = at[ea];
            let (sb, hb, _) = at[eb];
            let (ua, ub) = (tangent(ha), tangent(hb));
            let ratio = if kind == JunctionKind::C1 { 1.0 } else { ua.length() / ub.length() };
            weights.along(splines[sa as usize], ta, pool[knot], &mut scratch)?;
            normalize(&mut scratch, "knot (control point)", knot)?;
            junctions.push(Junction {
                knot: knot as u32,
                ends: [SplineEnd { spline: sa, handle: ha }, SplineEnd { spline: sb, handle: hb }],
                kind,
                ratio,
            });
            rows.push(JunctionRow {
                a: unk(ha),
                b: unk(hb),
                k: unk(knot as u32),
                ua,
                ub,
                knot_joints: scratch.clone(),
            });
        }
    }
    Ok((junctions, rows))
}

fn find(group: &mut [usize], mut i: usize) -> usize {
    while group[i] != i {
        group[i] = group[group[i]];
        i = group[i];
    }
    i
}

fn union(group: &mut [usize], a: usize, b: usize) {
    let (ra, rb) = (find(group, a), find(group, b));
    group[ra] = rb;
}
