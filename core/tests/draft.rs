//! `curvenet_core::draft`: drafted curvenets share their knots, sit in the
//! requested band off the surface, never cross themselves, are accepted by
//! the curvenet analysis and the binding, and are the same for the same seed.
//! On a sphere the counts and distances are known in closed form; on a real
//! mesh (the penguin) the invariants are checked without knowing the answer.

mod common;

use curvenet_core::closest_point::ClosestPointBvh;
use curvenet_core::draft::{Draft, DraftError, DraftOptions, Jitter, draft};
use curvenet_core::{BindOptions, Binding, Curvenet, CurvenetLayout, PolyMesh, SamplingOptions};

use common::{MESH_DIR, load_obj};

/// A UV sphere of radius `r` about the origin: `around` segments, `up`
/// stacks, quads with triangle fans at the poles (±z), counter-clockwise
/// seen from outside.
fn sphere(r: f64, around: u32, up: u32) -> (PolyMesh, Vec<[f64; 3]>) {
    let mut points = vec![[0.0, 0.0, -r]];
    for j in 1..up {
        let theta = std::f64::consts::PI * j as f64 / up as f64;
        for i in 0..around {
            let phi = std::f64::consts::TAU * i as f64 / around as f64;
            points.push([r * theta.sin() * phi.cos(), r * theta.sin() * phi.sin(), -r * theta.cos()]);
        }
    }
    points.push([0.0, 0.0, r]);
    let top = points.len() as u32 - 1;
    let at = |i: u32, j: u32| 1 + (j - 1) * around + i % around;
    let (mut counts, mut indices) = (Vec::new(), Vec::new());
    for i in 0..around {
        counts.push(3);
        indices.extend([0, at(i + 1, 1), at(i, 1)]);
        counts.push(3);
        indices.extend([top, at(i, up - 1), at(i + 1, up - 1)]);
    }
    for j in 1..up - 1 {
        for i in 0..around {
            counts.push(4);
            indices.extend([at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1)]);
        }
    }
    let n = points.len();
    (PolyMesh::new(&counts, &indices, n).unwrap(), points)
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn norm(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}

fn bezier(c: [[f64; 3]; 4], u: f64) -> [f64; 3] {
    let v = 1.0 - u;
    let w = [v * v * v, 3.0 * v * v * u, 3.0 * v * u * u, u * u * u];
    [0, 1, 2].map(|k| (0..4).map(|i| w[i] * c[i][k]).sum())
}

fn control(d: &Draft, s: usize) -> [[f64; 3]; 4] {
    d.splines[s].map(|i| d.pool[i as usize])
}

/// Endpoint use per pool index (0 for handles).
fn valences(d: &Draft) -> Vec<usize> {
    let mut v = vec![0; d.pool.len()];
    for s in &d.splines {
        v[s[0] as usize] += 1;
        v[s[3] as usize] += 1;
    }
    v
}

/// Structural checks every draft must pass: the pool is knots then two
/// handles per spline, used exactly so; knots are shared (every knot index
/// is an endpoint of at least one spline, and the report's counts match
/// the valences); handles belong to one spline each.
fn check_structure(d: &Draft) {
    let val = valences(d);
    let n_knots = d.report.knots;
    assert_eq!(d.pool.len(), n_knots + 2 * d.splines.len());
    assert!(val[..n_knots].iter().all(|&v| v > 0), "a knot no spline ends at");
    assert!(val[n_knots..].iter().all(|&v| v == 0), "a handle used as an endpoint");
    for (s, sp) in d.splines.iter().enumerate() {
        assert_eq!([sp[1], sp[2]], [(n_knots + 2 * s) as u32, (n_knots + 2 * s + 1) as u32]);
        assert_ne!(sp[0], sp[3], "spline {s} starts and ends at one knot");
    }
    assert_eq!(d.report.anchors, val.iter().filter(|&&v| v == 1).count());
    assert_eq!(d.report.t_junctions, val.iter().filter(|&&v| v == 3).count());
    assert_eq!(d.report.intersections, val.iter().filter(|&&v| v >= 4).count());
    assert_eq!(d.report.splines, d.splines.len());
}

/// Sampled splines (`n` + 1 points each).
fn sampled(d: &Draft, n: usize) -> Vec<Vec<[f64; 3]>> {
    (0..d.splines.len()).map(|s| (0..=n).map(|i| bezier(control(d, s), i as f64 / n as f64)).collect()).collect()
}

/// The smallest distance between two splines' samples, ignoring samples
/// within `near` of a knot both splines end at. Returns the distance and a
/// pair of spline indices reaching it.
fn closest_unshared(d: &Draft, samples: &[Vec<[f64; 3]>], near: f64) -> (f64, usize, usize) {
    let mut best = (f64::INFINITY, 0, 0);
    for a in 0..d.splines.len() {
        for b in a + 1..d.splines.len() {
            let (sa, sb) = (d.splines[a], d.splines[b]);
            let shared: Vec<[f64; 3]> =
                [sa[0], sa[3]].into_iter().filter(|k| *k == sb[0] || *k == sb[3]).map(|k| d.pool[k as usize]).collect();
            let free = |p: &[f64; 3]| shared.iter().all(|k| norm(sub(*p, *k)) > near);
            for p in samples[a].iter().filter(|p| free(p)) {
                for q in samples[b].iter().filter(|q| free(q)) {
                    let dist = norm(sub(*p, *q));
                    if dist < best.0 {
                        best = (dist, a, b);
                    }
                }
            }
        }
    }
    best
}

/// Pairs of splines whose projections onto the surface cross: every spline
/// is sampled every tenth of a mean edge and projected (closest points);
/// consecutive samples in one triangle make a segment in that triangle's
/// barycentric plane (an affine image of it, so crossings are preserved);
/// segments of two splines in one triangle that properly intersect are a
/// crossing, unless both are within half a mean edge of a knot the two
/// splines share.
fn projected_crossings(d: &Draft, bvh: &ClosestPointBvh, edge: f64) -> Vec<(usize, usize, [f64; 3])> {
    type Seg = (usize, [f64; 2], [f64; 2], [f64; 3], [f64; 3]);
    let mut by_triangle: std::collections::HashMap<u32, Vec<Seg>> = std::collections::HashMap::new();
    for s in 0..d.splines.len() {
        let c = control(d, s);
        let polygon = norm(sub(c[1], c[0])) + norm(sub(c[2], c[1])) + norm(sub(c[3], c[2]));
        let n = ((polygon / (0.1 * edge)).ceil() as usize).max(8);
        let hits: Vec<_> = (0..=n).map(|i| bvh.closest_point(bezier(c, i as f64 / n as f64)).unwrap()).collect();
        for w in hits.windows(2) {
            if w[0].triangle == w[1].triangle {
                let uv = |h: &curvenet_core::Hit| [h.barycentric[1], h.barycentric[2]];
                by_triangle.entry(w[0].triangle).or_default().push((s, uv(&w[0]), uv(&w[1]), w[0].point, w[1].point));
            }
        }
    }
    let orient = |a: [f64; 2], b: [f64; 2], c: [f64; 2]| (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
    let mut found = Vec::new();
    for segs in by_triangle.values() {
        for (i, a) in segs.iter().enumerate() {
            for b in &segs[i + 1..] {
                if a.0 == b.0 {
                    continue;
                }
                let crosses = orient(a.1, a.2, b.1) * orient(a.1, a.2, b.2) < 0.0
                    && orient(b.1, b.2, a.1) * orient(b.1, b.2, a.2) < 0.0;
                if !crosses {
                    continue;
                }
                let (sa, sb) = (d.splines[a.0], d.splines[b.0]);
                let at_shared_knot = [sa[0], sa[3]].into_iter().filter(|k| *k == sb[0] || *k == sb[3]).any(|k| {
                    let foot = bvh.closest_point(d.pool[k as usize]).unwrap().point;
                    [a.3, a.4, b.3, b.4].iter().all(|p| norm(sub(*p, foot)) < 0.5 * edge)
                });
                if !at_shared_knot {
                    found.push((a.0.min(b.0), a.0.max(b.0), a.3));
                }
            }
        }
    }
    found.sort_by_key(|x| (x.0, x.1));
    found
}

fn binds(mesh: &PolyMesh, points: &[[f64; 3]], d: &Draft) -> Result<Binding, curvenet_core::Error> {
    let net = Curvenet::new(&d.splines, &d.pool)?;
    let layout = CurvenetLayout::new(&net, mesh, points, &SamplingOptions::default())?;
    Binding::new(mesh, points, &[&layout], &BindOptions::default())
}

#[test]
fn sphere_draft_has_the_expected_network_in_the_offset_band() {
    let (mesh, points) = sphere(1.0, 64, 48);
    let bvh = ClosestPointBvh::new(&mesh, &points).unwrap();
    let diagonal = curvenet_core::mesh::bounding_box_diagonal(&points);
    let edge = mesh.mean_edge_length(&points);
    let (rings, lines) = (5, 3);
    let options = DraftOptions::default()
        .with_axis([0.0, 0.0, 1.0])
        .with_across([1.0, 0.0, 0.0])
        .with_rings(rings)
        .with_lines(lines)
        .with_span([0.2, 0.8])
        .with_offset(0.01);
    let d = draft(&mesh, &points, &options).unwrap();
    check_structure(&d);
    // Each line plane (x = const, |x| < 1) cuts each ring once on either
    // side: 2 lines' crossings per ring and line. Inner rings are crossed
    // (valence 4), the end rings end the lines (T-junctions).
    assert_eq!(d.report.rings.iter().map(|r| r.loops).collect::<Vec<_>>(), vec![1; rings]);
    assert_eq!(d.report.intersections, 2 * lines * (rings - 2));
    assert_eq!(d.report.t_junctions, 2 * lines * 2);
    assert_eq!(d.report.anchors, 0);
    assert_eq!(d.report.isolated_loops, 0);
    assert_eq!(d.report.reduced_pushes, 0, "nothing on a sphere is closer than its own surface");
    // Knots are pushed `offset × diagonal` along the interpolated vertex
    // normal, which is within 3° of the face normal on this sphere: they are
    // that far off the surface within cos 3° (0.14 %). The fitted curves are
    // within the fit tolerance (a quarter mean edge) of that.
    let h = 0.01 * diagonal;
    for k in 0..d.report.knots {
        let dist = bvh.closest_point(d.pool[k]).unwrap().distance;
        assert!(dist <= h * (1.0 + 1e-12) && dist >= h * 0.9986, "knot {k} is {dist} off the surface, want {h}");
    }
    for (s, samples) in sampled(&d, 32).iter().enumerate() {
        for p in samples {
            let dist = bvh.closest_point(*p).unwrap().distance;
            assert!((dist - h).abs() <= 0.3 * edge, "spline {s}: a sample {dist} off the surface, want {h}");
        }
    }
    // Crossing knots lie over both of their planes: the surface point under
    // each knot of valence >= 3 is on a ring plane and on a line plane.
    let val = valences(&d);
    for k in (0..d.report.knots).filter(|&k| val[k] >= 3) {
        let foot = bvh.closest_point(d.pool[k]).unwrap().point;
        let ring = d.report.rings.iter().map(|r| dot(sub(foot, r.point), r.normal).abs()).fold(f64::INFINITY, f64::min);
        let line = d.report.lines.iter().map(|l| (dot(foot, l.normal) - l.offset).abs()).fold(f64::INFINITY, f64::min);
        assert!(ring < 0.05 * edge && line < 0.05 * edge, "knot {k}: {ring} off a ring plane, {line} off a line plane");
    }
    // Splines meet only at shared knots: on a sphere (no thin parts) they
    // even stay half a mean edge apart away from them, and their
    // projections never cross.
    let (gap, a, b) = closest_unshared(&d, &sampled(&d, 64), 2.0 * edge);
    assert!(gap > 0.5 * edge, "splines {a} and {b} come within {gap} of each other");
    assert_eq!(projected_crossings(&d, &bvh, edge), vec![]);
    binds(&mesh, &points, &d).expect("the sphere draft binds");
}

#[test]
fn rings_only_and_a_single_ring() {
    let (mesh, points) = sphere(1.0, 48, 32);
    let options = DraftOptions::default().with_axis([0.0, 0.0, 1.0]).with_lines(0).with_rings(3);
    let d = draft(&mesh, &points, &options).unwrap();
    check_structure(&d);
    // Three isolated loops of four splines each, every knot of valence 2.
    assert_eq!(d.report.isolated_loops, 3);
    assert_eq!(d.splines.len(), 12);
    assert!(valences(&d)[..d.report.knots].iter().all(|&v| v == 2));
    let one = draft(&mesh, &points, &options.clone().with_rings(1)).unwrap();
    assert_eq!(one.report.isolated_loops, 1);
    binds(&mesh, &points, &d).expect("the rings bind");
}

#[test]
fn penguin_draft_invariants() {
    let (mesh, points) = load_obj(&format!("{MESH_DIR}/penguin.obj"));
    let bvh = ClosestPointBvh::new(&mesh, &points).unwrap();
    let diagonal = curvenet_core::mesh::bounding_box_diagonal(&points);
    let edge = mesh.mean_edge_length(&points);
    for offset in [0.0, 0.005, 0.02] {
        let options = DraftOptions::default().with_offset(offset);
        let d = draft(&mesh, &points, &options).unwrap_or_else(|e| panic!("offset {offset}: {e}"));
        check_structure(&d);
        assert!(d.report.intersections > 0 && d.report.t_junctions > 0, "{:?}", d.report);
        // No knot is farther off the surface than the offset; most get the
        // full push. Where a crease or another part of the penguin (the
        // flippers lie against the body) is closer than the push, it is
        // reduced, which the coarse penguin needs at 2 % of the diagonal (a
        // mean edge) for about a third of its knots.
        let h = offset * diagonal;
        let mut dist: Vec<f64> = (0..d.report.knots).map(|k| bvh.closest_point(d.pool[k]).unwrap().distance).collect();
        for (k, x) in dist.iter().enumerate() {
            assert!(*x <= h * (1.0 + 1e-9) + 1e-12, "offset {offset}: knot {k} is {x} off, more than {h}");
        }
        dist.sort_by(f64::total_cmp);
        let median = dist[dist.len() / 2];
        let want = if offset <= 0.005 { 0.95 } else { 0.5 };
        assert!(median >= want * h, "offset {offset}: the median knot is only {median} off the surface ({h} asked)");
        for (s, samples) in sampled(&d, 32).iter().enumerate() {
            for p in samples {
                let dist = bvh.closest_point(*p).unwrap().distance;
                assert!(dist <= h + 0.3 * edge, "offset {offset}: spline {s} has a sample {dist} off the surface");
            }
        }
        // Curves may pass close to each other across thin parts (the
        // flippers), but their projections onto the surface never cross.
        let crossings = projected_crossings(&d, &bvh, edge);
        assert!(crossings.is_empty(), "offset {offset}: splines cross: {crossings:?}");
        Curvenet::new(&d.splines, &d.pool).unwrap();
    }
}

#[test]
fn same_seed_same_draft_other_seed_other_draft() {
    let (mesh, points) = load_obj(&format!("{MESH_DIR}/penguin.obj"));
    let options = |seed| DraftOptions::default().with_offset(0.01).with_jitter(Some(Jitter::new(seed)));
    let a = draft(&mesh, &points, &options(7)).unwrap();
    let b = draft(&mesh, &points, &options(7)).unwrap();
    assert_eq!(a, b);
    let c = draft(&mesh, &points, &options(8)).unwrap();
    assert_ne!(a.pool, c.pool);
    // Without jitter the draft is the same on every call too.
    let plain = DraftOptions::default();
    assert_eq!(draft(&mesh, &points, &plain).unwrap(), draft(&mesh, &points, &plain).unwrap());
    check_structure(&a);
    check_structure(&c);
}

#[test]
fn bad_options_and_meshes_are_refused_by_name() {
    let (mesh, points) = sphere(1.0, 16, 8);
    let refused = |o: DraftOptions| match draft(&mesh, &points, &o) {
        Err(DraftError::Option { what, .. }) => what,
        other => panic!("{o:?} gave {other:?}"),
    };
    let base = DraftOptions::default();
    assert_eq!(refused(base.clone().with_rings(0)), "rings");
    assert_eq!(refused(base.clone().with_rings(1)), "rings"); // lines need two rings
    assert_eq!(refused(base.clone().with_span([0.5, 0.5])), "span");
    assert_eq!(refused(base.clone().with_span([-0.1, 0.5])), "span");
    assert_eq!(refused(base.clone().with_offset(0.5)), "offset");
    assert_eq!(refused(base.clone().with_offset(f64::NAN)), "offset");
    assert_eq!(refused(base.clone().with_axis([0.0, 0.0, 0.0])), "axis");
    assert_eq!(refused(base.clone().with_axis([0.0, 0.0, 1.0]).with_across([0.0, 0.0, 2.0])), "across");
    // A mesh that is not an oriented manifold: its error names the edge.
    let bad = PolyMesh::new(&[3, 3, 3], &[0, 1, 2, 0, 1, 3, 0, 1, 4], 5).unwrap();
    let pts = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]];
    match draft(&bad, &pts, &base) {
        Err(DraftError::Mesh(curvenet_core::Error::NonManifoldEdge { a: 0, b: 1, .. })) => {}
        other => panic!("{other:?}"),
    }
}
