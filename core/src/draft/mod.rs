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

// One concern per file, in layers: each file imports only from the layers
// before it (`python3 scripts/check-imports`), and none imports this module
// back. limits, report, rng, fit, surface, section (the numeric rules, the
// returned types, the generator, the geometry); error, options; tracks,
// frame; separation; rings; assemble; then `draft` below.
mod assemble;
mod error;
mod fit;
mod frame;
mod limits;
mod options;
mod report;
mod rings;
mod rng;
mod section;
mod separation;
mod surface;
mod tracks;

pub use error::DraftError;
pub use limits::{
    FIT_TOLERANCE, MAX_OFFSET, MIN_CROSSING_DEGREES, MIN_CURVE_SEPARATION, MIN_KNOT_SEPARATION, MIN_SPLIT_LENGTH,
    NETWORK_NEIGHBOURHOOD, TINY_LOOP,
};
pub use options::{DraftOptions, Jitter};
pub use report::{Draft, DraftReport, LineReport, RingReport};
pub use rng::SplitMix64;

use assemble::assemble;
use frame::{Frame, Plan};
use options::check_options;
use rings::place_rings;
use section::{Polyline, section};
use surface::TriSurface;

use crate::mesh::PolyMesh;

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
