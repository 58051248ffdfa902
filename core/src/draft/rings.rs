//! Ring placement: each ring plane at its first clean position, with its
//! kept loops and its crossings with the line sections (the ring-local
//! rules of the module docs).

use glam::DVec3;

use super::frame::{Frame, Plan};
use super::limits::{MAX_CROSSING_COS, MIN_CROSSING_DEGREES, MIN_KNOT_SEPARATION, NETWORK_NEIGHBOURHOOD, TINY_LOOP};
use super::section::{Plane, Polyline, SurfacePoint, section};
use super::separation::pinched;
use super::surface::TriSurface;

/// A ring × line crossing: where it sits in both sections.
#[derive(Debug, Clone, Copy)]
pub(super) struct Crossing {
    /// Index into the ring's kept loops, segment, parameter on the segment.
    pub(super) ring_loop: usize,
    pub(super) ring_seg: usize,
    pub(super) ring_u: f64,
    pub(super) line: usize,
    pub(super) line_poly: usize,
    pub(super) line_seg: usize,
    pub(super) line_u: f64,
    pub(super) point: SurfacePoint,
    pub(super) tri: u32,
}

/// A placed ring plane with its kept loops and its crossings.
pub(super) struct Ring {
    pub(super) plane: Plane,
    pub(super) position: f64,
    pub(super) point: DVec3,
    pub(super) loops: Vec<Polyline>,
    pub(super) crossings: Vec<Crossing>,
}

/// Ring positions tried, in sixteenths of the ring spacing from the nominal one.
const RING_STEPS: [f64; 13] = [0.0, 1.0, -1.0, 2.0, -2.0, 3.0, -3.0, 4.0, -4.0, 5.0, -5.0, 6.0, -6.0];

/// Places every ring plane in turn at its first clean candidate from
/// `first[k]` on (see the module docs): the positions of [`RING_STEPS`]
/// with the ring's normal, then (for a tilted ring) the same positions
/// untilted. Says why a ring could not be placed, or returns the rings and
/// the candidate each took.
pub(super) fn place_rings(
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
