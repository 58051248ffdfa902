//! Tracks (section polylines with the crossing knots inserted) and how they
//! are pushed off the surface: admissible pushes, eroded and smoothed along
//! each track, agreed at the knots.

use glam::DVec3;

use super::section::{Polyline, SurfacePoint};
use super::surface::TriSurface;

/// What a track is a section of (for messages and the report).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Source {
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
pub(super) struct Track {
    pub(super) source: Source,
    pub(super) closed: bool,
    pub(super) points: Vec<SurfacePoint>,
    pub(super) knot: Vec<Option<u32>>,
    /// Offset (pushed) positions and pushes, filled by `push_tracks`.
    pub(super) offset: Vec<DVec3>,
    pub(super) push: Vec<f64>,
}

impl Track {
    pub(super) fn new(source: Source, poly: &Polyline, mut insert: Vec<(usize, f64, u32, SurfacePoint)>) -> Self {
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

    pub(super) fn len(&self) -> usize {
        self.points.len()
    }

    /// The index after `i` (wrapping on closed tracks), or `None` at the end.
    pub(super) fn next(&self, i: usize) -> Option<usize> {
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
    pub(super) fn tangent(&self, i: usize, w: f64) -> DVec3 {
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
pub(super) fn push_tracks(surface: &TriSurface, tracks: &mut [Track], n_knots: usize, h: f64, window: f64) -> Vec<f64> {
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
