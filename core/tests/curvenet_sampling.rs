//! Pose-invariant sampling: counts fixed by the neutral pose, even
//! arc-length spacing in every pose.

mod common;

use common::*;
use curvenet_core::{Curvenet, CurvenetLayout, SamplingOptions};

/// Arc-length positions of `samples` along the cubic Bézier `ctrl`, located
/// on an independent dense polyline (the samples lie on the curve).
fn arc_positions(ctrl: [[f64; 3]; 4], samples: &[[f64; 3]]) -> (Vec<f64>, f64) {
    let n = 20_000;
    let eval = |t: f64| -> [f64; 3] {
        let s = 1.0 - t;
        std::array::from_fn(|k| {
            s * s * s * ctrl[0][k]
                + 3.0 * s * s * t * ctrl[1][k]
                + 3.0 * s * t * t * ctrl[2][k]
                + t * t * t * ctrl[3][k]
        })
    };
    let dense: Vec<[f64; 3]> = (0..=n).map(|i| eval(i as f64 / n as f64)).collect();
    let mut cum = vec![0.0];
    for w in dense.windows(2) {
        cum.push(cum.last().unwrap() + norm(sub(w[1], w[0])));
    }
    let mut from = 0;
    let mut out = Vec::new();
    for &q in samples {
        // Closest dense edge at or after the previous sample's.
        let mut best = (f64::INFINITY, 0.0);
        let start = from;
        for i in start..n {
            let (a, b) = (dense[i], dense[i + 1]);
            let d = sub(b, a);
            let t = (dot(sub(q, a), d) / dot(d, d)).clamp(0.0, 1.0);
            let x: [f64; 3] = std::array::from_fn(|k| a[k] + t * d[k]);
            let dist = norm(sub(q, x));
            if dist < best.0 {
                best = (dist, cum[i] + t * (cum[i + 1] - cum[i]));
                from = i;
            }
        }
        out.push(best.1);
    }
    (out, cum[n])
}

/// Worst relative deviation of a spline's sample spacing from even.
fn worst_spacing(layout: &CurvenetLayout, pose: &[[f64; 3]], splines: &[[u32; 4]]) -> f64 {
    let samples = layout.sampling().samples(pose).unwrap();
    let mut worst: f64 = 0.0;
    for (s, sp) in splines.iter().enumerate() {
        let ids: Vec<u32> = layout.sampling().spline_samples(s).collect();
        let qs: Vec<[f64; 3]> = ids.iter().map(|&k| samples[k as usize]).collect();
        let (pos, total) = arc_positions(sp.map(|k| pose[k as usize]), &qs);
        let n = ids.len() - 1;
        for w in pos.windows(2) {
            worst = worst.max(((w[1] - w[0]) / (total / n as f64) - 1.0).abs());
        }
    }
    worst
}

#[test]
fn counts_are_fixed_and_spacing_even_in_every_pose() {
    let (mesh, pts) = plane(3.0, 12);
    let b = grid(0.05);
    let net = Curvenet::new(&b.splines, &b.points).unwrap();
    let layout = CurvenetLayout::new(&net, &mesh, &pts, &SamplingOptions::default()).unwrap();
    let s = layout.sampling();
    // Count = round(5 × control polygon / mean edge), mean edge 0.5 here.
    let mean_edge = mesh.mean_edge_length(&pts);
    assert_eq!(mean_edge, 0.5);
    for (i, sp) in b.splines.iter().enumerate() {
        let p = sp.map(|k| b.points[k as usize]);
        let polygon = norm(sub(p[1], p[0])) + norm(sub(p[2], p[1])) + norm(sub(p[3], p[2]));
        assert_eq!(s.spline_segments(i), ((5.0 * polygon / mean_edge).round() as u32).max(1));
    }
    let neutral = worst_spacing(&layout, &b.points, &b.splines);
    assert!(neutral < 0.01, "neutral spacing off by {neutral}");

    // Poses: stretched ×3 along x, handles thrown far (strong bends, loops).
    let stretched: Vec<[f64; 3]> = b.points.iter().map(|p| [3.0 * p[0], p[1], p[2]]).collect();
    let mut wild = b.points.clone();
    for (i, sp) in b.splines.iter().enumerate() {
        let a = (i as f64 * 1.3).sin();
        wild[sp[1] as usize] = [wild[sp[1] as usize][0] + 1.5 * a, wild[sp[1] as usize][1] - 1.2, 0.8 * a];
        wild[sp[2] as usize] = [wild[sp[2] as usize][0] - 1.1, wild[sp[2] as usize][1] + 1.6 * a, -0.5];
    }
    for (name, pose) in [("stretched", stretched), ("wild", wild)] {
        let samples = layout.sampling().samples(&pose).unwrap();
        assert_eq!(samples.len(), layout.n_samples());
        let worst = worst_spacing(&layout, &pose, &b.splines);
        println!("{name} pose: worst arc-length spacing deviation {worst:.2e}");
        assert!(worst < 0.01, "{name}: spacing off by {worst}");
        // Knot samples are the control points themselves.
        for k in 0..layout.sampling().n_knots() {
            assert_eq!(samples[k], pose[layout.sampling().knot_point(k) as usize]);
        }
    }
}

#[test]
fn density_scales_the_counts() {
    let (mesh, pts) = plane(3.0, 12);
    let b = star();
    let net = Curvenet::new(&b.splines, &b.points).unwrap();
    let coarse = CurvenetLayout::new(&net, &mesh, &pts, &SamplingOptions::default().with_density(1.0)).unwrap();
    let fine = CurvenetLayout::new(&net, &mesh, &pts, &SamplingOptions::default().with_density(10.0)).unwrap();
    for s in 0..b.splines.len() {
        let (c, f) = (coarse.sampling().spline_segments(s), fine.sampling().spline_segments(s));
        assert!(c >= 1 && f >= 8 * c, "spline {s}: {c} vs {f}");
    }
    // A tiny density still gives one segment per spline.
    let tiny = CurvenetLayout::new(&net, &mesh, &pts, &SamplingOptions::default().with_density(1e-6)).unwrap();
    assert!((0..b.splines.len()).all(|s| tiny.sampling().spline_segments(s) == 1));
}

#[test]
fn single_spline_loop_gets_at_least_three_segments() {
    let mut b = NetBuilder::default();
    let p = [0.0, 0.0, 0.0];
    let k = b.knot(p);
    let h1 = b.handle([0.2, 0.2, 0.0]);
    let h2 = b.handle([-0.2, 0.2, 0.0]);
    b.splines.push([k, h1, h2, k]);
    let net = Curvenet::new(&b.splines, &b.points).unwrap();
    let (mesh, pts) = plane(3.0, 6);
    // Density 0.5 alone would give round(0.5 × 0.97 / 1.0) = 0 → 1 segment.
    let options = SamplingOptions::default().with_density(0.5);
    let layout = CurvenetLayout::new(&net, &mesh, &pts, &options).unwrap();
    assert_eq!(layout.sampling().spline_segments(0), 3);
    assert_eq!(layout.n_samples(), 3);
    assert_eq!(layout.constraints().len(), 6);
}
