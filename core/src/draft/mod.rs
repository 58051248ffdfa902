//! Drafting a starting curvenet on a mesh from plane sections: rings around
//! a main axis joined by lengthwise lines, with knots shared at their
//! crossings, cubic splines fitted to the sections and pushed off the
//! surface. For a rigging TD starting a new character (`curvenet draft`),
//! and for the fixtures and the binding stress test, which draw random
//! networks from the same code ([`Jitter`]).
//!
//! # Construction
//!
//! 1. **Frame.** The axis is [`DraftOptions::axis`] or the principal axis of
//!    the area-weighted vertex distribution (each vertex weighs a third of
//!    the area of its fan triangles); the *across* direction, the normal of
//!    the lengthwise planes, is the principal axis of the same distribution
//!    projected onto the plane perpendicular to the axis.
//! 2. **Rings** are the sections by `rings` planes perpendicular to the axis,
//!    evenly spaced over [`DraftOptions::span`] (fractions of the mesh's
//!    extent along the axis). Every loop of a section (or open polyline, on
//!    a mesh with a boundary) is a ring loop; loops shorter than
//!    [`TINY_LOOP`] mean edges are dropped.
//! 3. **Lines** are the sections by `lines` *parallel* planes containing the
//!    axis direction (normal: *across*), evenly spaced at `(j + 1) / (lines +
//!    1)` of the mesh's extent across, so two lines never meet. Lines are
//!    clipped to the slab between the first and the last ring plane: their
//!    ends are T-junctions (valence 3) on the end rings, their crossings with
//!    inner rings intersections (valence 4). A line loop inside the slab that
//!    meets no ring is kept as an isolated closed curve.
//! 4. **Knots** are shared: a crossing is the one point of a fan triangle on
//!    both planes, computed once and inserted into both sections.
//! 5. **Offset.** Every section point is pushed off the surface along the
//!    area-weighted vertex normal interpolated at it by `offset ×
//!    diagonal`, unless that would bring it closer to another part of the
//!    surface (a concavity narrower than the offset, a nearby limb): then
//!    the push is halved, up to three times, and dropped to zero after that
//!    (the point stays on the surface). A push counts as clear when the
//!    pushed point is at least half the push from the surface and the
//!    surface closest to it does not face back at it (its normal is less
//!    than 90° from the pushing normal): a point pushed across a crease or
//!    towards another limb finds a surface facing back at it. Pushes are then
//!    eroded (windowed minimum) and smoothed (windowed mean) along each
//!    section over half the offset (at least a mean edge) either way, so a
//!    reduced push ramps instead of jumping and never exceeds what is clear.
//! 6. **Splines.** Each piece of a section between consecutive knots is
//!    fitted by cubic Béziers: fixed ends, handles along the section's
//!    tangent at the ends (so a ring passes through its knots smoothly),
//!    handle lengths by least squares over chord-length parameters,
//!    split at the worst point (a new valence-2 knot) while the error
//!    exceeds [`FIT_TOLERANCE`] mean edges and the piece is longer than
//!    [`MIN_SPLIT_LENGTH`] mean edges. Closed loops get at least 3 splines
//!    (isolated loops 4). So the knots sit at their push off the surface
//!    (at most the offset) and the curves, which the binding samples, within
//!    the fit tolerance of the pushed sections; handles go wherever the fit
//!    puts them (outside a convex arc, inside a concave one), so their own
//!    distance to the surface is not bounded by the offset.
//!
//! # What is refused, and what is tried instead
//!
//! "On one sheet" below means in neighbouring fan triangles that face the
//! same way (normals less than 60° apart, sharing a vertex or joined by an
//! edge): the two sides of a thin fin, or a flipper against the body, are
//! close in space but not on one sheet, and a curve may pass between them.
//!
//! A ring plane position is refused when
//! - a crossing with a line is grazing (the two sections meet at less than
//!   [`MIN_CROSSING_DEGREES`] on the surface), or one of the sections sees
//!   a crossing the other does not (a crossing on a triangle edge);
//! - two crossings come within [`MIN_KNOT_SEPARATION`] mean edges of each
//!   other on one sheet (also against the rings placed before);
//! - a line crosses one of its loops shorter than [`TINY_LOOP`] mean edges
//!   (a dropped loop);
//! - a near miss: the ring and a line come within [`MIN_KNOT_SEPARATION`]
//!   mean edges of each other on one sheet, each within half that of the
//!   other's plane, away from their crossings;
//! - its section is pinched: two of its loops, or two parts of one loop
//!   more than [`NETWORK_NEIGHBOURHOOD`] mean edges apart along it, come
//!   within [`MIN_KNOT_SEPARATION`] mean edges on one sheet (a plane
//!   through a saddle, a loop squeezed where a limb meets the body);
//! - its loops come within [`MIN_KNOT_SEPARATION`] mean edges of another
//!   ring's plane, or the other's loops of its plane (tilted rings).
//!
//! The ring is then moved along the axis by ±1/16, ±2/16, ..., ±6/16 of the
//! ring spacing, in that order, and a tilted ring tries the same positions
//! untilted.
//!
//! The finished curvenet is refused when a line's section is pinched
//! between the end rings, or when the final check fails: every spline is
//! sampled every quarter mean edge, the samples are projected onto the
//! surface (closest points), and splines must stay [`MIN_CURVE_SEPARATION`]
//! mean edges apart on one sheet except where they are within
//! [`NETWORK_NEIGHBOURHOOD`] mean edges of each other along the curvenet
//! (next to a shared knot, or where a curve turns around a thin part): so
//! curves never cross except at shared knots. The rings the check blames
//! are moved to their next position and the curvenet is built again; when
//! a ring has no position left, or the lines are to blame, all line planes
//! are moved together by ±1/4, ±1/8, ±3/8 of their spacing and the rings are
//! placed again. When nothing fits, [`DraftError::NoCleanLayout`] says why
//! the last try failed.
//!
//! # Determinism
//!
//! The same mesh, points and options give the same curvenet bit for bit
//! (sequential arithmetic, no hashing order, [`SplitMix64`] for the jitter).

mod fit;
mod rng;
mod section;
mod surface;

use glam::{DQuat, DVec3};

pub use rng::SplitMix64;
use section::{Plane, Polyline, SurfacePoint, section};
use surface::TriSurface;

use crate::error::Error;
use crate::mesh::PolyMesh;

/// Section loops shorter than this many mean edge lengths are dropped.
pub const TINY_LOOP: f64 = 4.0;
/// Knots closer than this many mean edge lengths refuse a plane position.
pub const MIN_KNOT_SEPARATION: f64 = 1.0;
/// A ring and a line must cross at least at this angle on the surface.
pub const MIN_CROSSING_DEGREES: f64 = 20.0;
/// Largest distance from a fitted spline to its section points, in mean edges.
pub const FIT_TOLERANCE: f64 = 0.25;
/// Pieces shorter than this many mean edges are not split further.
pub const MIN_SPLIT_LENGTH: f64 = 4.0;
/// Projected splines must stay this many mean edges apart on the surface...
pub const MIN_CURVE_SEPARATION: f64 = 0.5;
/// ...except where they are within this many mean edges of each other
/// along the curvenet (next to a shared knot, around a thin part).
pub const NETWORK_NEIGHBOURHOOD: f64 = 4.0;
/// `cos(MIN_CROSSING_DEGREES)`, spelled out so no trigonometry runs
/// without jitter.
const MAX_CROSSING_COS: f64 = 0.939_692_620_785_908_4;
/// Largest accepted `offset` (fraction of the diagonal).
pub const MAX_OFFSET: f64 = 0.1;

/// What to draft. `Default` gives 5 rings over 10–90 % of the principal
/// axis, 4 lines, 0.5 % of the diagonal off the surface, no jitter.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub struct DraftOptions {
    /// The main axis (any length); `None`: the principal axis.
    pub axis: Option<[f64; 3]>,
    /// Normal of the lengthwise planes (made perpendicular to the axis);
    /// `None`: the principal axis across.
    pub across: Option<[f64; 3]>,
    /// Number of ring planes (at least 1; at least 2 when there are lines).
    pub rings: usize,
    /// Number of lengthwise planes (0: rings only).
    pub lines: usize,
    /// First and last ring plane as fractions of the extent along the axis,
    /// `0 <= span[0] < span[1] <= 1` (with one ring: its midpoint).
    pub span: [f64; 2],
    /// Distance off the surface as a fraction of the bounding-box diagonal,
    /// `0 <= offset <= MAX_OFFSET`.
    pub offset: f64,
    /// Seeded random perturbations (the stress test; `curvenet draft --seed`).
    pub jitter: Option<Jitter>,
}

impl Default for DraftOptions {
    fn default() -> Self {
        Self { axis: None, across: None, rings: 5, lines: 4, span: [0.1, 0.9], offset: 0.005, jitter: None }
    }
}

impl DraftOptions {
    pub fn with_axis(mut self, axis: [f64; 3]) -> Self {
        self.axis = Some(axis);
        self
    }
    pub fn with_across(mut self, across: [f64; 3]) -> Self {
        self.across = Some(across);
        self
    }
    pub fn with_rings(mut self, rings: usize) -> Self {
        self.rings = rings;
        self
    }
    pub fn with_lines(mut self, lines: usize) -> Self {
        self.lines = lines;
        self
    }
    pub fn with_span(mut self, span: [f64; 2]) -> Self {
        self.span = span;
        self
    }
    pub fn with_offset(mut self, offset: f64) -> Self {
        self.offset = offset;
        self
    }
    pub fn with_jitter(mut self, jitter: Option<Jitter>) -> Self {
        self.jitter = jitter;
        self
    }
}

/// Seeded random perturbations of a draft. Every magnitude may be 0.
#[derive(Debug, Clone, Copy, PartialEq)]
#[non_exhaustive]
pub struct Jitter {
    pub seed: u64,
    /// Each ring and line plane moves by up to this fraction of its spacing.
    pub plane_shift: f64,
    /// Each ring plane tilts by up to this many degrees about a random
    /// direction across the axis.
    pub ring_tilt_degrees: f64,
    /// The lines' common normal turns about the axis by up to this many degrees.
    pub line_turn_degrees: f64,
    /// Each knot (with its neighbouring handles) moves towards the surface
    /// by up to this fraction of its push.
    pub knot_offset: f64,
    /// Each handle moves by up to this fraction of its distance to its knot.
    pub handle: f64,
}

impl Jitter {
    /// The default magnitudes: planes shifted by up to 1/4 of their spacing,
    /// rings tilted by up to 10°, lines turned by up to 90°, knots pulled in
    /// by up to half their push, handles moved by up to 15 %.
    pub fn new(seed: u64) -> Self {
        Self {
            seed,
            plane_shift: 0.25,
            ring_tilt_degrees: 10.0,
            line_turn_degrees: 90.0,
            knot_offset: 0.5,
            handle: 0.15,
        }
    }
}

/// Why no curvenet was drafted.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum DraftError {
    /// An option is out of range.
    #[error("draft option {what}: {problem}")]
    Option { what: &'static str, problem: String },
    /// The mesh is not an oriented manifold or has bad points.
    #[error(transparent)]
    Mesh(#[from] Error),
    /// The ring planes cut nothing worth a curve.
    #[error("no ring plane cuts the mesh in a loop longer than {TINY_LOOP} mean edges; try another --axis or --span")]
    Empty,
    /// Every placement of the planes that was tried broke a rule (see the
    /// module docs); `reason` is the last one's.
    #[error(
        "no clean curvenet with these options ({attempts} complete placements of the planes tried); the last \
         failure: {reason} (try other --rings, --lines, --axis or --span, or a --seed)"
    )]
    NoCleanLayout { attempts: usize, reason: String },
}

/// A drafted curvenet: the arguments of [`crate::Curvenet::new`], and how it was made.
#[derive(Debug, Clone, PartialEq)]
pub struct Draft {
    /// Control points: the knots first, then two handles per spline.
    pub pool: Vec<[f64; 3]>,
    /// Cubic Bézier splines `[knot, handle, handle, knot]`.
    pub splines: Vec<[u32; 4]>,
    pub report: DraftReport,
}

/// How a draft was made and what it holds.
#[derive(Debug, Clone, PartialEq)]
pub struct DraftReport {
    /// Unit axis and across directions; the area-weighted centroid.
    pub axis: [f64; 3],
    pub across: [f64; 3],
    pub centroid: [f64; 3],
    pub rings: Vec<RingReport>,
    pub lines: Vec<LineReport>,
    /// Knots by valence: all, 1 (free ends), 3 (T-junctions), 4 or more (intersections).
    pub knots: usize,
    pub anchors: usize,
    pub t_junctions: usize,
    pub intersections: usize,
    /// Closed curves through no intersection.
    pub isolated_loops: usize,
    pub splines: usize,
    /// The requested offset in stage units, and how many section points got less.
    pub offset: f64,
    pub reduced_pushes: usize,
    /// Largest distance from a spline to the (pushed) section points it fits, in stage units.
    pub max_fit_error: f64,
    /// Placements of the line planes tried (1 when the first fitted).
    pub attempts: usize,
    pub mean_edge_length: f64,
    pub diagonal: f64,
}

/// A ring plane as used.
#[derive(Debug, Clone, PartialEq)]
pub struct RingReport {
    /// Unit normal (along the axis unless tilted) and the point where the
    /// plane meets the axis line through the centroid.
    pub normal: [f64; 3],
    pub point: [f64; 3],
    /// Length-weighted centroid of its loops (`point` when it has none).
    pub centre: [f64; 3],
    /// Position along the axis of `point`, relative to the centroid.
    pub position: f64,
    pub loops: usize,
}

/// A line plane as used: `{x : normal · x = offset}`.
#[derive(Debug, Clone, PartialEq)]
pub struct LineReport {
    pub normal: [f64; 3],
    pub offset: f64,
}

/// Drafts a curvenet on `mesh` posed at `points` (see the module docs).
pub fn draft(mesh: &PolyMesh, points: &[[f64; 3]], options: &DraftOptions) -> Result<Draft, DraftError> {
    check_options(options)?;
    let surface = TriSurface::new(mesh, points)?;
    let frame = Frame::new(&surface, options)?;
    let mut rng = options.jitter.map(|j| SplitMix64::new(j.seed));
    let plan = Plan::new(&surface, &frame, options, rng.as_mut());

    let line_shifts: &[f64] =
        if options.lines == 0 { &[0.0] } else { &[0.0, 0.25, -0.25, 0.125, -0.125, 0.375, -0.375] };
    let mut reason = String::new();
    let mut attempts = 0;
    for &shift in line_shifts {
        let lines = plan.line_planes(shift, &surface);
        let line_sections: Vec<Vec<Polyline>> = lines.iter().map(|p| section(&surface, p, p.normal)).collect();
        // Rings are placed at their first clean position; a ring the final
        // check blames starts again after the position it had.
        let mut first = vec![0; plan.rings.len()];
        loop {
            let (rings, chosen) = match place_rings(&surface, &frame, &plan, &lines, &line_sections, &first) {
                Ok(r) => r,
                Err(why) => {
                    reason = why;
                    break;
                }
            };
            if rings.iter().all(|r| r.loops.is_empty()) {
                return Err(DraftError::Empty);
            }
            attempts += 1;
            // Jitter after the placement draws the same numbers on every attempt.
            let mut local_rng = rng.clone();
            match assemble(&surface, &frame, options, &rings, &lines, &line_sections, local_rng.as_mut()) {
                Ok(mut d) => {
                    d.report.attempts = attempts;
                    return Ok(d);
                }
                Err(failure) => {
                    reason = failure.message;
                    if failure.rings.is_empty() {
                        break;
                    }
                    for k in failure.rings {
                        first[k] = chosen[k] + 1;
                    }
                }
            }
        }
    }
    Err(DraftError::NoCleanLayout { attempts, reason })
}

fn check_options(o: &DraftOptions) -> Result<(), DraftError> {
    let bad = |what, problem: String| Err(DraftError::Option { what, problem });
    if o.rings == 0 {
        return bad("rings", "must be at least 1".into());
    }
    if o.lines > 0 && o.rings < 2 {
        return bad(
            "rings",
            format!("must be at least 2 with lines (the lines run between the first and last ring), got {}", o.rings),
        );
    }
    if o.rings > 1000 || o.lines > 1000 {
        return bad("rings/lines", format!("at most 1000 each, got {} and {}", o.rings, o.lines));
    }
    let [lo, hi] = o.span;
    if !(lo.is_finite() && hi.is_finite() && 0.0 <= lo && lo < hi && hi <= 1.0) {
        return bad("span", format!("must satisfy 0 <= first < last <= 1, got [{lo}, {hi}]"));
    }
    if !(o.offset.is_finite() && (0.0..=MAX_OFFSET).contains(&o.offset)) {
        return bad("offset", format!("must be in [0, {MAX_OFFSET}] (a fraction of the diagonal), got {}", o.offset));
    }
    for (what, v) in [("axis", o.axis), ("across", o.across)] {
        if let Some(v) = v {
            let d = DVec3::from_array(v);
            if !(d.is_finite() && d.length() > 0.0) {
                return bad(what, format!("must be a finite non-zero vector, got {v:?}"));
            }
        }
    }
    if let Some(j) = o.jitter {
        let all = [j.plane_shift, j.ring_tilt_degrees, j.line_turn_degrees, j.knot_offset, j.handle];
        if !all.iter().all(|x| x.is_finite() && *x >= 0.0) || j.plane_shift > 0.5 || j.knot_offset > 1.0 {
            return bad(
                "jitter",
                format!("magnitudes must be finite and non-negative (plane shift <= 0.5, knot offset <= 1), got {j:?}"),
            );
        }
    }
    Ok(())
}

/// The drafting frame: unit axis and across directions, centroid, extents.
struct Frame {
    centroid: DVec3,
    axis: DVec3,
    across: DVec3,
    axis_range: [f64; 2],
    across_range: [f64; 2],
}

impl Frame {
    fn new(surface: &TriSurface, o: &DraftOptions) -> Result<Self, DraftError> {
        let (centroid, cov) = surface.weighted_covariance();
        let axis = match o.axis {
            Some(a) => DVec3::from_array(a).normalize(),
            None => surface::symmetric_eigenvectors(cov)[0],
        };
        let across = match o.across {
            Some(b) => DVec3::from_array(b).reject_from(axis),
            None => {
                // The principal axis of the distribution projected across the
                // axis: the top eigenvector of P C P, P = I - a aᵀ.
                let p = |r: usize, c: usize| f64::from(r == c) - axis[r] * axis[c];
                let mut pc = [[0.0; 3]; 3];
                for r in 0..3 {
                    for c in 0..3 {
                        pc[r][c] = (0..3).map(|m| p(r, m) * cov[m][c]).sum();
                    }
                }
                let mut pcp = [[0.0; 3]; 3];
                for r in 0..3 {
                    for c in 0..3 {
                        pcp[r][c] = (0..3).map(|m| pc[r][m] * p(m, c)).sum();
                    }
                }
                surface::symmetric_eigenvectors(pcp)[0].reject_from(axis)
            }
        };
        if !(across.length() > 1e-6) {
            return Err(DraftError::Option { what: "across", problem: "must not be parallel to the axis".into() });
        }
        let across = across.normalize();
        Ok(Self {
            centroid,
            axis,
            across,
            axis_range: extent_along(surface, centroid, axis),
            across_range: extent_along(surface, centroid, across),
        })
    }

    /// The point at position `s` along the axis line through the centroid.
    fn at(&self, s: f64) -> DVec3 {
        self.centroid + self.axis * s
    }
}

/// Nominal plane positions (with the jitter applied).
struct Plan {
    /// Per ring: unit normal and position along the axis (relative to the centroid).
    rings: Vec<(DVec3, f64)>,
    ring_spacing: f64,
    axis_range: [f64; 2],
    /// Per line: position across (relative to the centroid).
    lines: Vec<f64>,
    line_spacing: f64,
    across: DVec3,
    centroid: DVec3,
}

impl Plan {
    fn new(surface: &TriSurface, frame: &Frame, o: &DraftOptions, mut rng: Option<&mut SplitMix64>) -> Self {
        let [a0, a1] = frame.axis_range;
        let extent = a1 - a0;
        let [lo, hi] = o.span;
        let ring_spacing = if o.rings > 1 { (hi - lo) * extent / (o.rings - 1) as f64 } else { (hi - lo) * extent };
        let mut rings = Vec::with_capacity(o.rings);
        for k in 0..o.rings {
            let f = if o.rings > 1 { lo + (hi - lo) * k as f64 / (o.rings - 1) as f64 } else { 0.5 * (lo + hi) };
            let mut s = a0 + f * extent;
            let mut normal = frame.axis;
            if let (Some(j), Some(r)) = (o.jitter, rng.as_deref_mut()) {
                s += r.signed() * j.plane_shift * ring_spacing;
                let turn = r.range(0.0, std::f64::consts::TAU);
                let tilt_axis = DQuat::from_axis_angle(frame.axis, turn) * frame.across;
                normal = DQuat::from_axis_angle(tilt_axis, r.signed() * j.ring_tilt_degrees.to_radians()) * frame.axis;
            }
            rings.push((normal, s));
        }
        let mut across = frame.across;
        if let (Some(j), Some(r)) = (o.jitter, rng.as_deref_mut()) {
            across = (DQuat::from_axis_angle(frame.axis, r.signed() * j.line_turn_degrees.to_radians()) * across)
                .normalize();
        }
        let [b0, b1] =
            if across == frame.across { frame.across_range } else { extent_along(surface, frame.centroid, across) };
        let line_spacing = (b1 - b0) / (o.lines + 1) as f64;
        let mut lines = Vec::with_capacity(o.lines);
        for j in 0..o.lines {
            let mut b = b0 + (j + 1) as f64 * line_spacing;
            if let (Some(jit), Some(r)) = (o.jitter, rng.as_deref_mut()) {
                b += r.signed() * jit.plane_shift * line_spacing;
            }
            lines.push(b);
        }
        Self {
            rings,
            ring_spacing,
            axis_range: frame.axis_range,
            lines,
            line_spacing,
            across,
            centroid: frame.centroid,
        }
    }

    fn line_planes(&self, shift: f64, surface: &TriSurface) -> Vec<Plane> {
        self.lines
            .iter()
            .map(|&b| {
                let point = self.centroid + self.across * (b + shift * self.line_spacing);
                Plane::through(self.across, point).clear_of_vertices(surface)
            })
            .collect()
    }
}

/// The smallest and largest `(p - origin) · d` over the vertices.
fn extent_along(surface: &TriSurface, origin: DVec3, d: DVec3) -> [f64; 2] {
    surface.points.iter().fold([f64::INFINITY, f64::NEG_INFINITY], |r, p| {
        let x = (*p - origin).dot(d);
        [r[0].min(x), r[1].max(x)]
    })
}

/// A ring × line crossing: where it sits in both sections.
#[derive(Debug, Clone, Copy)]
struct Crossing {
    /// Index into the ring's kept loops, segment, parameter on the segment.
    ring_loop: usize,
    ring_seg: usize,
    ring_u: f64,
    line: usize,
    line_poly: usize,
    line_seg: usize,
    line_u: f64,
    point: SurfacePoint,
    tri: u32,
}

/// A placed ring plane with its kept loops and its crossings.
struct Ring {
    plane: Plane,
    position: f64,
    point: DVec3,
    loops: Vec<Polyline>,
    crossings: Vec<Crossing>,
}

/// Ring positions tried, in sixteenths of the ring spacing from the nominal one.
const RING_STEPS: [f64; 13] = [0.0, 1.0, -1.0, 2.0, -2.0, 3.0, -3.0, 4.0, -4.0, 5.0, -5.0, 6.0, -6.0];

/// Places every ring plane in turn at its first clean candidate from
/// `first[k]` on (see the module docs): the positions of [`RING_STEPS`]
/// with the ring's normal, then (for a tilted ring) the same positions
/// untilted. Says why a ring could not be placed, or returns the rings and
/// the candidate each took.
fn place_rings(
    surface: &TriSurface,
    frame: &Frame,
    plan: &Plan,
    lines: &[Plane],
    line_sections: &[Vec<Polyline>],
    first: &[usize],
) -> Result<(Vec<Ring>, Vec<usize>), String> {
    let [a0, a1] = plan.axis_range;
    let margin = 1e-3 * (a1 - a0);
    let mut rings: Vec<Ring> = Vec::with_capacity(plan.rings.len());
    let mut chosen = Vec::with_capacity(plan.rings.len());
    for (k, &(normal, s)) in plan.rings.iter().enumerate() {
        let mut reason = format!("ring {k} has no clean position inside the mesh's extent");
        let mut placed = None;
        // Every position with the (jittered) normal, then without the tilt.
        let normals = if normal == frame.axis { vec![normal] } else { vec![normal, frame.axis] };
        let candidates = normals.iter().flat_map(|&n| RING_STEPS.iter().map(move |&shift| (n, shift)));
        for (step, (normal, shift)) in candidates.enumerate().skip(first[k]) {
            let position = s + shift * plan.ring_spacing / 16.0;
            if position < a0 + margin || position > a1 - margin {
                continue;
            }
            let point = frame.at(position);
            let plane = Plane::through(normal, point).clear_of_vertices(surface);
            match try_ring(k, surface, plane, position, point, &rings, lines, line_sections) {
                Ok(ring) => {
                    placed = Some((ring, step));
                    break;
                }
                Err(why) => reason = why,
            }
        }
        let (ring, step) = placed.ok_or(reason)?;
        rings.push(ring);
        chosen.push(step);
    }
    Ok((rings, chosen))
}

/// Whether section polylines come within `sep` of each other on one sheet
/// of the surface (see `TriSurface::same_sheet`) other than along
/// themselves: two polylines, or two parts of one polyline more than
/// `reach` apart along it (a plane through a saddle, a loop pinched where a
/// limb meets the body). Only points for which `keep` holds count.
fn pinched(surface: &TriSurface, polys: &[&Polyline], sep: f64, reach: f64, keep: impl Fn(DVec3) -> bool) -> bool {
    // (polyline, arc length, position, triangle)
    let mut points: Vec<(usize, f64, DVec3, u32)> = Vec::new();
    let mut lengths = Vec::with_capacity(polys.len());
    for (pi, l) in polys.iter().enumerate() {
        let mut arc = 0.0;
        for i in 0..l.points.len() {
            if i > 0 {
                arc += l.points[i - 1].pos.distance(l.points[i].pos);
            }
            if keep(l.points[i].pos) {
                points.push((pi, arc, l.points[i].pos, l.tri_of_point(i)));
            }
        }
        lengths.push(l.length());
    }
    let cell = |p: DVec3| ((p / sep).floor()).as_i64vec3();
    let mut grid: rustc_hash::FxHashMap<glam::I64Vec3, Vec<u32>> = rustc_hash::FxHashMap::default();
    for (i, x) in points.iter().enumerate() {
        grid.entry(cell(x.2)).or_default().push(i as u32);
    }
    for (i, a) in points.iter().enumerate() {
        let c = cell(a.2);
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let Some(list) = grid.get(&(c + glam::I64Vec3::new(dx, dy, dz))) else { continue };
                    for &j in list {
                        let b = &points[j as usize];
                        if (j as usize) <= i || a.2.distance(b.2) >= sep || !surface.same_sheet(a.3, b.3) {
                            continue;
                        }
                        let apart = if a.0 != b.0 {
                            f64::INFINITY
                        } else {
                            let d = (a.1 - b.1).abs();
                            if polys[a.0].closed { d.min(lengths[a.0] - d) } else { d }
                        };
                        if apart > reach {
                            return true;
                        }
                    }
                }
            }
        }
    }
    false
}

/// The ring `k` at `plane`, if it passes every ring-local rule.
#[allow(clippy::too_many_arguments)]
fn try_ring(
    k: usize,
    surface: &TriSurface,
    plane: Plane,
    position: f64,
    point: DVec3,
    placed: &[Ring],
    lines: &[Plane],
    line_sections: &[Vec<Polyline>],
) -> Result<Ring, String> {
    let edge = surface.mean_edge;
    let sep = MIN_KNOT_SEPARATION * edge;
    let all = section(surface, &plane, plane.normal);
    let mut kept_index = vec![usize::MAX; all.len()];
    let mut loops = Vec::new();
    for (i, l) in all.iter().enumerate() {
        if l.length() >= TINY_LOOP * edge {
            kept_index[i] = loops.len();
            loops.push(l.clone());
        }
    }
    // Tilted rings must stay clear of each other's planes.
    for (kk, r) in placed.iter().enumerate() {
        let near = loops.iter().flat_map(|l| &l.points).any(|p| r.plane.distance(p.pos) < sep)
            || r.loops.iter().flat_map(|l| &l.points).any(|p| plane.distance(p.pos) > -sep);
        if near {
            return Err(format!("ring {k} comes within {MIN_KNOT_SEPARATION} mean edges of ring {kk}'s plane"));
        }
    }
    let mut crossings = Vec::new();
    for (j, (lp, polys)) in lines.iter().zip(line_sections).enumerate() {
        let crossings_of = |polys: &[Polyline], by: &Plane| {
            let mut found: Vec<(u32, usize, usize, f64)> = Vec::new();
            for (pi, l) in polys.iter().enumerate() {
                for i in 0..l.n_segments() {
                    let (a, b) = l.segment(i);
                    if by.side(a) != by.side(b) {
                        let (da, db) = (by.distance(a), by.distance(b));
                        found.push((l.tris[i], pi, i, (da / (da - db)).clamp(0.0, 1.0)));
                    }
                }
            }
            found.sort_by_key(|c| c.0);
            found
        };
        let from_ring = crossings_of(&all, lp);
        let from_line = crossings_of(polys, &plane);
        if from_ring.len() != from_line.len() || from_ring.iter().zip(&from_line).any(|(r, l)| r.0 != l.0) {
            return Err(format!(
                "ring {k} and line {j} meet where only one of their sections sees the other (a crossing on a triangle edge)"
            ));
        }
        for (r, l) in from_ring.iter().zip(&from_line) {
            let ring_loop = kept_index[r.1];
            if ring_loop == usize::MAX {
                return Err(format!("line {j} crosses a loop of ring {k} shorter than {TINY_LOOP} mean edges"));
            }
            let poly = &all[r.1];
            let (a, b) = (poly.points[r.2], poly.points[(r.2 + 1) % poly.points.len()]);
            let point =
                SurfacePoint { pos: a.pos.lerp(b.pos, r.3), normal: a.normal.lerp(b.normal, r.3).normalize_or_zero() };
            let n = surface.tri_normals[r.0 as usize];
            let (tr, tl) = (plane.normal.cross(n).normalize_or_zero(), lp.normal.cross(n).normalize_or_zero());
            let cos = tr.dot(tl).abs();
            if !(cos <= MAX_CROSSING_COS) {
                return Err(format!(
                    "ring {k} crosses line {j} at {:?} at {:.1}° (less than {MIN_CROSSING_DEGREES}°)",
                    point.pos.to_array(),
                    cos.min(1.0).acos().to_degrees()
                ));
            }
            crossings.push(Crossing {
                ring_loop,
                ring_seg: r.2,
                ring_u: r.3,
                line: j,
                line_poly: l.1,
                line_seg: l.2,
                line_u: l.3,
                point,
                tri: r.0,
            });
        }
    }
    // Knots must not nearly coincide on the surface (see `TriSurface::same_sheet`).
    let close =
        |a: &Crossing, b: &Crossing| a.point.pos.distance(b.point.pos) < sep && surface.same_sheet(a.tri, b.tri);
    for (i, c) in crossings.iter().enumerate() {
        for d in &crossings[i + 1..] {
            if close(c, d) {
                return Err(format!(
                    "ring {k}'s crossings with lines {} and {} are {:.2} mean edges apart (less than {MIN_KNOT_SEPARATION})",
                    c.line,
                    d.line,
                    c.point.pos.distance(d.point.pos) / edge
                ));
            }
        }
        for (kk, r) in placed.iter().enumerate() {
            if r.crossings.iter().any(|d| close(c, d)) {
                return Err(format!(
                    "a crossing of ring {k} is within {MIN_KNOT_SEPARATION} mean edges of one of ring {kk}"
                ));
            }
        }
    }
    // Near misses: the ring and a line come within `sep` of each other on
    // the surface, each near the other's plane, away from their crossings.
    let near_crossing =
        |j: usize, x: DVec3| crossings.iter().any(|c| c.line == j && c.point.pos.distance(x) < 2.0 * sep);
    for (j, (lp, polys)) in lines.iter().zip(line_sections).enumerate() {
        let ring_side: Vec<(DVec3, u32)> = loops
            .iter()
            .flat_map(|l| (0..l.points.len()).map(move |i| (l.points[i].pos, l.tri_of_point(i))))
            .filter(|(p, _)| lp.distance(*p).abs() < 0.5 * sep && !near_crossing(j, *p))
            .collect();
        if ring_side.is_empty() {
            continue;
        }
        let line_side = polys
            .iter()
            .flat_map(|l| (0..l.points.len()).map(move |i| (l.points[i].pos, l.tri_of_point(i))))
            .filter(|(q, _)| plane.distance(*q).abs() < 0.5 * sep && !near_crossing(j, *q));
        for (q, tq) in line_side {
            if ring_side.iter().any(|(p, tp)| p.distance(q) < sep && surface.same_sheet(*tp, tq)) {
                return Err(format!(
                    "ring {k} and line {j} pass within {MIN_KNOT_SEPARATION} mean edges of each other without crossing"
                ));
            }
        }
    }
    // Loops of one section never cross, but nearly touching ones (a plane
    // through a saddle, a pinched loop) could after the fit.
    let refs: Vec<&Polyline> = loops.iter().collect();
    if pinched(surface, &refs, sep, NETWORK_NEIGHBOURHOOD * edge, |_| true) {
        return Err(format!("ring {k}'s section nearly touches itself (within {MIN_KNOT_SEPARATION} mean edges)"));
    }
    Ok(Ring { plane, position, point, loops, crossings })
}

/// What a track is a section of (for messages and the report).
#[derive(Debug, Clone, Copy, PartialEq)]
enum Source {
    Ring(usize),
    Line(usize),
}

impl std::fmt::Display for Source {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Source::Ring(k) => write!(f, "ring {k}"),
            Source::Line(j) => write!(f, "line {j}"),
        }
    }
}

/// A section polyline with the crossing knots inserted (`knot[i]` is the
/// knot at point `i`); closed tracks are cyclic.
struct Track {
    source: Source,
    closed: bool,
    points: Vec<SurfacePoint>,
    knot: Vec<Option<u32>>,
    /// Offset (pushed) positions and pushes, filled by `push_tracks`.
    offset: Vec<DVec3>,
    push: Vec<f64>,
}

impl Track {
    fn new(source: Source, poly: &Polyline, mut insert: Vec<(usize, f64, u32, SurfacePoint)>) -> Self {
        insert.sort_by(|a, b| (a.0, a.1).partial_cmp(&(b.0, b.1)).expect("finite parameters"));
        let mut points = Vec::with_capacity(poly.points.len() + insert.len());
        let mut knot = Vec::with_capacity(points.capacity());
        let mut at = 0;
        for (i, p) in poly.points.iter().enumerate() {
            points.push(*p);
            knot.push(None);
            while at < insert.len() && insert[at].0 == i {
                points.push(insert[at].3);
                knot.push(Some(insert[at].2));
                at += 1;
            }
        }
        Self { source, closed: poly.closed, points, knot, offset: Vec::new(), push: Vec::new() }
    }

    fn len(&self) -> usize {
        self.points.len()
    }

    /// The index after `i` (wrapping on closed tracks), or `None` at the end.
    fn next(&self, i: usize) -> Option<usize> {
        if i + 1 < self.len() {
            Some(i + 1)
        } else if self.closed {
            Some(0)
        } else {
            None
        }
    }

    fn prev(&self, i: usize) -> Option<usize> {
        if i > 0 {
            Some(i - 1)
        } else if self.closed {
            Some(self.len() - 1)
        } else {
            None
        }
    }

    /// Indices within arc length `w` of point `i` along the section (both ways), `i` included.
    fn window(&self, i: usize, w: f64) -> Vec<usize> {
        let mut out = vec![i];
        let n = self.len();
        for step in [Track::next as fn(&Track, usize) -> Option<usize>, Track::prev] {
            let (mut j, mut s) = (i, 0.0);
            while let Some(k) = step(self, j) {
                s += self.points[j].pos.distance(self.points[k].pos);
                if s > w || k == i || out.len() >= n {
                    break;
                }
                out.push(k);
                j = k;
            }
        }
        out.sort_unstable();
        out.dedup();
        out
    }

    /// The unit tangent at point `i` of the pushed polyline: the chord
    /// between the points at arc length `w` before and after it.
    fn tangent(&self, i: usize, w: f64) -> DVec3 {
        let reach = |step: fn(&Track, usize) -> Option<usize>| {
            let (mut j, mut s) = (i, 0.0);
            while let Some(k) = step(self, j) {
                let d = self.offset[j].distance(self.offset[k]);
                if s + d >= w && d > 0.0 {
                    return self.offset[j].lerp(self.offset[k], (w - s) / d);
                }
                s += d;
                j = k;
                if k == i {
                    break;
                }
            }
            self.offset[j]
        };
        let t = (reach(Track::next) - reach(Track::prev)).normalize_or_zero();
        if t != DVec3::ZERO {
            return t;
        }
        let (a, b) = (self.prev(i).unwrap_or(i), self.next(i).unwrap_or(i));
        (self.offset[b] - self.offset[a]).normalize_or_zero()
    }
}

/// The admissible push of a surface point: `h`, halved up to three times
/// until clear (see the module docs), else 0.
fn admissible_push(surface: &TriSurface, p: &SurfacePoint, h: f64) -> f64 {
    if p.normal == DVec3::ZERO {
        return 0.0;
    }
    let mut t = h;
    for _ in 0..4 {
        if t <= 0.0 {
            break;
        }
        let q = p.pos + p.normal * t;
        if let Ok(hit) = surface.bvh.closest_point(q.to_array()) {
            let facing = surface.tri_normals[hit.triangle as usize].dot(p.normal);
            if hit.distance >= 0.5 * t && facing >= 0.0 {
                return t;
            }
        }
        t *= 0.5;
    }
    0.0
}

/// Fills every track's pushes and pushed positions: admissible pushes,
/// eroded then smoothed along each track over `window`; a knot takes the
/// smallest value any of its tracks gives it.
fn push_tracks(surface: &TriSurface, tracks: &mut [Track], n_knots: usize, h: f64, window: f64) -> Vec<f64> {
    let mut knot_push = vec![f64::INFINITY; n_knots];
    let mut admissible: Vec<Vec<f64>> = Vec::with_capacity(tracks.len());
    for t in tracks.iter() {
        let a: Vec<f64> = t
            .points
            .iter()
            .zip(&t.knot)
            .map(|(p, k)| match k {
                Some(k) if knot_push[*k as usize].is_finite() => knot_push[*k as usize],
                _ => admissible_push(surface, p, h),
            })
            .collect();
        for (k, v) in t.knot.iter().zip(&a) {
            if let Some(k) = k {
                knot_push[*k as usize] = *v;
            }
        }
        admissible.push(a);
    }
    let windows: Vec<Vec<Vec<usize>>> =
        tracks.iter().map(|t| (0..t.len()).map(|i| t.window(i, window)).collect()).collect();
    // Erode (windowed minimum), agree at knots, smooth (windowed mean), agree again.
    let mut values = admissible;
    for pass in 0..2 {
        for (w, v) in windows.iter().zip(values.iter_mut()) {
            let next: Vec<f64> = w
                .iter()
                .map(|wi| {
                    let vals = wi.iter().map(|&j| v[j]);
                    if pass == 0 { vals.fold(f64::INFINITY, f64::min) } else { vals.sum::<f64>() / wi.len() as f64 }
                })
                .collect();
            *v = next;
        }
        knot_push.iter_mut().for_each(|x| *x = f64::INFINITY);
        for (t, v) in tracks.iter().zip(&values) {
            for (k, x) in t.knot.iter().zip(v) {
                if let Some(k) = k {
                    knot_push[*k as usize] = knot_push[*k as usize].min(*x);
                }
            }
        }
        for (t, v) in tracks.iter().zip(values.iter_mut()) {
            for (k, x) in t.knot.iter().zip(v.iter_mut()) {
                if let Some(k) = k {
                    *x = knot_push[*k as usize];
                }
            }
        }
    }
    for (t, v) in tracks.iter_mut().zip(values) {
        t.offset = t.points.iter().zip(&v).map(|(p, &x)| p.pos + p.normal * x).collect();
        t.push = v;
    }
    knot_push
}

/// A piece of a track between two knots (or free ends): track indices
/// `start` to `end` following the track; `start == end` on a closed track is
/// the whole loop.
#[derive(Debug, Clone, Copy)]
struct Piece {
    track: usize,
    start: usize,
    end: usize,
}

/// The knots of a draft: surface point, push and pushed position.
#[derive(Default)]
struct Knots {
    normal: Vec<DVec3>,
    push: Vec<f64>,
    pos: Vec<DVec3>,
}

impl Knots {
    fn add(&mut self, normal: DVec3, push: f64, pos: DVec3) -> u32 {
        self.normal.push(normal);
        self.push.push(push);
        self.pos.push(pos);
        (self.pos.len() - 1) as u32
    }
}

/// Why a placement did not give a clean curvenet, and which rings to move.
struct Failure {
    message: String,
    rings: Vec<usize>,
}

impl From<String> for Failure {
    fn from(message: String) -> Self {
        Self { message, rings: Vec::new() }
    }
}

/// Builds the curvenet from placed rings and lines: tracks, pushes,
/// fitted splines, jitter, the final check and the report.
#[allow(clippy::too_many_arguments)]
fn assemble(
    surface: &TriSurface,
    frame: &Frame,
    options: &DraftOptions,
    rings: &[Ring],
    lines: &[Plane],
    line_sections: &[Vec<Polyline>],
    rng: Option<&mut SplitMix64>,
) -> Result<Draft, Failure> {
    let edge = surface.mean_edge;
    let h = options.offset * surface.diagonal;
    type Inserts = Vec<Vec<(usize, f64, u32, SurfacePoint)>>;
    let mut crossing_points = Vec::new();
    let mut ring_inserts: Vec<Inserts> = rings.iter().map(|r| vec![Vec::new(); r.loops.len()]).collect();
    let mut line_inserts: Vec<Inserts> = line_sections.iter().map(|p| vec![Vec::new(); p.len()]).collect();
    for (k, r) in rings.iter().enumerate() {
        for c in &r.crossings {
            let id = crossing_points.len() as u32;
            crossing_points.push(c.point);
            ring_inserts[k][c.ring_loop].push((c.ring_seg, c.ring_u, id, c.point));
            line_inserts[c.line][c.line_poly].push((c.line_seg, c.line_u, id, c.point));
        }
    }
    // Tracks and the pieces worth a curve.
    let mut tracks = Vec::new();
    for (k, r) in rings.iter().enumerate() {
        for (li, l) in r.loops.iter().enumerate() {
            tracks.push(Track::new(Source::Ring(k), l, std::mem::take(&mut ring_inserts[k][li])));
        }
    }
    if rings.len() >= 2 {
        for (j, polys) in line_sections.iter().enumerate() {
            for (pi, l) in polys.iter().enumerate() {
                if l.length() >= TINY_LOOP * edge || !line_inserts[j][pi].is_empty() {
                    tracks.push(Track::new(Source::Line(j), l, std::mem::take(&mut line_inserts[j][pi])));
                }
            }
        }
    }
    let (first, last) = (rings[0].plane, rings[rings.len() - 1].plane);
    let inside = |x: DVec3| first.distance(x) > 0.0 && last.distance(x) < 0.0;
    let mut pieces = Vec::new();
    for (ti, t) in tracks.iter().enumerate() {
        let knots: Vec<usize> = (0..t.len()).filter(|&i| t.knot[i].is_some()).collect();
        let mut candidates = Vec::new();
        if t.closed {
            if knots.is_empty() {
                candidates.push((0, 0));
            } else {
                for m in 0..knots.len() {
                    candidates.push((knots[m], knots[(m + 1) % knots.len()]));
                }
            }
        } else {
            let mut ends = vec![0];
            ends.extend(knots.iter().copied().filter(|&i| i != 0 && i != t.len() - 1));
            ends.push(t.len() - 1);
            for w in ends.windows(2) {
                candidates.push((w[0], w[1]));
            }
        }
        for (start, end) in candidates {
            let keep = match t.source {
                Source::Ring(_) => true,
                Source::Line(_) => {
                    let next = t.next(start).expect("a piece has a second point");
                    inside(t.points[start].pos.lerp(t.points[next].pos, 0.5))
                }
            };
            if keep {
                pieces.push(Piece { track: ti, start, end });
            }
        }
    }
    if pieces.is_empty() {
        return Err(Failure::from("no section piece is left to draw".to_string()));
    }
    // Lines must not nearly touch themselves or each other inside the slab.
    if rings.len() >= 2 {
        let sep = MIN_KNOT_SEPARATION * edge;
        for (j, polys) in line_sections.iter().enumerate() {
            let refs: Vec<&Polyline> = polys.iter().collect();
            if pinched(surface, &refs, sep, NETWORK_NEIGHBOURHOOD * edge, |x| {
                first.distance(x) > 0.5 * sep && last.distance(x) < -0.5 * sep
            }) {
                return Err(Failure::from(format!(
                    "line {j}'s section nearly touches itself between the end rings (within {MIN_KNOT_SEPARATION} mean edges)"
                )));
            }
        }
    }
    // Only tracks with a kept piece are pushed and fitted.
    let mut used = vec![false; tracks.len()];
    pieces.iter().for_each(|p| used[p.track] = true);
    let mut remap = vec![usize::MAX; tracks.len()];
    let mut kept_tracks = Vec::new();
    for (i, t) in tracks.into_iter().enumerate() {
        if used[i] {
            remap[i] = kept_tracks.len();
            kept_tracks.push(t);
        }
    }
    let mut tracks = kept_tracks;
    pieces.iter_mut().for_each(|p| p.track = remap[p.track]);
    let window = (0.5 * h).max(edge);
    let crossing_push = push_tracks(surface, &mut tracks, crossing_points.len(), h, window);
    let mut knots = Knots::default();
    for (p, push) in crossing_points.iter().zip(&crossing_push) {
        let push = if push.is_finite() { *push } else { 0.0 };
        knots.add(p.normal, push, p.pos + p.normal * push);
    }

    // Fit every piece.
    let tol = FIT_TOLERANCE * edge;
    let min_split = MIN_SPLIT_LENGTH * edge;
    let mut splines: Vec<([u32; 2], [DVec3; 2], Source)> = Vec::new();
    let mut max_fit_error: f64 = 0.0;
    let mut isolated_loops = 0;
    for piece in &pieces {
        let t = &tracks[piece.track];
        let mut idx = vec![piece.start];
        let mut i = piece.start;
        loop {
            i = t.next(i).expect("pieces end at a knot or at the track's end");
            idx.push(i);
            if i == piece.end {
                break;
            }
        }
        let q: Vec<DVec3> = idx.iter().map(|&i| t.offset[i]).collect();
        let mut arc = vec![0.0; q.len()];
        for m in 1..q.len() {
            arc[m] = arc[m - 1] + q[m - 1].distance(q[m]);
        }
        let tangents: Vec<DVec3> = idx.iter().map(|&i| t.tangent(i, edge)).collect();
        let knot_at = |local: usize, knots: &mut Knots| -> u32 {
            match t.knot[idx[local]] {
                Some(k) => k,
                None => knots.add(t.points[idx[local]].normal, t.push[idx[local]], t.offset[idx[local]]),
            }
        };
        let last = q.len() - 1;
        // Closed loops through fewer than two knots are cut into 3 (one
        // knot) or 4 (isolated) pieces of equal length first.
        let mut cuts = vec![0];
        if piece.start == piece.end {
            let n = if t.knot[piece.start].is_some() { 3 } else { 4 };
            if t.knot[piece.start].is_none() {
                isolated_loops += 1;
            }
            for m in 1..n {
                let target = arc[last] * m as f64 / n as f64;
                let c = (0..=last).min_by(|&a, &b| (arc[a] - target).abs().total_cmp(&(arc[b] - target).abs()));
                let c = c.expect("a loop has points");
                if c > *cuts.last().expect("non-empty") && c < last {
                    cuts.push(c);
                }
            }
        }
        cuts.push(last);
        let start_knot = knot_at(0, &mut knots);
        let mut local_knot = vec![u32::MAX; q.len()];
        local_knot[0] = start_knot;
        local_knot[last] = if piece.start == piece.end { start_knot } else { knot_at(last, &mut knots) };
        let mut fitted = Vec::new();
        for w in cuts.windows(2) {
            fit_range(&q, &arc, &tangents, w[0], w[1], tol, min_split, &mut fitted);
        }
        for &(lo, hi, curve, error) in &fitted {
            max_fit_error = max_fit_error.max(error);
            for end in [lo, hi] {
                if local_knot[end] == u32::MAX {
                    local_knot[end] = knot_at(end, &mut knots);
                }
            }
            splines.push(([local_knot[lo], local_knot[hi]], [curve[1], curve[2]], t.source));
        }
    }

    // Jitter: knots towards the surface with their handles, then handles.
    if let (Some(j), Some(r)) = (options.jitter, rng) {
        for k in 0..knots.pos.len() {
            let shift = -knots.normal[k] * (r.unit() * j.knot_offset * knots.push[k]);
            knots.pos[k] += shift;
            for (ends, handles, _) in splines.iter_mut() {
                for e in 0..2 {
                    if ends[e] as usize == k {
                        handles[e] += shift;
                    }
                }
            }
        }
        for (ends, handles, _) in splines.iter_mut() {
            for e in 0..2 {
                let reach = handles[e].distance(knots.pos[ends[e] as usize]);
                handles[e] += DVec3::from_array(r.in_ball()) * (j.handle * reach);
            }
        }
    }

    // The pool: used knots first, then two handles per spline.
    let mut knot_index = vec![u32::MAX; knots.pos.len()];
    let mut pool: Vec<[f64; 3]> = Vec::new();
    for (ends, _, _) in &splines {
        for &k in ends {
            if knot_index[k as usize] == u32::MAX {
                knot_index[k as usize] = pool.len() as u32;
                pool.push(knots.pos[k as usize].to_array());
            }
        }
    }
    let n_knots = pool.len();
    let mut out_splines = Vec::with_capacity(splines.len());
    for (ends, handles, _) in &splines {
        let h0 = pool.len() as u32;
        pool.push(handles[0].to_array());
        pool.push(handles[1].to_array());
        out_splines.push([knot_index[ends[0] as usize], h0, h0 + 1, knot_index[ends[1] as usize]]);
    }
    let labels: Vec<Source> = splines.iter().map(|s| s.2).collect();
    check_separation(surface, &pool, &out_splines, &labels)?;

    let mut valence = vec![0usize; n_knots];
    for s in &out_splines {
        valence[s[0] as usize] += 1;
        valence[s[3] as usize] += 1;
    }
    let reduced_pushes = tracks.iter().flat_map(|t| &t.push).filter(|&&x| x < h * (1.0 - 1e-9)).count();
    let report = DraftReport {
        axis: frame.axis.to_array(),
        across: lines.first().map(|p| p.normal).unwrap_or(frame.across).to_array(),
        centroid: frame.centroid.to_array(),
        rings: rings
            .iter()
            .map(|r| {
                let (mut sum, mut length) = (DVec3::ZERO, 0.0);
                for l in &r.loops {
                    for i in 0..l.n_segments() {
                        let (a, b) = l.segment(i);
                        sum += (a + b) * 0.5 * a.distance(b);
                        length += a.distance(b);
                    }
                }
                let centre = if length > 0.0 { sum / length } else { r.point };
                RingReport {
                    normal: r.plane.normal.to_array(),
                    point: r.point.to_array(),
                    centre: centre.to_array(),
                    position: r.position,
                    loops: r.loops.len(),
                }
            })
            .collect(),
        lines: lines.iter().map(|p| LineReport { normal: p.normal.to_array(), offset: p.offset }).collect(),
        knots: n_knots,
        anchors: valence.iter().filter(|&&v| v == 1).count(),
        t_junctions: valence.iter().filter(|&&v| v == 3).count(),
        intersections: valence.iter().filter(|&&v| v >= 4).count(),
        isolated_loops,
        splines: out_splines.len(),
        offset: h,
        reduced_pushes,
        max_fit_error,
        attempts: 1,
        mean_edge_length: edge,
        diagonal: surface.diagonal,
    };
    Ok(Draft { pool, splines: out_splines, report })
}

/// Fits `q[lo..=hi]` by one cubic, or splits it at its worst point (kept
/// in the middle half by arc length) and recurses.
#[allow(clippy::too_many_arguments)]
fn fit_range(
    q: &[DVec3],
    arc: &[f64],
    tangents: &[DVec3],
    lo: usize,
    hi: usize,
    tol: f64,
    min_split: f64,
    out: &mut Vec<(usize, usize, fit::Cubic, f64)>,
) {
    let (curve, error, worst) = fit::fit_one(&q[lo..=hi], tangents[lo], tangents[hi]);
    let length = arc[hi] - arc[lo];
    if error <= tol || length < min_split || hi - lo < 4 {
        out.push((lo, hi, curve, error));
        return;
    }
    let (from, to) = (arc[lo] + 0.25 * length, arc[hi] - 0.25 * length);
    let mut m = lo + worst;
    while arc[m] < from && m + 1 < hi {
        m += 1;
    }
    while arc[m] > to && m > lo + 1 {
        m -= 1;
    }
    if m <= lo || m >= hi {
        out.push((lo, hi, curve, error));
        return;
    }
    fit_range(q, arc, tangents, lo, m, tol, min_split, out);
    fit_range(q, arc, tangents, m, hi, tol, min_split, out);
}

/// The final check: splines sampled every quarter mean edge and projected
/// onto the surface come within [`MIN_CURVE_SEPARATION`] mean edges of each
/// other on one sheet of the surface (see `TriSurface::same_sheet`) only
/// where they are within [`NETWORK_NEIGHBOURHOOD`] mean edges of each other
/// along the curvenet: next to a shared knot, or where a curve turns around a
/// thin part. Anything else would be curves crossing (or nearly touching)
/// without a shared knot.
fn check_separation(
    surface: &TriSurface,
    pool: &[[f64; 3]],
    splines: &[[u32; 4]],
    labels: &[Source],
) -> Result<(), Failure> {
    let edge = surface.mean_edge;
    let (delta, reach) = (MIN_CURVE_SEPARATION * edge, NETWORK_NEIGHBOURHOOD * edge);
    // Projected samples: (spline, arc length from the spline's start, point, triangle).
    let mut samples: Vec<(u32, f64, DVec3, u32)> = Vec::new();
    let mut lengths = Vec::with_capacity(splines.len());
    for (s, sp) in splines.iter().enumerate() {
        let c: fit::Cubic = sp.map(|i| DVec3::from_array(pool[i as usize]));
        let polygon = c[0].distance(c[1]) + c[1].distance(c[2]) + c[2].distance(c[3]);
        let n = ((polygon / (0.25 * edge)).ceil() as usize).clamp(8, 100_000);
        let mut arc = 0.0;
        let mut last: Option<DVec3> = None;
        for i in 0..=n {
            let q = fit::eval(&c, i as f64 / n as f64);
            if let Some(l) = last {
                arc += l.distance(q);
            }
            last = Some(q);
            let (p, t) = match surface.bvh.closest_point(q.to_array()) {
                Ok(h) => (DVec3::from_array(h.point), h.triangle),
                Err(_) => continue,
            };
            samples.push((s as u32, arc, p, t));
        }
        lengths.push(arc);
    }
    // Knot-to-knot distances along the network, up to `reach`.
    let n_knots = splines.iter().flat_map(|s| [s[0], s[3]]).max().map_or(0, |k| k as usize + 1);
    let mut adjacent: Vec<Vec<(u32, f64)>> = vec![Vec::new(); n_knots];
    for (s, sp) in splines.iter().enumerate() {
        adjacent[sp[0] as usize].push((sp[3], lengths[s]));
        adjacent[sp[3] as usize].push((sp[0], lengths[s]));
    }
    let mut within: Vec<Option<Vec<(u32, f64)>>> = vec![None; n_knots];
    let mut knot_distance = |from: u32, to: u32| -> f64 {
        let reached = within[from as usize].get_or_insert_with(|| {
            // Dijkstra from `from`, stopping at `reach` (few knots are that close).
            let mut done: Vec<(u32, f64)> = Vec::new();
            let mut front: Vec<(u32, f64)> = vec![(from, 0.0)];
            while let Some(i) = (0..front.len()).min_by(|&a, &b| front[a].1.total_cmp(&front[b].1)) {
                let (k, d) = front.swap_remove(i);
                if done.iter().any(|x| x.0 == k) {
                    continue;
                }
                done.push((k, d));
                for &(m, len) in &adjacent[k as usize] {
                    if d + len <= reach && !done.iter().any(|x| x.0 == m) {
                        front.push((m, d + len));
                    }
                }
            }
            done
        });
        reached.iter().find(|x| x.0 == to).map_or(f64::INFINITY, |x| x.1)
    };
    let along =
        |a: &(u32, f64, DVec3, u32), b: &(u32, f64, DVec3, u32), knot_distance: &mut dyn FnMut(u32, u32) -> f64| {
            if a.0 == b.0 {
                return (a.1 - b.1).abs();
            }
            let (sa, sb) = (splines[a.0 as usize], splines[b.0 as usize]);
            let ends_a = [(sa[0], a.1), (sa[3], lengths[a.0 as usize] - a.1)];
            let ends_b = [(sb[0], b.1), (sb[3], lengths[b.0 as usize] - b.1)];
            let mut best = f64::INFINITY;
            for (ka, da) in ends_a {
                for (kb, db) in ends_b {
                    if da + db < reach && da + db < best {
                        best = best.min(da + db + knot_distance(ka, kb));
                    }
                }
            }
            best
        };
    let cell = |p: DVec3| ((p / delta).floor()).as_i64vec3();
    let mut grid: rustc_hash::FxHashMap<glam::I64Vec3, Vec<u32>> = rustc_hash::FxHashMap::default();
    for (i, x) in samples.iter().enumerate() {
        grid.entry(cell(x.2)).or_default().push(i as u32);
    }
    for (i, a) in samples.iter().enumerate() {
        let c = cell(a.2);
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let Some(list) = grid.get(&(c + glam::I64Vec3::new(dx, dy, dz))) else { continue };
                    for &j in list {
                        let b = &samples[j as usize];
                        if (j as usize) <= i || a.2.distance(b.2) >= delta || !surface.same_sheet(a.3, b.3) {
                            continue;
                        }
                        let net = along(a, b, &mut knot_distance);
                        if net > reach {
                            let message = format!(
                                "splines {} ({}) and {} ({}) come within {:.2} mean edges of each other on the surface near {:?}",
                                a.0,
                                labels[a.0 as usize],
                                b.0,
                                labels[b.0 as usize],
                                a.2.distance(b.2) / edge,
                                a.2.to_array()
                            );
                            let mut rings: Vec<usize> = [labels[a.0 as usize], labels[b.0 as usize]]
                                .into_iter()
                                .filter_map(|l| if let Source::Ring(k) = l { Some(k) } else { None })
                                .collect();
                            rings.dedup();
                            return Err(Failure { message, rings });
                        }
                    }
                }
            }
        }
    }
    Ok(())
}
