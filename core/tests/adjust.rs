//! Knot orientations on hand-built curvenets where the answer is known:
//! the intersection fit against exact rotations and against an SVD
//! reference, and the inverse-distance blend between two intersections.

mod common;

use common::*;
use curvenet_core::adjust::{OrientationPlan, blend_rotations, fit_rotation};
use curvenet_core::{Curvenet, CurvenetLayout, Mat3, SamplingOptions};

/// xorshift64*: a fixed sequence of numbers in [-1, 1).
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let x = self.0.wrapping_mul(0x2545_f491_4f6c_dd1d);
        (x >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }

    fn vec(&mut self) -> [f64; 3] {
        [self.next(), self.next(), self.next()]
    }
}

/// The weighted Kabsch optimum by SVD (faer): `R = U diag(1, 1, det(U Vᵀ)) Vᵀ`
/// for `H = Σ w b aᵀ = U Σ Vᵀ`, maximising `Σ w b·(R a)`.
fn kabsch_svd(from: &[[f64; 3]], to: &[[f64; 3]], w: &[f64]) -> Mat3 {
    let h = faer::Mat::<f64>::from_fn(3, 3, |i, j| (0..from.len()).map(|k| w[k] * to[k][i] * from[k][j]).sum());
    let svd = h.svd().expect("svd of a 3x3");
    let (u, v) = (svd.U(), svd.V());
    let uvt: Mat3 = std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| u[(i, k)] * v[(j, k)]).sum()));
    let det = uvt[0][0] * (uvt[1][1] * uvt[2][2] - uvt[1][2] * uvt[2][1])
        - uvt[0][1] * (uvt[1][0] * uvt[2][2] - uvt[1][2] * uvt[2][0])
        + uvt[0][2] * (uvt[1][0] * uvt[2][1] - uvt[1][1] * uvt[2][0]);
    let d = [1.0, 1.0, det.signum()];
    std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| u[(i, k)] * d[k] * v[(j, k)]).sum()))
}

fn layout_of(net: &NetBuilder) -> CurvenetLayout {
    let (mesh, pts) = plane(3.0, 23);
    let c = Curvenet::new(&net.splines, &net.points).unwrap();
    CurvenetLayout::new(&c, &mesh, &pts, &SamplingOptions::default()).unwrap()
}

/// The orientation of every knot of `layout` posed at `pool`, with the
/// plane's normal turned by `r` as the surface normal.
fn orientations(layout: &CurvenetLayout, plan: &OrientationPlan, pool: &[[f64; 3]], r: &Mat3) -> Vec<Mat3> {
    let samples = layout.sampling().samples(pool).unwrap();
    let mut out = vec![I3; plan.n_knots()];
    plan.orientations_into(layout, pool, &samples, |_| apply(r, [0.0, 0.0, 1.0]), &mut out).unwrap();
    out
}

#[test]
fn tangents_rotated_exactly_by_r_fit_r_at_every_intersection() {
    for (name, net) in [("grid", grid(0.05)), ("star", star())] {
        let layout = layout_of(&net);
        let plan = OrientationPlan::new(&layout, |_| [0.0, 0.0, 1.0]).unwrap();
        let sampling = layout.sampling();
        let mut rng = Rng(0x5eed_1234_abcd_0001);
        for trial in 0..20 {
            let r = rotation(rng.vec(), 3.0 * rng.next());
            let t = rng.vec();
            let pool: Vec<[f64; 3]> = net.points.iter().map(|&p| add(apply(&r, p), t)).collect();
            let o = orientations(&layout, &plan, &pool, &r);
            let (mut at_intersections, mut elsewhere) = (0.0f64, 0.0f64);
            for (k, ok) in o.iter().enumerate() {
                let err = max_diff(ok, &r);
                match layout.topology().valence(sampling.knot_point(k) as usize) >= 3 {
                    true => at_intersections = at_intersections.max(err),
                    false => elsewhere = elsewhere.max(err),
                }
            }
            if trial == 0 {
                eprintln!(
                    "{name}: rigid pose, |O - R| at intersections {at_intersections:.1e}, other knots {elsewhere:.1e}"
                );
            }
            assert!(at_intersections <= 1e-12, "{name} trial {trial}: intersection fit off R by {at_intersections:e}");
            assert!(elsewhere <= 1e-11, "{name} trial {trial}: transported orientation off R by {elsewhere:e}");
        }
    }
}

fn add(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

#[test]
fn with_noise_the_fit_is_the_weighted_kabsch_optimum() {
    // The fit function itself, on random weighted sets of 2 to 7 vectors.
    let mut rng = Rng(0x0dd_ba11_cafe_f00d);
    let mut worst = 0.0f64;
    for trial in 0..500 {
        let n = 2 + trial % 6;
        let r = rotation(rng.vec(), 3.1 * rng.next());
        let from: Vec<[f64; 3]> = (0..n).map(|_| rng.vec()).collect();
        let to: Vec<[f64; 3]> = from.iter().map(|&a| add(apply(&r, a), rng.vec().map(|x| 0.3 * x))).collect();
        let w: Vec<f64> = (0..n).map(|_| 1.5 + rng.next()).collect();
        let fit = fit_rotation(&from, &to, &w).unwrap().expect("a determined fit");
        worst = worst.max(max_diff(&fit, &kabsch_svd(&from, &to, &w)));
    }
    eprintln!("fit_rotation vs the SVD Kabsch reference on 500 noisy sets: max entry difference {worst:.1e}");
    assert!(worst <= 1e-10, "{worst:e}");

    // At the star's valence-5 intersection with noisy posed handles: the
    // knot's orientation is the SVD optimum of its unit Bézier end tangents
    // weighted by their neutral lengths.
    let net = star();
    let layout = layout_of(&net);
    let plan = OrientationPlan::new(&layout, |_| [0.0, 0.0, 1.0]).unwrap();
    let centre = net.points.iter().position(|p| *p == [0.0; 3]).unwrap() as u32;
    let handles: Vec<u32> = net
        .splines
        .iter()
        .filter_map(|s| match (s[0] == centre, s[3] == centre) {
            (true, _) => Some(s[1]),
            (_, true) => Some(s[2]),
            _ => None,
        })
        .collect();
    assert_eq!(handles.len(), 5);
    let k = layout.sampling().knot_sample(centre as usize).unwrap() as usize;
    let mut worst = 0.0f64;
    for _ in 0..50 {
        let r = rotation(rng.vec(), 3.0 * rng.next());
        let pool: Vec<[f64; 3]> = net.points.iter().map(|&p| add(apply(&r, p), rng.vec().map(|x| 0.05 * x))).collect();
        let o = orientations(&layout, &plan, &pool, &r);
        let unit = |v: [f64; 3]| normalize(v);
        let from: Vec<[f64; 3]> =
            handles.iter().map(|&h| unit(sub(net.points[h as usize], net.points[centre as usize]))).collect();
        let to: Vec<[f64; 3]> = handles.iter().map(|&h| unit(sub(pool[h as usize], pool[centre as usize]))).collect();
        let w: Vec<f64> =
            handles.iter().map(|&h| norm(sub(net.points[h as usize], net.points[centre as usize]))).collect();
        worst = worst.max(max_diff(&o[k], &kabsch_svd(&from, &to, &w)));
    }
    eprintln!("star intersection with noisy handles: orientation vs SVD reference {worst:.1e}");
    assert!(worst <= 1e-10, "{worst:e}");
}

/// Rotation about the y axis by `deg` degrees.
fn ry(deg: f64) -> Mat3 {
    rotation([0.0, 1.0, 0.0], deg.to_radians())
}

#[test]
fn a_knot_between_two_intersections_blends_their_orientations_by_arc_length() {
    // The straight grid: on the line x = 0, intersections at y = -1 (A) and
    // y = 0 (B), the joint knot at y = -0.5 halfway between them, the anchor
    // at y = -2 beyond A. Turning the horizontal line y = -1 by α about the y
    // axis turns A's tangents by exactly Ry(α) (its vertical tangents lie on
    // the axis); y = 0 by β turns B's by Ry(β). The line x = 0 stays straight.
    let net = grid(0.0);
    let layout = layout_of(&net);
    let plan = OrientationPlan::new(&layout, |_| [0.0, 0.0, 1.0]).unwrap();
    let sampling = layout.sampling();
    let (alpha, beta) = (40.0, -70.0);
    let pool: Vec<[f64; 3]> = net
        .points
        .iter()
        .map(|&p| match p[1] {
            -1.0 => apply(&ry(alpha), p),
            0.0 => apply(&ry(beta), p),
            _ => p,
        })
        .collect();
    let o = orientations(&layout, &plan, &pool, &I3);
    let at = |p: [f64; 3]| {
        let i = net.points.iter().position(|q| *q == p).unwrap();
        o[sampling.knot_sample(i).unwrap() as usize]
    };
    let a = at([0.0, -1.0, 0.0]);
    let b = at([0.0, 0.0, 0.0]);
    assert!(max_diff(&a, &ry(alpha)) <= 1e-12 && max_diff(&b, &ry(beta)) <= 1e-12, "{a:?} {b:?}");
    let halfway = at([0.0, -0.5, 0.0]);
    let err = max_diff(&halfway, &ry(0.5 * (alpha + beta)));
    eprintln!(
        "knot halfway between intersections at {alpha} and {beta} degrees: off Ry({}) by {err:.1e}",
        0.5 * (alpha + beta)
    );
    assert!(err <= 1e-6, "{err:e}");
    assert!(max_diff(&halfway, &blend_rotations(&a, &b, 0.5)) <= 1e-12);
    // Beyond A, towards the anchor, only A's orientation reaches.
    assert!(max_diff(&at([0.0, -2.0, 0.0]), &ry(alpha)) <= 1e-12);
}

#[test]
fn a_knots_tangents_are_the_handles_next_to_it_that_are_not_knots() {
    use curvenet_core::adjust::knot_tangents;
    // The plan's table and the splines-only rule (the USD reader's) agree on
    // every knot of the test nets.
    for (name, net) in [("grid", grid(0.05)), ("star", star()), ("cylinder", cylinder_net())] {
        let layout = layout_of_on(&net, name);
        let plan = OrientationPlan::new(&layout, |_| [0.0, 0.0, 1.0]).unwrap();
        let sampling = layout.sampling();
        for k in 0..sampling.n_knots() {
            let p = sampling.knot_point(k);
            assert_eq!(plan.knot_tangents(k), knot_tangents(&net.splines, p), "{name} knot {p}");
            // Every handle of a spline ending at the knot is listed (the test nets have no degenerate handles).
            let valence = layout.topology().valence(p as usize) as usize;
            assert_eq!(plan.knot_tangents(k).len(), valence, "{name} knot {p}");
        }
    }
    // A handle on the knot itself and a handle that is another knot are not tangents.
    let splines = [[0, 0, 1, 2], [2, 3, 4, 5], [5, 0, 6, 7]];
    assert_eq!(knot_tangents(&splines, 0), Vec::<u32>::new());
    assert_eq!(knot_tangents(&splines, 2), [1, 3]);
    assert_eq!(knot_tangents(&splines, 5), [4], "handle 0 of the third spline is a knot");
    assert_eq!(knot_tangents(&splines, 7), [6]);
}

/// `layout_of`, on a cylinder for the cylinder net.
fn layout_of_on(net: &NetBuilder, name: &str) -> CurvenetLayout {
    if name != "cylinder" {
        return layout_of(net);
    }
    let (mesh, pts) = cylinder(1.0, -1.0, 4.0, 48, 30);
    let c = Curvenet::new(&net.splines, &net.points).unwrap();
    CurvenetLayout::new(&c, &mesh, &pts, &SamplingOptions::default()).unwrap()
}
