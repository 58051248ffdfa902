//! What to draft: [`DraftOptions`] with its [`Jitter`], and the range
//! checks `draft` runs on them first.

use glam::DVec3;

use super::error::DraftError;
use super::limits::MAX_OFFSET;

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

pub(super) fn check_options(o: &DraftOptions) -> Result<(), DraftError> {
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
