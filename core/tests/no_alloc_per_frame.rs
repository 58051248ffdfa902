//! The per-frame path (sampling, frames, gradients, constraint remap) makes
//! no heap allocation. This binary holds a single test, and counts only
//! the allocations of its thread (`counting::count_only_this_thread`).

mod common;
mod counting;

use common::*;
use curvenet_core::curvenet::{ScaledFrame, constraint_gradients_into, deformation_gradients_into, scaled_frames_into};
use curvenet_core::{Adjustment, Curvenet, CurvenetLayout, Mat3, Rotate, SamplingOptions};

#[global_allocator]
static GLOBAL: counting::Counting = counting::Counting;

#[test]
fn per_frame_evaluation_does_not_allocate() {
    // Every frame path measured here runs on the calling thread.
    counting::count_only_this_thread();
    curvenet_evaluation();
    whole_frame_solve();
    frames_in_groups();
}

/// Frames solved in groups (`Deformer::frames`: posed pools, a rest pose,
/// Curvenet Adjustments, blend shapes in both modes, gradients asked for or
/// not) allocate nothing once a group of as many frames has been solved.
fn frames_in_groups() {
    use curvenet_core::blend_shapes::BlendShape;
    use curvenet_core::{
        BlendShapeMode, CurvenetInput, Deformer, DeformerInput, DeformerOptions, Frame, FrameOut, MeshInput,
    };
    let (mesh, pts) = plane(3.0, 23);
    let b = grid(0.05);
    let counts: Vec<u32> = mesh.face_vertex_counts().collect();
    let nets = [CurvenetInput { splines: &b.splines, pool: &b.points, sample_density: 5.0 }];
    let n = pts.len();
    let shape = BlendShape::new(n, (0..n).map(|i| [0.0, 0.0, 0.001 * (i % 5) as f64]).collect(), None, vec![]).unwrap();
    let input = DeformerInput {
        mesh: MeshInput {
            face_vertex_counts: &counts,
            face_vertex_indices: mesh.face_vertex_indices(),
            projection_points: &pts,
        },
        curvenets: &nets,
        blend_shapes: vec![shape],
        skinning: None,
        cage: None,
        options: DeformerOptions::default(),
    };
    let deformer = Deformer::new(&input).unwrap();
    let r = rotation([0.2, 1.0, 0.3], 0.7);
    let pose: Vec<[f64; 3]> = b.points.iter().map(|&p| apply(&r, p)).collect();
    let rest: Vec<[f64; 3]> = pts.iter().map(|&p| [p[0], p[1], 0.1 * p[0] * p[0]]).collect();
    let knot = deformer.binding().layouts()[0].sampling().knot_point(0);
    let adjustments = [Adjustment::new(0, knot).with_translate([0.0, 0.0, 0.05])];
    let posed = [Some(pose.as_slice())];
    let weights = [0.8];
    let frames = [
        Frame { posed: &posed, ..Frame::default() },
        Frame { rest: Some(&rest), adjustments: &adjustments, ..Frame::default() },
        Frame { posed: &posed, blend_shape_weights: Some(&weights), ..Frame::default() },
        Frame {
            posed: &posed,
            rest: Some(&rest),
            blend_shape_weights: Some(&weights),
            blend_shape_mode: BlendShapeMode::Before,
            ..Frame::default()
        },
    ];
    let mut points = vec![vec![[0.0; 3]; n]; frames.len()];
    let mut grads = vec![[0.0; 9]; n];
    let (first, rest_points) = points.split_first_mut().unwrap();
    let mut outs: Vec<FrameOut<'_>> = std::iter::once(FrameOut { points: first, gradients: Some(&mut grads) })
        .chain(rest_points.iter_mut().map(|p| FrameOut { points: p, gradients: None }))
        .collect();
    // A group all in the projection pose: its constraint rows are made lane
    // by lane in the group's block (`Binding::lanes_rows`).
    let plain = [frames[0], frames[2], frames[0], frames[2]];
    // A group whose every frame has its own rest pose (a bake over skinning).
    let rested = [frames[1], frames[3], frames[3], frames[1]];
    // Warm-up: the group's workspaces, each with the buffers its frames' modes need.
    deformer.frames(&frames, &mut outs).unwrap();
    deformer.frames(&frames[1..3], &mut outs[1..3]).unwrap();
    deformer.frames(&plain, &mut outs).unwrap();
    deformer.frames(&rested, &mut outs).unwrap();
    let before = counting::allocations();
    for _ in 0..3 {
        deformer.frames(&frames, &mut outs).unwrap();
        deformer.frames(&frames[1..3], &mut outs[1..3]).unwrap();
        deformer.frames(&plain, &mut outs).unwrap();
        deformer.frames(&rested, &mut outs).unwrap();
    }
    let after = counting::allocations();
    assert_eq!(after - before, 0, "Deformer::frames allocated");
    for out in &outs {
        assert!(out.points.iter().zip(&pts).any(|(o, p)| (o[2] - p[2]).abs() > 1e-3), "a frame did not move the mesh");
    }
}

/// A whole frame (`Binding::deform`, with and without a rest pose, with and
/// without Curvenet Adjustments, with per-vertex gradients) allocates
/// nothing once its workspace exists.
fn whole_frame_solve() {
    let (mesh, pts) = plane(3.0, 23);
    let b = grid(0.05);
    let net = Curvenet::new(&b.splines, &b.points).unwrap();
    let layout = CurvenetLayout::new(&net, &mesh, &pts, &SamplingOptions::default()).unwrap();
    let binding = curvenet_core::Binding::new(&mesh, &pts, &[&layout], &Default::default()).unwrap();
    let r = rotation([0.2, 1.0, 0.3], 0.7);
    let pose: Vec<[f64; 3]> = b.points.iter().map(|&p| apply(&r, p)).collect();
    let rest: Vec<[f64; 3]> = pts.iter().map(|&p| [p[0], p[1], 0.1 * p[0] * p[0]]).collect();
    let mut ws = binding.workspace();
    let mut out = vec![[0.0; 3]; binding.n_vertices()];
    let mut grads = vec![[0.0; 9]; binding.n_vertices()];
    // An intersection, a joint and an anchor of the grid, every control of an adjustment used.
    let sampling = layout.sampling();
    let knot = |v: u32| {
        (0..sampling.n_knots())
            .map(|k| sampling.knot_point(k))
            .find(|&p| layout.topology().valence(p as usize) == v)
            .unwrap()
    };
    let tangents =
        |p: u32| binding.orientation_plan(0).knot_tangents(sampling.knot_sample(p as usize).unwrap() as usize).len();
    let adjustments = [
        Adjustment::new(0, knot(4))
            .with_translate([0.0, 0.0, 0.05])
            .with_rotate(Rotate::EulerXyz([10.0, 0.0, 30.0]))
            .with_scale([1.2, 1.0, 0.8]),
        Adjustment::new(0, knot(2)).with_rotate(Rotate::Quaternion([0.9, 0.1, 0.0, 0.3])).with_attach_tangents(false),
        Adjustment::new(0, knot(1)).with_tangent_translates(vec![[0.0, 0.0, 0.02]; tangents(knot(1))]),
    ];
    let before = counting::allocations();
    for rest in [None, Some(rest.as_slice())] {
        for adjustments in [&[][..], &adjustments[..]] {
            let input = curvenet_core::Frame { posed: &[Some(&pose)], rest, adjustments, ..Default::default() };
            binding.deform(&input, &mut ws, &mut out, Some(&mut grads)).unwrap();
        }
        let input = curvenet_core::Frame { posed: &[None], rest, adjustments: &adjustments, ..Default::default() };
        binding.deform(&input, &mut ws, &mut out, Some(&mut grads)).unwrap();
    }
    let after = counting::allocations();
    assert_eq!(after - before, 0, "Binding::deform allocated");
    assert!(out.iter().zip(&pts).any(|(o, p)| (o[2] - p[2]).abs() > 1e-3), "the frame moved the mesh");
}

fn curvenet_evaluation() {
    let (mesh, pts) = cylinder(1.0, -1.0, 4.0, 48, 30);
    let b = cylinder_net();
    let net = Curvenet::new(&b.splines, &b.points).unwrap();
    let layout = CurvenetLayout::new(&net, &mesh, &pts, &SamplingOptions::default()).unwrap();
    let r = rotation([0.2, 1.0, 0.3], 0.7);
    let pose: Vec<[f64; 3]> = b.points.iter().map(|&p| apply(&r, p)).collect();
    let mut samples = vec![[0.0; 3]; layout.n_samples()];
    let mut frames = vec![[ScaledFrame::default(); 2]; layout.n_segments()];
    let mut f: Vec<[Mat3; 2]> = vec![[[[0.0; 3]; 3]; 2]; layout.n_segments()];
    let mut fc: Vec<Mat3> = vec![[[0.0; 3]; 3]; layout.constraints().len()];

    let before = counting::allocations();
    for _ in 0..3 {
        layout.sampling().samples_into(&pose, &mut samples).unwrap();
        scaled_frames_into(&layout, &samples, &mut frames).unwrap();
        deformation_gradients_into(&layout, layout.neutral_frames(), &frames, &mut f).unwrap();
        constraint_gradients_into(layout.constraints(), &f, &mut fc).unwrap();
    }
    let after = counting::allocations();
    assert_eq!(after - before, 0, "the per-frame path allocated");

    // And it computed something: F = R on curves meeting an intersection.
    let s = layout.sampling().segments().iter().position(|s| !layout.curve_is_isolated(s.curve as usize)).unwrap();
    assert!(max_diff(&f[s][0], &r) < 1e-9);
    let slot = layout.constraints().slots().iter().position(|sl| !layout.curve_is_isolated(sl.curve as usize)).unwrap();
    assert!(max_diff(&fc[slot], &r) < 1e-9);
}
