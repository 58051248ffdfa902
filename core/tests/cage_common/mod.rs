//! Helpers of the cage tests (tests/cage_*.rs): a coarse enclosing cage
//! built around a mesh, and small vector checks.
//!
//! The cage is an icosphere (an icosahedron subdivided `levels` times,
//! vertices on the unit sphere) mapped onto the axis-aligned ellipsoid
//! centred on the mesh's bounding box with semi-axes `1.1·√3` times the
//! box's half-extents. That ellipsoid contains the box (a corner is at
//! `Σ (h_i / (1.1√3 h_i))² = 0.83` of it); every icosphere face of level
//! 2 or more lies within 2% of the sphere (its flat faces sag by less
//! than `1 − cos(16°)`), so the polyhedral cage encloses the whole mesh.
//! Outward counter-clockwise triangles.
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
    let (v, f) = icosphere(levels);
    let axes = half * 1.1 * 3f64.sqrt();
    (v.iter().map(|d| (c + *d * axes).to_array()).collect(), f)
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
