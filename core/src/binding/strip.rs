//! The fallback surface path between two points: the shortest path inside a
//! strip of faces, which exists whenever the two points lie on one connected
//! component, so it cannot fail there.
//!
//! 1. **Strip.** An A* search over the faces (adjacent through interior
//!    edges, costed by the distance between face centroids, guided by the
//!    straight-line distance to the target) finds a chain of faces
//!    `F_0 … F_k` from a face holding the start to a face holding the
//!    target. The chain is trimmed so the start lies in no face after `F_0`
//!    and the target in no face before `F_k`.
//! 2. **Unfolding.** Every face already has its own plane (`Surface`);
//!    `F_0` is placed as it is, and each next face by the similarity of the
//!    plane that lays its copy of the shared edge onto the previous face's.
//!    For planar faces this is the usual isometric unfolding; a non-planar
//!    face's projected edge can be slightly shorter or longer than its
//!    neighbour's, and the similarity absorbs that, so both faces agree on
//!    the point at every edge parameter (a crossing is an edge parameter).
//! 3. **Funnel.** The shortest path through the sequence of shared edges
//!    ("portals") in the unfolded plane is the funnel algorithm's (Lee and
//!    Preparata 1984), in its usual single-pass form: a funnel from the
//!    current apex bounded by the last left and right portal endpoints is
//!    narrowed portal by portal; when one side crosses the other, that
//!    side's endpoint — a mesh vertex — becomes the next apex.
//! 4. **Path.** Between consecutive apices the path crosses every portal
//!    once, at an edge parameter; an apex is a mesh vertex the path passes
//!    through. Each piece of the path lies in the face between two
//!    portals, as [`super::path::Path`] requires.
//!
//! The result is a geodesic within the strip (exact on planar faces), not
//! necessarily the global geodesic: the strip comes from centroid
//! distances, and the funnel straightens the path only inside it.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use glam::{DVec2, DVec3};
use rustc_hash::FxHashMap as HashMap;

use super::locate::Location;
use super::path::{Path, TraceFailure};
use super::surface::Surface;
use crate::halfedge::INVALID;

/// A face on the A* frontier.
#[derive(Clone, Copy, PartialEq)]
struct Open {
    estimate: f64,
    cost: f64,
    face: u32,
}

impl Eq for Open {}

impl Ord for Open {
    fn cmp(&self, other: &Self) -> Ordering {
        // Smallest estimate first (BinaryHeap is a max-heap); ties by face for determinism.
        other.estimate.total_cmp(&self.estimate).then_with(|| other.face.cmp(&self.face))
    }
}

impl PartialOrd for Open {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

/// How a face was reached: its cost so far, the previous face and the
/// halfedge of the previous face crossed to get here (`INVALID` for a start face).
#[derive(Clone, Copy)]
struct Reached {
    cost: f64,
    from_face: u32,
    via: u32,
}

/// A funnel corner: a position in the unfolded plane and the mesh vertex it
/// is (`INVALID` for the start and the target, which are not vertices).
#[derive(Clone, Copy, Debug)]
struct Corner {
    p: DVec2,
    vertex: u32,
}

impl Corner {
    fn same(&self, other: &Corner) -> bool {
        if self.vertex != INVALID || other.vertex != INVALID { self.vertex == other.vertex } else { self.p == other.p }
    }
}

/// 2D cross product: positive when `b` is counter-clockwise (to the left) of `a`.
fn cross(a: DVec2, b: DVec2) -> f64 {
    a.perp_dot(b)
}

/// Complex multiplication of 2D vectors (a similarity's rotation and scale).
fn cmul(a: DVec2, b: DVec2) -> DVec2 {
    DVec2::new(a.x * b.x - a.y * b.y, a.x * b.y + a.y * b.x)
}

/// Complex division `a / b`.
fn cdiv(a: DVec2, b: DVec2) -> DVec2 {
    let d = b.length_squared();
    DVec2::new(a.x * b.x + a.y * b.y, a.y * b.x - a.x * b.y) / d
}

/// The centroid of face `f` (mean of its corners).
fn face_centroid(surface: &Surface, f: u32) -> DVec3 {
    let hs = surface.halfedges.face_halfedges(f);
    let n = hs.len() as f64;
    hs.map(|h| surface.points[surface.halfedges.tail(h) as usize]).sum::<DVec3>() / n
}

/// The chain of faces from a face holding `a` to one holding `b`, with
/// the halfedge of each face crossed into the next (`portals[i]` is in
/// `faces[i]`, its twin in `faces[i + 1]`). `None` when no chain exists
/// (the two points are on different components).
fn face_strip(surface: &Surface, a: Location, b: Location) -> Option<(Vec<u32>, Vec<u32>)> {
    let he = &surface.halfedges;
    let (mut fa, mut fb) = (Vec::new(), Vec::new());
    surface.faces_of(a, &mut fa);
    surface.faces_of(b, &mut fb);
    let (pa, pb) = (surface.position(a), surface.position(b));
    if fa.is_empty() || fb.is_empty() || surface.components.of_face(fa[0]) != surface.components.of_face(fb[0]) {
        return None;
    }
    let mut reached: HashMap<u32, Reached> = HashMap::default();
    let mut heap = BinaryHeap::new();
    for &f in &fa {
        let cost = (face_centroid(surface, f) - pa).length();
        reached.insert(f, Reached { cost, from_face: INVALID, via: INVALID });
        heap.push(Open { estimate: cost + (face_centroid(surface, f) - pb).length(), cost, face: f });
    }
    let goal = loop {
        let Open { cost, face, .. } = heap.pop()?;
        if reached.get(&face).is_some_and(|r| r.cost < cost) {
            continue; // a stale entry
        }
        if fb.contains(&face) {
            break face;
        }
        let c = face_centroid(surface, face);
        for h in he.face_halfedges(face) {
            let t = he.twin(h);
            if t == INVALID {
                continue;
            }
            let g = he.face(t);
            let cg = face_centroid(surface, g);
            let next = cost + (cg - c).length();
            if reached.get(&g).is_none_or(|r| next < r.cost) {
                reached.insert(g, Reached { cost: next, from_face: face, via: h });
                heap.push(Open { estimate: next + (cg - pb).length(), cost: next, face: g });
            }
        }
    };
    let mut faces = vec![goal];
    let mut portals = Vec::new();
    let mut f = goal;
    while let Some(r) = reached.get(&f).filter(|r| r.from_face != INVALID) {
        portals.push(r.via);
        faces.push(r.from_face);
        f = r.from_face;
    }
    faces.reverse();
    portals.reverse();
    // Trim: start at the last face holding `a`, end at the first holding `b`.
    let first = faces.iter().rposition(|f| fa.contains(f)).unwrap_or(0);
    let last = first + faces[first..].iter().position(|f| fb.contains(f)).unwrap_or(faces.len() - 1 - first);
    Some((faces[first..=last].to_vec(), portals[first..last].to_vec()))
}

/// The shortest path from `a` to `b` inside a strip of faces (see the
/// module documentation). Crossings within `tol` of a vertex snap to it.
/// Fails only when `a` and `b` lie on different connected components.
pub fn trace_in_strip(
    surface: &Surface,
    a: Location,
    b: Location,
    tol: f64,
    out: &mut Path,
) -> Result<(), TraceFailure> {
    out.points.clear();
    out.faces.clear();
    let (faces, portals) = face_strip(surface, a, b).ok_or(TraceFailure::Disconnected)?;
    let he = &surface.halfedges;
    let c = &surface.corners_2d;
    // Unfold: face i's plane maps into the common plane by z -> offset + scale * z.
    let mut sim = vec![(DVec2::new(1.0, 0.0), DVec2::ZERO)];
    // Funnel portals (left, right) seen walking from a to b; the first and last are a and b.
    let pa = surface.position_2d(faces[0], a);
    let mut funnel = vec![(Corner { p: pa, vertex: INVALID }, Corner { p: pa, vertex: INVALID })];
    for (i, &h) in portals.iter().enumerate() {
        let (scale, offset) = sim[i];
        let map = |z: DVec2| offset + cmul(scale, z);
        let (tail, head) = (map(c[h as usize]), map(c[he.next(h) as usize]));
        // Leaving a face through its counter-clockwise halfedge h, the head is on the left.
        funnel.push((Corner { p: head, vertex: he.head(h) }, Corner { p: tail, vertex: he.tail(h) }));
        let t = he.twin(h);
        let (zt, zn) = (c[t as usize], c[he.next(t) as usize]); // head(h), tail(h) in the next face
        let s = cdiv(head - tail, zt - zn);
        sim.push((s, tail - cmul(s, zn)));
    }
    let (scale, offset) = sim[faces.len() - 1];
    let pb = offset + cmul(scale, surface.position_2d(faces[faces.len() - 1], b));
    funnel.push((Corner { p: pb, vertex: INVALID }, Corner { p: pb, vertex: INVALID }));
    let apices = string_pull(&funnel);

    // Walk the portals between consecutive apices; a crossing leaves into
    // the face after its portal, an apex vertex into the last face of the
    // run of portals that share it.
    let leave_face_of_vertex = |v: u32, from: usize| -> u32 {
        let mut q = from;
        while q < portals.len() && (he.tail(portals[q]) == v || he.head(portals[q]) == v) {
            q += 1;
        }
        faces[q]
    };
    push_point(out, a, faces[0]);
    for w in apices.windows(2) {
        let ((p0, i0), (p1, i1)) = (w[0], w[1]);
        for m in i0.max(1)..i1 {
            // Funnel portal m is strip portal m - 1, between faces m - 1 and m.
            let h = portals[m - 1];
            let (l, r) = funnel[m];
            if l.same(&p0) || r.same(&p0) || l.same(&p1) || r.same(&p1) {
                continue; // the path passes this portal at an apex vertex
            }
            let e = l.p - r.p;
            let den = cross(p1.p - p0.p, e);
            let u = if den.abs() > 0.0 { (cross(p1.p - p0.p, p0.p - r.p) / den).clamp(0.0, 1.0) } else { 0.5 };
            let len = (surface.points[he.head(h) as usize] - surface.points[he.tail(h) as usize]).length();
            let x = if u * len <= tol {
                Location::Vertex(he.tail(h))
            } else if (1.0 - u) * len <= tol {
                Location::Vertex(he.head(h))
            } else {
                surface.edge_location(h, u)
            };
            let leave = match x {
                Location::Vertex(v) => leave_face_of_vertex(v, m - 1),
                _ => faces[m],
            };
            push_point(out, x, leave);
        }
        if i1 + 1 < funnel.len() {
            // An intermediate apex: a mesh vertex at funnel portal i1.
            push_point(out, Location::Vertex(p1.vertex), leave_face_of_vertex(p1.vertex, i1 - 1));
        }
    }
    match (out.points.last(), b) {
        (Some(&Location::Vertex(p)), Location::Vertex(v)) if p == v => {
            out.faces.pop(); // the last crossing snapped onto b
        }
        _ => out.points.push(b),
    }
    if out.points.len() < 2 {
        return Err(TraceFailure::Lost);
    }
    Ok(())
}

/// Appends a path point and the face the path leaves it into; a vertex
/// repeated (a crossing snapped onto the previous apex) only updates that face.
fn push_point(out: &mut Path, x: Location, leave: u32) {
    if let (Some(&Location::Vertex(p)), Location::Vertex(v)) = (out.points.last(), x)
        && p == v
    {
        if let Some(f) = out.faces.last_mut() {
            *f = leave;
        }
        return;
    }
    out.points.push(x);
    out.faces.push(leave);
}

/// The funnel algorithm over `portals` (left, right): the apices of the
/// shortest path, each with the index of the portal where it lies (0 for
/// the start, the last index for the target).
fn string_pull(portals: &[(Corner, Corner)]) -> Vec<(Corner, usize)> {
    let n = portals.len();
    let mut path = vec![(portals[0].0, 0usize)];
    let mut apex = portals[0].0;
    let (mut left, mut right) = (portals[0].0, portals[0].1);
    let (mut left_i, mut right_i) = (0usize, 0usize);
    let mut i = 1;
    while i < n {
        let (l, r) = portals[i];
        // Narrow the right side: r at or left of the right edge.
        if apex.same(&right) || cross(right.p - apex.p, r.p - apex.p) >= 0.0 {
            if apex.same(&right) || cross(left.p - apex.p, r.p - apex.p) <= 0.0 || apex.same(&left) {
                right = r;
                right_i = i;
            } else {
                // The right side crossed the left: the left corner is the next apex.
                apex = left;
                path.push((apex, left_i));
                (right, right_i) = (apex, left_i);
                i = left_i + 1;
                continue;
            }
        }
        // Narrow the left side: l at or right of the left edge.
        if apex.same(&left) || cross(left.p - apex.p, l.p - apex.p) <= 0.0 {
            if apex.same(&left) || cross(right.p - apex.p, l.p - apex.p) >= 0.0 || apex.same(&right) {
                left = l;
                left_i = i;
            } else {
                apex = right;
                path.push((apex, right_i));
                (left, left_i) = (apex, right_i);
                i = right_i + 1;
                continue;
            }
        }
        i += 1;
    }
    let last = portals[n - 1].0;
    if !path.last().is_some_and(|(p, _)| p.same(&last)) {
        path.push((last, n - 1));
    }
    path
}
