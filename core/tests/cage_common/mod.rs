//! Helpers of the cage tests (tests/cage_*.rs): a coarse enclosing cage
//! built around a mesh, and small vector checks.
//!
//! The cage is an icosphere (an icosahedron subdivided `levels` times,
//! vertices on the unit sphere) fitted star-shaped around the mesh: in the
//! space where the mesh's bounding box is the cube [-1, 1]³, the vertex in
//! direction `d` is put at `d·(1.15·r(d) + 0.08)` from the box's centre,
//! `r(d)` the distance of the farthest mesh point within 25° of `d` — a
//! coarse inflated hull of the mesh (a real cage hugs its mesh: a cage far
//! from it makes `Φ` numerically low-rank and the MaxVol system badly
//! conditioned). Enclosure is then checked, not assumed: every mesh point
//! must have winding number above 1/2 with respect to the cage, else the
//! cage is inflated by 10% and checked again. Outward counter-clockwise
//! triangles.
#![allow(dead_code)]

use std::collections::HashMap;

use glam::DVec3;

/// A unit icosphere: vertices and counter-clockwise (outward) triangles.
pub fn icosphere(levels: usize) -> (Vec<DVec3>, Vec<[u32; 3]>) {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let mut v: Vec<DVec3> = [
        [-1.0, t, 0.0],
        [1.0, t, 0.0],
        [-1.0, -t, 0.0],
        [1.0, -t, 0.0],
        [0.0, -1.0, t],
        [0.0, 1.0, t],
        [0.0, -1.0, -t],
        [0.0, 1.0, -t],
        [t, 0.0, -1.0],
        [t, 0.0, 1.0],
        [-t, 0.0, -1.0],
        [-t, 0.0, 1.0],
    ]
    .iter()
    .map(|p| DVec3::from_array(*p).normalize())
    .collect();
    let mut f: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..levels {
        let mut mid: HashMap<(u32, u32), u32> = HashMap::new();
        let mut next = Vec::new();
        for t in &f {
            let mut m = [0u32; 3];
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                let key = (a.min(b), a.max(b));
                m[k] = *mid.entry(key).or_insert_with(|| {
                    v.push(((v[a as usize] + v[b as usize]) / 2.0).normalize());
                    (v.len() - 1) as u32
                });
            }
            next.push([t[0], m[0], m[2]]);
            next.push([t[1], m[1], m[0]]);
            next.push([t[2], m[2], m[1]]);
            next.push([m[0], m[1], m[2]]);
        }
        f = next;
    }
    (v, f)
}

/// The enclosing cage of `points` (see the module docs).
pub fn enclosing_cage(points: &[[f64; 3]], levels: usize) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let (lo, hi) = bbox(points);
    let c = (lo + hi) / 2.0;
    let half = ((hi - lo) / 2.0).max(DVec3::splat(1e-9));
    let (dirs, f) = icosphere(levels);
    // Star-shaped fit in the box-normalised space: each direction's radius
    // is the farthest point within 25° of it.
    let u: Vec<DVec3> = points.iter().map(|p| (DVec3::from_array(*p) - c) / half).collect();
    let cos = 25f64.to_radians().cos();
    let radius: Vec<f64> = dirs
        .iter()
        .map(|d| {
            let r = u
                .iter()
                .filter(|x| x.length() > 0.0 && x.normalize().dot(*d) >= cos)
                .map(|x| x.length())
                .fold(0.0, f64::max);
            if r > 0.0 { r } else { u.iter().map(|x| x.dot(*d)).fold(0.0, f64::max) }
        })
        .collect();
    let mut inflate = 1.15;
    loop {
        let cage: Vec<[f64; 3]> =
            dirs.iter().zip(&radius).map(|(d, r)| (c + half * (*d * (r * inflate + 0.08))).to_array()).collect();
        if points.iter().all(|p| winding_number(&cage, &f, DVec3::from_array(*p)) > 0.5) {
            return (cage, f);
        }
        inflate *= 1.1;
        assert!(inflate < 10.0, "no enclosing cage");
    }
}

/// The generalized winding number of `q` with respect to a closed triangle
/// mesh (van Oosterom and Strackee's solid angles): 1 inside, 0 outside.
pub fn winding_number(points: &[[f64; 3]], triangles: &[[u32; 3]], q: DVec3) -> f64 {
    let mut omega = 0.0;
    for t in triangles {
        let [a, b, c] = t.map(|i| DVec3::from_array(points[i as usize]) - q);
        let (la, lb, lc) = (a.length(), b.length(), c.length());
        let num = a.dot(b.cross(c));
        let den = la * lb * lc + a.dot(b) * lc + b.dot(c) * la + c.dot(a) * lb;
        omega += 2.0 * num.atan2(den);
    }
    omega / (4.0 * std::f64::consts::PI)
}

pub fn bbox(points: &[[f64; 3]]) -> (DVec3, DVec3) {
    points.iter().fold((DVec3::splat(f64::MAX), DVec3::splat(f64::MIN)), |(lo, hi), p| {
        let p = DVec3::from_array(*p);
        (lo.min(p), hi.max(p))
    })
}

pub fn diagonal(points: &[[f64; 3]]) -> f64 {
    let (lo, hi) = bbox(points);
    (hi - lo).length()
}

pub fn max_dist(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    a.iter().zip(b).map(|(p, q)| DVec3::from_array(*p).distance(DVec3::from_array(*q))).fold(0.0, f64::max)
}
