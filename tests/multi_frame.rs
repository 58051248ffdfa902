//! Multi-frame solves (`Deformer::frames`, issue 19): a group of frames
//! solved with one sweep of each triangular solve gives what solving them
//! one by one (`Deformer::frame`) gives, on the 22k hand and a corpus mesh,
//! with every frame feature that reaches the solves (posed pools, knot
//! tracking to a rest pose, blend shapes in both modes, Curvenet
//! Adjustments, gradients asked for or not), whatever the group size; a bad
//! frame is named by its index.

use curvenet_core::BlendShape;
use curvenet_core::{Adjustment, BlendShapeMode, Deformer, Error, Frame, FrameOut, Rotate};
use curvenet_e2e::{bind_fixture, curvenet_inputs, deformer_input};

/// A frame's inputs, owned.
struct Case {
    posed: Vec<Option<Vec<[f64; 3]>>>,
    rest: Option<Vec<[f64; 3]>>,
    weights: Option<Vec<f64>>,
    mode: BlendShapeMode,
    adjustments: Vec<Adjustment>,
    gradients: bool,
}

/// A deformer of the fixture's first mesh with two blend shapes (one
/// sparse with an inbetween, one dense), and frames using every feature.
fn setup(rel: &str) -> (Deformer, Vec<Case>) {
    let b = bind_fixture(rel);
    let pts = &b.mesh.projection_points;
    let n = pts.len();
    let d = b.diagonal();
    let inputs = curvenet_inputs(&b.nets);
    let mut input = deformer_input(&b.mesh, &inputs);
    let sparse: Vec<u32> = (0..n as u32).step_by(7).collect();
    let offsets: Vec<[f64; 3]> = sparse.iter().map(|&v| [0.01 * d, 0.0, 0.002 * d * (v % 5) as f64]).collect();
    let inbetween: Vec<[f64; 3]> = offsets.iter().map(|o| [0.4 * o[0], 0.1 * d * 0.01, o[2]]).collect();
    input.blend_shapes = vec![
        BlendShape::new(n, offsets, Some(sparse), vec![(0.5, inbetween)]).unwrap(),
        BlendShape::new(n, pts.iter().map(|p| [0.0, 0.02 * p[0], -0.01 * p[1]]).collect(), None, vec![]).unwrap(),
    ];
    let deformer = Deformer::new(&input).unwrap();
    // A smooth non-rigid pose of every curvenet, and a smooth rest pose.
    let bend = |p: &[f64; 3], s: f64| {
        [
            p[0] + s * 0.03 * (p[1] / d * 5.0).sin() * d,
            p[1] + s * 0.02 * (p[2] / d * 3.0).cos() * d,
            p[2] * (1.0 + 0.05 * s),
        ]
    };
    let posed = |s: f64| b.nets.iter().map(|net| Some(net.pool.iter().map(|p| bend(p, s)).collect())).collect();
    let rest: Vec<[f64; 3]> = pts.iter().map(|p| [p[0], p[1] + 0.02 * (p[0] / d * 4.0).sin() * d, p[2]]).collect();
    let layout = &deformer.binding().layouts()[0];
    let knot = layout.sampling().knot_point(layout.sampling().n_knots() / 2);
    let adjust = vec![
        Adjustment::new(0, knot)
            .with_translate([0.01 * d, 0.0, 0.005 * d])
            .with_rotate(Rotate::EulerXyz([5.0, 10.0, 0.0])),
    ];
    let case = |posed, rest: Option<&Vec<_>>, weights: Option<[f64; 2]>, mode, adjustments: &Vec<_>, gradients| Case {
        posed,
        rest: rest.cloned(),
        weights: weights.map(|w| w.to_vec()),
        mode,
        adjustments: adjustments.clone(),
        gradients,
    };
    let (after, before, none) = (BlendShapeMode::After, BlendShapeMode::Before, Vec::new());
    let cases = vec![
        case(posed(1.0), None, None, after, &none, true),
        case(vec![None; b.nets.len()], Some(&rest), None, after, &none, false),
        case(posed(0.5), None, Some([0.75, 0.3]), after, &none, true),
        case(posed(-0.7), None, Some([0.75, 0.3]), after, &none, false),
        case(posed(0.3), Some(&rest), Some([0.25, 1.0]), before, &none, true),
        case(Vec::new(), None, Some([1.0, 0.0]), before, &adjust, false),
        case(posed(0.8), Some(&rest), None, after, &adjust, true),
        case(Vec::new(), None, None, after, &none, false),
        case(posed(1.2), None, Some([0.0, 0.0]), after, &none, true),
    ];
    (deformer, cases)
}

fn frame<'a>(c: &'a Case, posed: &'a [Option<&'a [[f64; 3]]>]) -> Frame<'a> {
    Frame {
        posed,
        rest: c.rest.as_deref(),
        blend_shape_weights: c.weights.as_deref(),
        blend_shape_mode: c.mode,
        adjustments: &c.adjustments,
        ..Default::default()
    }
}

/// A frame's points and, when asked for, gradients.
type Solved = (Vec<[f64; 3]>, Option<Vec<[f64; 9]>>);

/// Largest difference over the largest magnitude.
fn relative(a: &[f64], b: &[f64]) -> f64 {
    let scale = b.iter().fold(0.0f64, |m, x| m.max(x.abs())).max(f64::MIN_POSITIVE);
    a.iter().zip(b).fold(0.0f64, |m, (x, y)| m.max((x - y).abs())) / scale
}

fn same_bits(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
}

/// Groups of `k` frames cycled from `which` (indices into `frames`) give
/// the single frames' bits, bit for bit: a group does every frame's
/// operations in the same order (the bake's bytes must not depend on the
/// group size). Every frame of `which` is solved, in at least two full
/// groups and a shorter last one.
fn check_groups(rel: &str, deformer: &Deformer, frames: &[Frame<'_>], single: &[Solved], which: &[usize], k: usize) {
    let n = deformer.n_vertices();
    let count = which.len().max(2 * k + 1);
    let picked: Vec<usize> = which.iter().copied().cycle().take(count).collect();
    let group_frames: Vec<Frame<'_>> = picked.iter().map(|&i| frames[i]).collect();
    let mut points: Vec<Vec<[f64; 3]>> = vec![vec![[f64::NAN; 3]; n]; picked.len()];
    let mut grads: Vec<Option<Vec<[f64; 9]>>> =
        picked.iter().map(|&i| single[i].1.as_ref().map(|_| vec![[f64::NAN; 9]; n])).collect();
    let mut outs: Vec<FrameOut<'_>> = points
        .iter_mut()
        .zip(grads.iter_mut())
        .map(|(p, g)| FrameOut { points: p, gradients: g.as_deref_mut() })
        .collect();
    for (group, outs) in group_frames.chunks(k).zip(outs.chunks_mut(k)) {
        deformer.frames(group, outs).unwrap();
    }
    for (j, &i) in picked.iter().enumerate() {
        let e = relative(points[j].as_flattened(), single[i].0.as_flattened());
        assert!(
            same_bits(points[j].as_flattened(), single[i].0.as_flattened()),
            "{rel}: frames {which:?} in groups of {k}: frame {i} (position {j}): points differ by {e:e} (relative)"
        );
        if let (Some(g), Some(sg)) = (&grads[j], &single[i].1) {
            let e = relative(g.as_flattened(), sg.as_flattened());
            assert!(
                same_bits(g.as_flattened(), sg.as_flattened()),
                "{rel}: frames {which:?} in groups of {k}: frame {i} (position {j}): gradients differ by {e:e} (relative)"
            );
        }
    }
}

fn check(rel: &str) {
    let (deformer, cases) = setup(rel);
    let n = deformer.n_vertices();
    let posed: Vec<Vec<Option<&[[f64; 3]]>>> =
        cases.iter().map(|c| c.posed.iter().map(|p| p.as_deref()).collect()).collect();
    let frames: Vec<Frame<'_>> = cases.iter().zip(&posed).map(|(c, p)| frame(c, p)).collect();
    // One by one.
    let single: Vec<Solved> = frames
        .iter()
        .zip(&cases)
        .map(|(f, c)| {
            let mut out = vec![[0.0; 3]; n];
            let mut g = c.gradients.then(|| vec![[0.0; 9]; n]);
            deformer.frame(f, &mut out, g.as_deref_mut()).unwrap();
            (out, g)
        })
        .collect();
    // The features did something: frames differ from each other and from the projection pose.
    for (i, (out, _)) in single.iter().enumerate() {
        let moved = relative(out.as_flattened(), deformer.projection_points().as_flattened());
        assert!(moved > 1e-4 || i == 7, "{rel}: frame {i} moved the mesh by only {moved:e}");
    }
    assert!(relative(single[2].0.as_flattened(), single[3].0.as_flattened()) > 1e-4);
    // Single frames leave the factor's row copy unmade; the first group makes it, counted then.
    let (copy, held) = (deformer.binding().factor_row_copy_bytes(), deformer.binding().heap_bytes());
    assert!(copy > 0, "{rel}: single frames made the factor's row copy");
    // All frames in groups of every size from 1 to all of them, and of 16 and 32 (the most a
    // group takes), the frames cycled to two full groups and a shorter last one.
    let all: Vec<usize> = (0..frames.len()).collect();
    for k in [1usize, 2, 3, 4, 5, 8, 9, 16, 32] {
        check_groups(rel, &deformer, &frames, &single, &all, k);
    }
    assert_eq!(deformer.binding().factor_row_copy_bytes(), 0, "{rel}: groups did not make the row copy");
    assert_eq!(deformer.binding().heap_bytes(), held + copy, "{rel}: the row copy is counted once made");
    // Groups whose every frame brings its own rest pose (given, or sculpted
    // by blend shapes before the solve), and groups whose frames need no
    // gradients back at all, in every fixed-width group size and the widest.
    let own_rest: Vec<usize> = (0..cases.len())
        .filter(|&i| cases[i].rest.is_some() || (cases[i].weights.is_some() && cases[i].mode == BlendShapeMode::Before))
        .collect();
    let plain: Vec<usize> = (0..cases.len())
        .filter(|&i| !own_rest.contains(&i) && !cases[i].gradients && cases[i].mode == BlendShapeMode::After)
        .filter(|&i| cases[i].weights.as_ref().is_none_or(|w| w.iter().all(|&x| x == 0.0)))
        .collect();
    assert!(own_rest.len() >= 3 && !plain.is_empty(), "{own_rest:?} {plain:?}");
    for k in [2, 4, 8, 16, 32] {
        check_groups(rel, &deformer, &frames, &single, &own_rest, k);
        let before = curvenet_core::lane_row_groups();
        check_groups(rel, &deformer, &frames, &single, &plain, k);
        // Plain groups of 2, 4, 8 and 16 made their rows lane by lane (and
        // still gave the single frames' bits); other sizes, frame by frame.
        let made = curvenet_core::lane_row_groups() - before;
        if k != 32 {
            assert!(made >= 2, "{rel}: groups of {k} made their rows lane by lane {made} times");
        }
    }
}

#[test]
fn hand_22k_frames_in_groups_match_frames_one_by_one() {
    check("hand/hand_22k.usdc");
}

#[test]
fn corpus_frames_in_groups_match_frames_one_by_one() {
    check("corpus/penguin.usda");
}

#[test]
fn a_bad_frame_of_a_group_is_named_by_its_index() {
    let (deformer, cases) = setup("corpus/penguin.usda");
    let n = deformer.n_vertices();
    let posed: Vec<Vec<Option<&[[f64; 3]]>>> =
        cases.iter().map(|c| c.posed.iter().map(|p| p.as_deref()).collect()).collect();
    let mut frames: Vec<Frame<'_>> = cases.iter().zip(&posed).map(|(c, p)| frame(c, p)).collect();
    let short = [0.5];
    frames[4].blend_shape_weights = Some(&short);
    let mut points = vec![vec![[0.0; 3]; n]; frames.len()];
    let mut outs: Vec<FrameOut<'_>> = points.iter_mut().map(|p| FrameOut { points: p, gradients: None }).collect();
    let e = deformer.frames(&frames, &mut outs).unwrap_err();
    assert_eq!(e.frame, 4);
    assert_eq!(e.error, Error::CountMismatch { what: "blend-shape weights", expected: 2, got: 1 });
    // A wrong output length.
    frames[4].blend_shape_weights = None;
    let mut short_out = vec![[0.0; 3]; n - 1];
    outs[6] = FrameOut { points: &mut short_out, gradients: None };
    let e = deformer.frames(&frames, &mut outs).unwrap_err();
    assert_eq!(e.frame, 6);
    assert!(matches!(e.error, Error::CountMismatch { what: "output points", .. }), "{e}");
    // Fewer outputs than frames.
    let e = deformer.frames(&frames, &mut outs[..3]).unwrap_err();
    assert!(matches!(e.error, Error::CountMismatch { what: "frame outputs", expected: 9, got: 3 }), "{e}");
}

/// FNV-1a of a name, so that every stage draws its own poses.
fn name_seed(rel: &str) -> u64 {
    rel.bytes().fold(0xcbf2_9ce4_8422_2325u64, |h, b| (h ^ b as u64).wrapping_mul(0x0100_0000_01b3))
}

/// Seeded random poses on every corpus stage and two more hands, in groups
/// of every fixed-width size (whose constraint rows are made lane by lane,
/// `Binding::lanes_rows`): every frame gives its single solve's bits. A
/// pose is a random rotation and translation of the whole curvenet, a
/// random smooth warp, and per-point noise of up to 0.3% of the diagonal;
/// the same poses again, each frame with a random rest pose (the bake over
/// skinning). Replay a failure with the seed it prints: `CURVENET_GROUP_SEED=<seed>`.
/// Then a group holding a collapsed curvenet fails as that frame alone
/// does, naming it.
#[test]
fn random_poses_in_groups_match_single_frames_on_every_corpus_stage() {
    use curvenet_core::SplitMix64;
    let base = std::env::var("CURVENET_GROUP_SEED").ok().and_then(|s| s.parse::<u64>().ok()).unwrap_or(0x19_5eed);
    let mut stages: Vec<String> = std::fs::read_dir(curvenet_e2e::fixtures_dir().join("corpus"))
        .unwrap()
        .map(|e| format!("corpus/{}", e.unwrap().file_name().to_string_lossy()))
        .collect();
    stages.sort();
    assert!(stages.len() >= 8, "{stages:?}");
    stages.extend(["hand/hand_1k4.usda".to_string(), "hand/hand_closed.usda".to_string()]);
    for rel in &stages {
        let seed = base ^ name_seed(rel);
        let b = bind_fixture(rel);
        let d = b.diagonal();
        let n = b.deformer.n_vertices();
        let mut rng = SplitMix64::new(seed);
        let poses: Vec<Vec<Vec<[f64; 3]>>> = (0..8)
            .map(|_| {
                let axis = [rng.signed(), rng.signed(), rng.signed() + 0.1];
                let len = (axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]).sqrt();
                let axis = glam::DVec3::from_array(axis) / len;
                let rot = glam::DMat3::from_axis_angle(axis, rng.range(-1.0, 1.0));
                let shift = glam::DVec3::new(rng.signed(), rng.signed(), rng.signed()) * 0.2 * d;
                let (wave, freq) = (rng.range(0.0, 0.04) * d, rng.range(1.0, 6.0) / d);
                b.nets
                    .iter()
                    .map(|net| {
                        net.pool
                            .iter()
                            .map(|&p| {
                                let p = glam::DVec3::from_array(p);
                                let warp = glam::DVec3::new(0.0, (p.x * freq).sin(), (p.y * freq).cos()) * wave;
                                let noise = glam::DVec3::new(rng.signed(), rng.signed(), rng.signed()) * 0.003 * d;
                                (rot * (p + warp) + shift + noise).to_array()
                            })
                            .collect()
                    })
                    .collect()
            })
            .collect();
        let posed: Vec<Vec<Option<&[[f64; 3]]>>> =
            poses.iter().map(|p| p.iter().map(|x| Some(x.as_slice())).collect()).collect();
        let frames: Vec<Frame<'_>> = posed.iter().map(|p| Frame { posed: p, ..Default::default() }).collect();
        // The same poses, each frame also with a random rest pose: the
        // projection pose moved rigidly and warped smoothly (knot tracking,
        // rows and Poisson right-hand sides frame by frame in the group).
        let points = b.deformer.projection_points();
        let rests: Vec<Vec<[f64; 3]>> = (0..8)
            .map(|_| {
                let rot =
                    glam::DMat3::from_rotation_z(rng.range(-1.0, 1.0)) * glam::DMat3::from_rotation_x(rng.signed());
                let shift = glam::DVec3::new(rng.signed(), rng.signed(), rng.signed()) * 0.2 * d;
                let (wave, freq) = (rng.range(0.0, 0.02) * d, rng.range(1.0, 6.0) / d);
                points
                    .iter()
                    .map(|&p| {
                        let p = glam::DVec3::from_array(p);
                        let warp = glam::DVec3::new((p.y * freq).sin(), 0.0, (p.x * freq).cos()) * wave;
                        (rot * (p + warp) + shift).to_array()
                    })
                    .collect()
            })
            .collect();
        let rest_frames: Vec<Frame<'_>> =
            posed.iter().zip(&rests).map(|(p, r)| Frame { posed: p, rest: Some(r), ..Default::default() }).collect();
        // Rows lane by lane (Binding::lanes_rows) only for the plain poses.
        for (frames, what, lanes) in [(&frames, "poses", true), (&rest_frames, "poses with rest poses", false)] {
            let single: Vec<Vec<[f64; 3]>> = frames
                .iter()
                .map(|f| {
                    let mut out = vec![[0.0; 3]; n];
                    b.deformer
                        .frame(f, &mut out, None)
                        .unwrap_or_else(|e| panic!("{rel} (seed {seed}): one of the {what} failed: {e}"));
                    out
                })
                .collect();
            for k in [2usize, 4, 8, 16] {
                let before = curvenet_core::lane_row_groups();
                let picked: Vec<usize> = (0..frames.len()).cycle().skip(k / 2).take(2 * k).collect();
                let group: Vec<Frame<'_>> = picked.iter().map(|&i| frames[i]).collect();
                let mut points = vec![vec![[f64::NAN; 3]; n]; picked.len()];
                let mut outs: Vec<FrameOut<'_>> =
                    points.iter_mut().map(|p| FrameOut { points: p, gradients: None }).collect();
                for (g, o) in group.chunks(k).zip(outs.chunks_mut(k)) {
                    b.deformer
                        .frames(g, o)
                        .unwrap_or_else(|e| panic!("{rel} (seed {seed}): {what} in groups of {k}: {e}"));
                }
                for (j, &i) in picked.iter().enumerate() {
                    assert!(
                        same_bits(points[j].as_flattened(), single[i].as_flattened()),
                        "{rel}: {what}: {i} in groups of {k} differs from its single frame by {:e} (relative); \
                         replay with CURVENET_GROUP_SEED={base}",
                        relative(points[j].as_flattened(), single[i].as_flattened())
                    );
                }
                let made = curvenet_core::lane_row_groups() - before;
                assert!(
                    !lanes || made >= 2,
                    "{rel}: {what} in groups of {k} made their rows lane by lane {made} times"
                );
            }
        }
        // A curvenet collapsed to one point in frame 5 of a group of 8.
        let collapsed: Vec<Vec<[f64; 3]>> = b.nets.iter().map(|net| vec![net.pool[0]; net.pool.len()]).collect();
        let bad: Vec<Option<&[[f64; 3]]>> = collapsed.iter().map(|x| Some(x.as_slice())).collect();
        let mut group: Vec<Frame<'_>> = frames.clone();
        group[5] = Frame { posed: &bad, ..Default::default() };
        let alone = b.deformer.frame(&group[5], &mut vec![[0.0; 3]; n], None).unwrap_err();
        let mut points = vec![vec![[0.0; 3]; n]; 8];
        let mut outs: Vec<FrameOut<'_>> = points.iter_mut().map(|p| FrameOut { points: p, gradients: None }).collect();
        let e = b.deformer.frames(&group, &mut outs).unwrap_err();
        assert_eq!((e.frame, &e.error), (5, &alone), "{rel}: a collapsed curvenet in a group");
    }
}
