//! Helpers of the cage tests (tests/cage_*.rs, which also declare `mod
//! common`): a coarse enclosing cage built around a mesh, a rigged hand,
//! and small vector checks.
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

use curvenet_core::cage::{CageRevApproximation, CoupledRig, fan_triangles};
use curvenet_core::skinning::{self, Influences, Mat4, Skeleton, Skin, SkinningMethod};
use glam::{DMat3, DVec3};

use crate::common::{MESH_DIR, load_obj};

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

fn smoothstep(x: f64) -> f64 {
    let x = x.clamp(0.0, 1.0);
    x * x * (3.0 - 2.0 * x)
}

fn translate(t: DVec3) -> Mat4 {
    let mut m = skinning::IDENTITY;
    m[12..15].copy_from_slice(&t.to_array());
    m
}

pub fn rotate_about(axis: DVec3, deg: f64, pivot: DVec3) -> Mat4 {
    let r = DMat3::from_axis_angle(axis.normalize(), deg.to_radians());
    let shift = pivot - r * pivot;
    let c = r.to_cols_array();
    [c[0], c[1], c[2], 0.0, c[3], c[4], c[5], 0.0, c[6], c[7], c[8], 0.0, shift.x, shift.y, shift.z, 1.0]
}

/// A hand with its cage (icosphere `levels`, or a reference rig's cage and
/// joints: the same rig on another resolution) and a wrist → palm → fingers
/// chain along its height; joints inside the hand near each blend band, weights blending over
/// 20% and 15% of the height.
pub struct HandRig {
    pub points: Vec<[f64; 3]>,
    pub triangles: Vec<[u32; 3]>,
    pub cage: Vec<[f64; 3]>,
    pub cage_triangles: Vec<[u32; 3]>,
    pub skeleton: Skeleton,
    pub influences: Influences,
    pub joints: Vec<DVec3>,
}

pub fn hand_rig(name: &str, reference: Option<&HandRig>, levels: usize) -> HandRig {
    let (mesh, points) = load_obj(&format!("{MESH_DIR}/{name}"));
    let triangles = fan_triangles(&mesh);
    let (cage, cage_triangles) = match reference {
        Some(r) => (r.cage.clone(), r.cage_triangles.clone()),
        None => enclosing_cage(&points, levels),
    };
    let (lo, hi) = bbox(reference.map_or(&points[..], |r| &r.points[..]));
    let t = |p: &[f64; 3]| (p[1] - lo.y) / (hi.y - lo.y);
    let mut idx = Vec::new();
    let mut w = Vec::new();
    for p in &points {
        let a = smoothstep((t(p) - 0.25) / 0.2);
        let b = smoothstep((t(p) - 0.55) / 0.15);
        idx.extend([0, 1, 2]);
        w.extend([1.0 - a, a - b, b]);
    }
    let influences = Influences::new(points.len(), 3, &idx, &w, 3).unwrap();
    let joint_at = |h: f64| {
        let near: Vec<DVec3> =
            points.iter().filter(|p| (t(p) - h).abs() < 0.02).map(|p| DVec3::from_array(*p)).collect();
        near.iter().sum::<DVec3>() / near.len() as f64
    };
    let joints = match reference {
        Some(r) => r.joints.clone(),
        None => vec![joint_at(0.05), joint_at(0.35), joint_at(0.55)],
    };
    let binds: Vec<Mat4> = joints.iter().map(|j| translate(*j)).collect();
    let skeleton = Skeleton::new(&[None, Some(0), Some(1)], &binds).unwrap();
    HandRig { points, triangles, cage, cage_triangles, skeleton, influences, joints }
}

impl HandRig {
    pub fn rig(&self, method: SkinningMethod, approx: CageRevApproximation) -> (CoupledRig, Skin) {
        let skin = Skin::new(self.influences.clone(), skinning::IDENTITY, method).unwrap();
        let rig = CoupledRig::new(
            &self.cage,
            &self.cage_triangles,
            &self.points,
            &self.triangles,
            Some((&self.skeleton, &skin)),
            approx,
        )
        .unwrap();
        (rig, skin)
    }

    /// A consistent chain pose: the palm bends 40° about z at joint 1, the
    /// fingers a further 30° about x at joint 2.
    pub fn pose(&self, scale: f64) -> Vec<Mat4> {
        let t1 = rotate_about(DVec3::Z, 40.0 * scale, self.joints[1]);
        let t2 = skinning::mul(&rotate_about(DVec3::X, 30.0 * scale, self.joints[2]), &t1);
        vec![skinning::IDENTITY, t1, t2]
    }

    /// A rest-cage edit: an anisotropic stretch about an off-centre point
    /// and a bump pushing the cage vertices on one side outward.
    pub fn edit(&self) -> Vec<[f64; 3]> {
        let (lo, hi) = bbox(&self.cage);
        let c = (lo + hi) / 2.0 + DVec3::new(0.1, -0.05, 0.0) * (hi - lo);
        let size = (hi - lo).length();
        self.cage
            .iter()
            .map(|p| {
                let q = DVec3::from_array(*p);
                let mut r = c + (q - c) * DVec3::new(1.25, 1.1, 0.9);
                let side = (q - (lo + hi) / 2.0).normalize();
                if side.x > 0.5 {
                    r += side * 0.05 * size * (side.x - 0.5);
                }
                r.to_array()
            })
            .collect()
    }
}
