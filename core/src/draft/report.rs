//! What a draft returns: the curvenet's control points and splines
//! ([`Draft`]) and how it was made ([`DraftReport`]).

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
