//! Degenerate input gives typed errors naming the element, never a panic or NaN.

mod common;

use common::*;
use curvenet_core::curvenet::{deformation_gradients, scaled_frames};
use curvenet_core::{Curvenet, CurvenetLayout, Error, PolyMesh, SamplingOptions};

fn analyse(b: &NetBuilder) -> Result<CurvenetLayout, Error> {
    let (mesh, pts) = plane(3.0, 12);
    let net = Curvenet::new(&b.splines, &b.points)?;
    CurvenetLayout::new(&net, &mesh, &pts, &SamplingOptions::default())
}

#[test]
fn empty_out_of_range_non_finite() {
    let b = star();
    assert!(matches!(Curvenet::new(&[], &b.points), Err(Error::Empty { .. })));
    let mut splines = b.splines.clone();
    splines[3][2] = 999;
    assert_eq!(
        Curvenet::new(&splines, &b.points),
        Err(Error::IndexOutOfRange {
            what: "spline",
            index: 3,
            target: "control point",
            value: 999,
            len: b.points.len()
        })
    );
    let mut points = b.points.clone();
    points[4][0] = f64::NAN;
    assert!(matches!(Curvenet::new(&b.splines, &points), Err(Error::NonFinite { index: 4, .. })));
}

#[test]
fn zero_length_spline() {
    let mut b = star();
    let p = [0.5, 0.5, 0.0];
    let k = b.knot(p);
    let h = b.handle(p);
    let tip = b.knot(p.map(|x| x + 1e-14));
    b.splines.push([k, h, h, tip]);
    let n = b.splines.len() - 1;
    assert_eq!(analyse(&b).err(), Some(Error::ZeroLengthSpline { spline: n }));
}

#[test]
fn coincident_tangents_at_an_intersection() {
    // Two straight arms leaving the center along +x, of different lengths.
    let mut b = NetBuilder::default();
    b.segment([0.0; 3], [1.0, 0.0, 0.0], [0.0; 3]);
    b.segment([0.0, 1.0, 0.0], [0.0; 3], [0.0; 3]);
    b.segment([0.0; 3], [2.0, 0.0, 0.0], [0.0; 3]);
    b.segment([0.0; 3], [-1.0, -1.0, 0.0], [0.0; 3]);
    let center = b.knot([0.0; 3]);
    assert_eq!(analyse(&b).err(), Some(Error::CoincidentTangents { point: center, splines: [0, 2] }));

    // A T-junction's opposite tangents are fine.
    let mut t = NetBuilder::default();
    t.segment([-1.0, 0.0, 0.0], [0.0; 3], [0.0; 3]);
    t.segment([0.0; 3], [1.0, 0.0, 0.0], [0.0; 3]);
    t.segment([0.0; 3], [0.0, 1.0, 0.0], [0.0; 3]);
    assert!(analyse(&t).is_ok());
}

#[test]
fn tangent_along_the_surface_normal() {
    let mut b = NetBuilder::default();
    b.segment([-1.0, 0.0, 0.0], [0.0; 3], [0.0; 3]);
    b.segment([0.0; 3], [1.0, 0.0, 0.0], [0.0; 3]);
    b.segment([0.0; 3], [0.0, 0.0, 1.0], [0.0; 3]);
    let center = b.knot([0.0; 3]);
    assert_eq!(analyse(&b).err(), Some(Error::TangentAlongNormal { point: center, spline: 2 }));
}

#[test]
fn zero_area_surface_face_under_an_intersection() {
    let b = star();
    let net = Curvenet::new(&b.splines, &b.points).unwrap();
    let mesh = PolyMesh::new(&[3], &[0, 1, 2], 3).unwrap();
    let pts = [[-1.0, 0.0, -0.1], [0.0, 0.0, -0.1], [1.0, 0.0, -0.1]];
    let err = CurvenetLayout::new(&net, &mesh, &pts, &SamplingOptions::default()).err();
    assert_eq!(err, Some(Error::DegenerateSurfaceFace { point: b.splines[0][0], face: 0 }));
}

#[test]
fn bad_options_and_too_many_segments() {
    let b = star();
    let net = Curvenet::new(&b.splines, &b.points).unwrap();
    let (mesh, pts) = plane(3.0, 12);
    let err = CurvenetLayout::new(&net, &mesh, &pts, &SamplingOptions::default().with_density(0.0)).err();
    assert!(matches!(err, Some(Error::InvalidParameter { .. })));
    let err = CurvenetLayout::new(&net, &mesh, &pts, &SamplingOptions::default().with_density(1e9)).err();
    assert!(matches!(err, Some(Error::TooManySegments { spline: 0, .. })), "{err:?}");
}

#[test]
fn wrong_pool_and_buffer_lengths() {
    let b = star();
    let layout = analyse(&b).unwrap();
    let short = &b.points[..b.points.len() - 1];
    assert!(matches!(
        layout.sampling().samples(short),
        Err(Error::CountMismatch { expected, got, .. }) if expected == b.points.len() && got == b.points.len() - 1
    ));
    let mut out = vec![[0.0; 3]; layout.n_samples() + 1];
    assert!(matches!(layout.sampling().samples_into(&b.points, &mut out), Err(Error::CountMismatch { .. })));
    let mut bad = b.points.clone();
    bad[2][1] = f64::INFINITY;
    assert!(matches!(layout.sampling().samples(&bad), Err(Error::NonFinite { index: 2, .. })));
    assert!(matches!(scaled_frames(&layout, &layout.neutral_samples()[1..]), Err(Error::CountMismatch { .. })));
}

#[test]
fn posed_collapse_names_spline_and_segment() {
    let b = star();
    let layout = analyse(&b).unwrap();
    // Collapse spline 3 entirely onto its control point 0.
    let mut pose = b.points.clone();
    let sp = b.splines[3];
    for k in 1..4 {
        pose[sp[k] as usize] = pose[sp[0] as usize];
    }
    let samples = layout.sampling().samples(&pose).unwrap();
    assert!(samples.iter().flatten().all(|x| x.is_finite()));
    match deformation_gradients(&layout, layout.neutral_samples(), &samples) {
        Err(Error::SegmentCollapsed { spline: 3, segment, length }) => {
            assert!(segment < layout.sampling().spline_segments(3) as usize);
            assert!(length <= layout.collapse_length());
        }
        other => panic!("expected a collapsed segment of spline 3, got {other:?}"),
    }
}

#[test]
fn posed_collinear_intersection_is_an_error_not_nan() {
    // T-junction whose stem folds onto the right half of the bar.
    let mut b = NetBuilder::default();
    b.segment([-1.0, 0.0, 0.0], [0.0; 3], [0.0; 3]);
    b.segment([0.0; 3], [1.0, 0.0, 0.0], [0.0; 3]);
    b.segment([0.0; 3], [0.0, 1.0, 0.0], [0.0; 3]);
    let layout = analyse(&b).unwrap();
    let r = rotation([0.0, 0.0, 1.0], -std::f64::consts::FRAC_PI_2);
    let pose: Vec<[f64; 3]> = b.points.iter().map(|&p| if p[1] > 0.0 { apply(&r, p) } else { p }).collect();
    let samples = layout.sampling().samples(&pose).unwrap();
    let center = b.knot([0.0; 3]);
    assert_eq!(scaled_frames(&layout, &samples).err(), Some(Error::DegenerateIntersection { point: center }));

    // Nearly collinear (1e-7 rad) is still well defined and finite.
    let r = rotation([0.0, 0.0, 1.0], -std::f64::consts::FRAC_PI_2 + 1e-7);
    let pose: Vec<[f64; 3]> = b.points.iter().map(|&p| if p[1] > 0.0 { apply(&r, p) } else { p }).collect();
    let samples = layout.sampling().samples(&pose).unwrap();
    let f = deformation_gradients(&layout, layout.neutral_samples(), &samples).unwrap();
    assert!(f.iter().flatten().flatten().flatten().all(|x| x.is_finite()));
}
