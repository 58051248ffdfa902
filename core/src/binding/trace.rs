//! Inserting one curvenet segment into the surface: the path between the
//! projected positions of its two samples.
//!
//! When the two points share a face, the path is the straight chord in that
//! face's plane (the first three columns of the paper's Fig. 6). Otherwise it
//! is traced as a straightest path (Polthier and Schmies 1998): start in the
//! face around the first point that contains the direction to the second,
//! walk straight across the face in its plane, and at every edge crossing
//! unfold the direction into the next face keeping its angle with the edge,
//! until a face containing the second point is reached; the last piece is the
//! chord to it. The crossings become cut-vertices on mesh edges (Fig. 6,
//! right). A path that runs into a mesh vertex restarts there towards the
//! target (the straightest direction through a vertex is not unique; aiming
//! at the target is the choice that keeps short segments short).

use glam::{DVec2, DVec3};

use super::locate::Location;
use super::strip::trace_in_strip;
use super::surface::Surface;
use crate::halfedge::INVALID;

pub use super::path::{Path, PathMethod, TraceFailure};

fn perp(e: DVec2) -> DVec2 {
    DVec2::new(-e.y, e.x)
}

/// Counter-clockwise angle from `a` to `b` in [0, 2π).
fn ccw_angle(a: DVec2, b: DVec2) -> f64 {
    let t = a.perp_dot(b).atan2(a.dot(b));
    if t < 0.0 { t + std::f64::consts::TAU } else { t }
}

/// How far inside face `f` the direction `d` from `loc` points (positive:
/// into the face), for choosing the face a path leaves `loc` through.
fn entry_margin(surface: &Surface, f: u32, loc: Location, d: DVec2) -> f64 {
    let he = &surface.halfedges;
    let c = &surface.corners_2d;
    match loc {
        Location::Face { .. } => 1.0,
        Location::Edge { h, .. } => {
            let hf = if he.face(h) == f { h } else { he.twin(h) };
            let e = (c[he.next(hf) as usize] - c[hf as usize]).normalize();
            e.perp_dot(d.normalize())
        }
        Location::Vertex(v) => {
            let Some(h) = surface.corner_of(f, v) else { return f64::NEG_INFINITY };
            let e_out = c[he.next(h) as usize] - c[h as usize];
            let e_in = c[he.prev(h) as usize] - c[h as usize];
            let wedge = ccw_angle(e_out, e_in);
            let a = ccw_angle(e_out, d);
            if a <= wedge { a.min(wedge - a) } else { -(a - wedge).min(std::f64::consts::TAU - a) }
        }
    }
}

/// The face to leave `loc` through towards the 3D point `target`, with the
/// direction in that face's plane; `skip` is excluded.
fn leave(
    surface: &Surface,
    loc: Location,
    target: DVec3,
    skip: Option<u32>,
    faces: &mut Vec<u32>,
) -> Option<(u32, DVec2)> {
    surface.faces_of(loc, faces);
    let mut best: Option<(f64, u32, DVec2)> = None;
    for &f in faces.iter() {
        if Some(f) == skip {
            continue;
        }
        let d = surface.planes[f as usize].to_2d(target) - surface.position_2d(f, loc);
        if d.length_squared() == 0.0 {
            continue;
        }
        let m = entry_margin(surface, f, loc, d);
        if best.is_none_or(|b| m > b.0) {
            best = Some((m, f, d));
        }
    }
    best.map(|(_, f, d)| (f, d.normalize()))
}

/// A surface path from `a` to `b` that ends exactly at `b`: the chord
/// when they share a face, else the straightest path from `a` (or, when
/// that misses, from `b`, reversed), else the shortest path in a strip
/// of faces. Fails only with [`TraceFailure::Disconnected`]. `tol`
/// snaps crossings to vertices.
pub fn trace(
    surface: &Surface,
    a: Location,
    b: Location,
    tol: f64,
    out: &mut Path,
) -> Result<PathMethod, TraceFailure> {
    let mut fa = Vec::new();
    let mut fb = Vec::new();
    surface.faces_of(a, &mut fa);
    surface.faces_of(b, &mut fb);
    if let Some(&f) = fa.iter().find(|f| fb.contains(f)) {
        out.points.clear();
        out.faces.clear();
        out.points.extend([a, b]);
        out.faces.push(f);
        return Ok(PathMethod::Chord);
    }
    if trace_straightest(surface, a, b, tol, out).is_ok() {
        return Ok(PathMethod::Straightest);
    }
    if trace_straightest(surface, b, a, tol, out).is_ok() {
        out.points.reverse();
        out.faces.reverse();
        return Ok(PathMethod::Straightest);
    }
    trace_in_strip(surface, a, b, tol, out)?;
    Ok(PathMethod::Fallback)
}

/// The straightest path from `a` to `b` (see the module documentation),
/// within a length budget of four times their distance plus four mean
/// edges. `tol` snaps crossings to vertices.
pub fn trace_straightest(
    surface: &Surface,
    a: Location,
    b: Location,
    tol: f64,
    out: &mut Path,
) -> Result<(), TraceFailure> {
    out.points.clear();
    out.faces.clear();
    out.points.push(a);
    let mut fa = Vec::new();
    let mut fb = Vec::new();
    surface.faces_of(a, &mut fa);
    surface.faces_of(b, &mut fb);
    if let Some(&f) = fa.iter().find(|f| fb.contains(f)) {
        out.points.push(b);
        out.faces.push(f);
        return Ok(());
    }
    let he = &surface.halfedges;
    let c = &surface.corners_2d;
    let target = surface.position(b);
    let budget = 4.0 * (surface.position(a) - target).length() + 4.0 * surface.mean_edge_length;
    let mut walked = 0.0;
    let (mut face, mut dir) = leave(surface, a, target, None, &mut fa).ok_or(TraceFailure::Lost)?;
    let mut here = a;
    // Edges the ray starts on (not to be "hit" at distance zero).
    let mut skip_edges: [u32; 2] = start_edges(surface, face, a);
    for _ in 0..10_000 {
        if fb.contains(&face) {
            out.points.push(b);
            out.faces.push(face);
            return Ok(());
        }
        let p = surface.position_2d(face, here);
        let mut best: Option<(f64, u32, f64)> = None;
        for h in he.face_halfedges(face) {
            if skip_edges.contains(&h) {
                continue;
            }
            let (q0, q1) = (c[h as usize], c[he.next(h) as usize]);
            let e = q1 - q0;
            let den = dir.perp_dot(e);
            if den.abs() < 1e-300 {
                continue;
            }
            let s = (q0 - p).perp_dot(e) / den;
            let u = (q0 - p).perp_dot(dir) / den;
            if s > 0.0 && (-1e-9..=1.0 + 1e-9).contains(&u) && best.is_none_or(|b| s < b.0) {
                best = Some((s, h, u.clamp(0.0, 1.0)));
            }
        }
        let (s, h, u) = best.ok_or(TraceFailure::Lost)?;
        walked += s;
        if walked > budget {
            return Err(TraceFailure::Lost);
        }
        let len = (c[he.next(h) as usize] - c[h as usize]).length();
        let x = if u * len <= tol {
            Location::Vertex(he.tail(h))
        } else if (1.0 - u) * len <= tol {
            Location::Vertex(he.head(h))
        } else {
            surface.edge_location(h, u)
        };
        out.points.push(x);
        out.faces.push(face);
        match x {
            Location::Vertex(_) => {
                let (f, d) = leave(surface, x, target, Some(face), &mut fa).ok_or(TraceFailure::Lost)?;
                face = f;
                dir = d;
                skip_edges = start_edges(surface, face, x);
            }
            _ => {
                let t = he.twin(h);
                if t == INVALID {
                    return Err(TraceFailure::LeftTheSurface);
                }
                let e_f = (c[he.next(h) as usize] - c[h as usize]).normalize();
                let (alpha, beta) = (dir.dot(e_f), dir.dot(perp(e_f)));
                let g = he.face(t);
                let e_g = (c[he.next(t) as usize] - c[t as usize]).normalize();
                dir = (-alpha * e_g - beta * perp(e_g)).normalize();
                face = g;
                skip_edges = [t, t];
            }
        }
        here = x;
    }
    Err(TraceFailure::Lost)
}

/// The halfedges of face `f` that a ray starting at `loc` lies on.
fn start_edges(surface: &Surface, f: u32, loc: Location) -> [u32; 2] {
    let he = &surface.halfedges;
    match loc {
        Location::Vertex(v) => match surface.corner_of(f, v) {
            Some(h) => [h, he.prev(h)],
            None => [INVALID; 2],
        },
        Location::Edge { h, .. } => {
            let hf = if he.face(h) == f { h } else { he.twin(h) };
            [hf, hf]
        }
        Location::Face { .. } => [INVALID; 2],
    }
}
