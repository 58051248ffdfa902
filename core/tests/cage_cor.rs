//! Skinning with optimised centres of rotation (Le and Hodgins 2016, Corda
//! et al. 2020 Eq. 5-6) against linear blending and dual quaternions at a
//! 90° elbow-like bend of a closed cylinder: CoR keeps the volume LBS loses
//! and does not bulge as DQS does (numbers printed); identity and rigid
//! transforms are reproduced; the method's tokens.

use curvenet_core::Error;
use curvenet_core::cage::{CentersOfRotation, skin_points_cor};
use curvenet_core::skinning::{self, Influences, Mat4, Skin, SkinningMethod};
use glam::{DMat3, DVec3};

const RADIUS: f64 = 0.15;

/// A closed cylinder along y from 0 to 2 (rings of `seg` vertices, a centre
/// vertex on each cap), outward counter-clockwise triangles.
fn cylinder(rings: usize, seg: usize) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let mut p = Vec::new();
    for r in 0..rings {
        let y = 2.0 * r as f64 / (rings - 1) as f64;
        for s in 0..seg {
            let a = std::f64::consts::TAU * s as f64 / seg as f64;
            p.push([RADIUS * a.cos(), y, RADIUS * a.sin()]);
        }
    }
    let (bottom, top) = (p.len() as u32, p.len() as u32 + 1);
    p.push([0.0, 0.0, 0.0]);
    p.push([0.0, 2.0, 0.0]);
    let mut t = Vec::new();
    let id = |r: usize, s: usize| (r * seg + s % seg) as u32;
    for r in 0..rings - 1 {
        for s in 0..seg {
            // Outward: (x, z) angle grows from x to z, y up.
            t.push([id(r, s), id(r + 1, s), id(r, s + 1)]);
            t.push([id(r, s + 1), id(r + 1, s), id(r + 1, s + 1)]);
        }
    }
    for s in 0..seg {
        t.push([bottom, id(0, s), id(0, s + 1)]);
        t.push([top, id(rings - 1, s + 1), id(rings - 1, s)]);
    }
    (p, t)
}

fn volume(p: &[[f64; 3]], t: &[[u32; 3]]) -> f64 {
    t.iter()
        .map(|f| {
            let v = f.map(|i| DVec3::from_array(p[i as usize]));
            v[0].dot(v[1].cross(v[2])) / 6.0
        })
        .sum()
}

fn smoothstep(x: f64) -> f64 {
    let x = x.clamp(0.0, 1.0);
    x * x * (3.0 - 2.0 * x)
}

fn influences(p: &[[f64; 3]]) -> Influences {
    let mut idx = Vec::new();
    let mut w = Vec::new();
    for q in p {
        let b = smoothstep((q[1] - 0.75) / 0.5);
        idx.extend([0, 1]);
        w.extend([1.0 - b, b]);
    }
    Influences::new(p.len(), 2, &idx, &w, 2).unwrap()
}

fn rotate_about(axis: DVec3, deg: f64, pivot: DVec3) -> Mat4 {
    let r = DMat3::from_axis_angle(axis.normalize(), deg.to_radians());
    let shift = pivot - r * pivot;
    let c = r.to_cols_array();
    [c[0], c[1], c[2], 0.0, c[3], c[4], c[5], 0.0, c[6], c[7], c[8], 0.0, shift.x, shift.y, shift.z, 1.0]
}

/// Distance from `q` to the bent axis: the segment (0,0,0)-(0,1,0) and its
/// continuation rotated by the elbow.
fn axis_distance(q: DVec3, elbow: &Mat4) -> f64 {
    let seg = |a: DVec3, b: DVec3| {
        let t = ((q - a).dot(b - a) / (b - a).length_squared()).clamp(0.0, 1.0);
        (a + (b - a) * t).distance(q)
    };
    let j = DVec3::new(0.0, 1.0, 0.0);
    let end = DVec3::from_array(skinning::transform_point(elbow, [0.0, 2.0, 0.0]));
    seg(DVec3::ZERO, j).min(seg(j, end))
}

#[test]
fn centers_of_rotation_keep_volume_and_do_not_bulge_at_a_90_degree_bend() {
    let (p, t) = cylinder(81, 32);
    let inf = influences(&p);
    let cor = CentersOfRotation::new(&p, &t, &inf).unwrap();
    println!("{} of {} vertices have a centre of their own", cor.n_blended(), p.len());
    // Blending vertices of a straight cylinder: their centre is on the axis,
    // inside the band where the weights blend (they depend on the height only).
    for (i, c) in cor.centers().iter().enumerate() {
        if cor.is_blended(i) {
            let radial = (c[0] * c[0] + c[2] * c[2]).sqrt();
            assert!(radial < 1e-3 * RADIUS, "centre {i} {c:?} off the axis by {radial:e}");
            assert!((0.75..=1.25).contains(&c[1]), "centre {i} at height {} outside the blend band", c[1]);
        }
    }
    let v0 = volume(&p, &t);
    let elbow = rotate_about(DVec3::Z, 90.0, DVec3::new(0.0, 1.0, 0.0));
    let transforms = [skinning::IDENTITY, elbow];
    let mut stats = Vec::new();
    for method in [SkinningMethod::ClassicLinear, SkinningMethod::DualQuaternion, SkinningMethod::CentersOfRotation] {
        let mut skin = Skin::new(inf.clone(), skinning::IDENTITY, method).unwrap();
        if method == SkinningMethod::CentersOfRotation {
            skin = skin.with_centers_of_rotation(cor.centers().to_vec()).unwrap();
        }
        let mut out = vec![[0.0; 3]; p.len()];
        skin.skin_points(&p, &transforms, &mut out).unwrap();
        let vol = volume(&out, &t) / v0 - 1.0;
        // Radial deviation of the ring vertices from the bent axis.
        let (mut bulge, mut pinch) = (0.0f64, 0.0f64);
        for q in &out[..p.len() - 2] {
            let d = axis_distance(DVec3::from_array(*q), &elbow) / RADIUS - 1.0;
            bulge = bulge.max(d);
            pinch = pinch.min(d);
        }
        println!(
            "{:>18}: volume change {:+.3}%, bulge (max distance to the bent axis / r - 1) {:+.3}%, pinch {:+.3}%",
            method.token(),
            vol * 100.0,
            bulge * 100.0,
            pinch * 100.0
        );
        stats.push((vol, bulge));
    }
    let (lbs, dqs, cor) = (stats[0], stats[1], stats[2]);
    assert!(lbs.0 < -0.01, "LBS loses volume at a 90° bend: {}", lbs.0);
    assert!(cor.0.abs() < lbs.0.abs() / 2.0, "CoR keeps volume better than LBS: {} vs {}", cor.0, lbs.0);
    assert!(dqs.1 > 0.01, "DQS bulges at a 90° bend: {}", dqs.1);
    assert!(cor.1 < 0.8 * dqs.1, "CoR bulges less than DQS: {} vs {}", cor.1, dqs.1);
}

#[test]
fn centers_of_rotation_reproduce_identity_and_rigid_transforms() {
    let (p, t) = cylinder(21, 12);
    let inf = influences(&p);
    let cor = CentersOfRotation::new(&p, &t, &inf).unwrap();
    let mut out = vec![[0.0; 3]; p.len()];
    skin_points_cor(&p, cor.centers(), &inf, &skinning::IDENTITY, &[skinning::IDENTITY; 2], &mut out).unwrap();
    for (a, b) in out.iter().zip(&p) {
        for c in 0..3 {
            assert!((a[c] - b[c]).abs() < 1e-14);
        }
    }
    // The same rigid motion on both joints moves everything rigidly.
    let mut m = rotate_about(DVec3::new(1.0, 2.0, 0.3), 50.0, DVec3::new(0.3, 0.1, -1.0));
    m[12] += 0.5;
    skin_points_cor(&p, cor.centers(), &inf, &skinning::IDENTITY, &[m, m], &mut out).unwrap();
    for (a, b) in out.iter().zip(&p) {
        let want = skinning::transform_point(&m, *b);
        for c in 0..3 {
            assert!((a[c] - want[c]).abs() < 1e-13, "{a:?} vs {want:?}");
        }
    }
    // Without centres, the generic entry point refuses the method.
    let err =
        skinning::skin_points(SkinningMethod::CentersOfRotation, &p, &inf, &skinning::IDENTITY, &[m, m], &mut out)
            .unwrap_err();
    assert!(matches!(err, Error::Unsupported { .. }), "{err}");
    // Tokens: UsdSkel's stay as they are; the curvenet attribute adds CoR.
    assert_eq!(SkinningMethod::from_token("centersOfRotation"), None);
    assert_eq!(SkinningMethod::from_curvenet_token("centersOfRotation"), Some(SkinningMethod::CentersOfRotation));
    assert_eq!(SkinningMethod::from_curvenet_token("dualQuaternion"), Some(SkinningMethod::DualQuaternion));
    assert_eq!(SkinningMethod::CentersOfRotation.token(), "centersOfRotation");
    // A triangle index out of range is named.
    let mut bad = t.clone();
    bad[4][1] = 10_000;
    assert!(matches!(
        CentersOfRotation::new(&p, &bad, &inf),
        Err(Error::Cage(curvenet_core::cage::CageError::IndexOutOfRange { face: 4, corner: 1, vertex: 10_000, .. }))
    ));
}
