//! Assembly of a curvenet from placed rings and lines: tracks cut into
//! pieces between knots, pushed, fitted by cubic splines, jittered, checked
//! and reported.

use glam::DVec3;

use super::error::Failure;
use super::fit;
use super::frame::Frame;
use super::limits::{FIT_TOLERANCE, MIN_KNOT_SEPARATION, MIN_SPLIT_LENGTH, NETWORK_NEIGHBOURHOOD, TINY_LOOP};
use super::options::DraftOptions;
use super::report::{Draft, DraftReport, LineReport, RingReport};
use super::rings::Ring;
use super::rng::SplitMix64;
use super::section::{Plane, Polyline, SurfacePoint};
use super::separation::{check_separation, pinched};
use super::surface::TriSurface;
use super::tracks::{Source, Track, push_tracks};

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

/// Builds the curvenet from placed rings and lines: tracks, pushes,
/// fitted splines, jitter, the final check and the report.
#[allow(clippy::too_many_arguments)]
pub(super) fn assemble(
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
