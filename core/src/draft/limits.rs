//! The numeric rules of a draft, in mean edge lengths (and degrees): a leaf
//! the error messages, the ring placement, the fit and the final check name
//! without importing the draft module back.

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
pub(super) const MAX_CROSSING_COS: f64 = 0.939_692_620_785_908_4;
/// Largest accepted `offset` (fraction of the diagonal).
pub const MAX_OFFSET: f64 = 0.1;
