//! The §3 analysis of one curvenet (its neutral pool against the surface of
//! the mesh that targets it): intersections, anchors, curves with their
//! sampling, the distance of the samples from the surface, the warnings it
//! raises, and its lines of the text report.

use std::collections::BTreeMap;
use std::fmt::Write as _;

use curvenet_core::CurveEnd;
use curvenet_core::Surface;
use curvenet_core::{Curvenet, CurvenetLayout, SamplingOptions};
use curvenet_schema::CurvenetData;
use serde::Serialize;

use super::wording::{list, plural};

/// A sample farther than this fraction of the mesh's bounding-box diagonal
/// from the surface is reported.
pub(super) const FAR_FROM_SURFACE: f64 = 0.05;

#[derive(Serialize)]
pub(super) struct Analysis {
    /// The mesh analysed against (its projection pose).
    mesh: String,
    mean_edge_length: f64,
    bounding_box_diagonal: f64,
    control_points: usize,
    /// Pool indices used by no spline.
    unused_control_points: Vec<u32>,
    splines: usize,
    intersections: Vec<IntersectionReport>,
    /// Number of intersections by valence (JSON keys are the valences).
    intersections_by_valence: BTreeMap<u32, usize>,
    /// Pool indices of the anchors (valence-1 endpoints).
    anchors: Vec<u32>,
    curves: Vec<CurveReport>,
    /// Indices into `curves` of the isolated closed curves.
    isolated_closed_curves: Vec<usize>,
    samples: usize,
    segments: usize,
    /// The largest distance of a neutral sample from the surface.
    max_distance_to_surface: f64,
    /// The spline of that sample.
    max_distance_spline: u32,
}

#[derive(Serialize)]
pub(super) struct IntersectionReport {
    /// The pool index of the intersection's control point.
    point: u32,
    valence: u32,
    /// Its (knot) sample.
    sample: u32,
    /// The curve ends there, counter-clockwise around the surface normal.
    curves_ccw: Vec<u32>,
}

#[derive(Serialize)]
pub(super) struct CurveReport {
    splines: Vec<CurveSplineReport>,
    start: EndReport,
    end: EndReport,
    /// Samples along the curve (an open curve counts both ends, an isolated
    /// closed curve its start once).
    samples: usize,
    segments: usize,
    /// Arc length of the neutral samples' polyline.
    length: f64,
}

#[derive(Serialize)]
pub(super) struct CurveSplineReport {
    spline: u32,
    reversed: bool,
}

#[derive(Serialize)]
pub(super) struct EndReport {
    /// `intersection`, `anchor` or `closed` (an isolated closed curve).
    kind: &'static str,
    point: u32,
}

impl From<CurveEnd> for EndReport {
    fn from(e: CurveEnd) -> Self {
        match e {
            CurveEnd::Intersection(point) => Self { kind: "intersection", point },
            CurveEnd::Anchor(point) => Self { kind: "anchor", point },
            CurveEnd::Closed(point) => Self { kind: "closed", point },
        }
    }
}

impl std::fmt::Display for EndReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.kind {
            "closed" => write!(f, "closed at {}", self.point),
            kind => write!(f, "{kind} {}", self.point),
        }
    }
}

/// The analysis of one curvenet (neutral pool) against `surface`.
pub(super) fn analyse(
    c: &CurvenetData,
    mesh_path: &str,
    surface: &Surface,
    unused_control_points: Vec<u32>,
    warnings: &mut Vec<String>,
) -> Result<Analysis, curvenet_core::Error> {
    let net = Curvenet::new(&c.splines, &c.pool)?;
    let options = SamplingOptions::default().with_density(c.sample_density);
    let layout =
        CurvenetLayout::with_closest_point(&net, surface.closest_points(), surface.mean_edge_length(), &options)?;
    let topology = layout.topology();
    let sampling = layout.sampling();
    let samples = layout.neutral_samples();

    let intersections: Vec<IntersectionReport> = layout
        .intersections()
        .iter()
        .map(|fan| IntersectionReport {
            point: fan.point(),
            valence: topology.valence(fan.point() as usize),
            sample: fan.sample(),
            curves_ccw: fan.emanations().iter().map(|e| e.curve).collect(),
        })
        .collect();
    let mut intersections_by_valence = BTreeMap::new();
    for i in &intersections {
        *intersections_by_valence.entry(i.valence).or_insert(0) += 1;
    }

    let dist =
        |a: [f64; 3], b: [f64; 3]| ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt();
    let mut curves = Vec::with_capacity(topology.curves().len());
    for (k, curve) in topology.curves().iter().enumerate() {
        let segs = sampling.curve_segments(k);
        let n_segments = segs.len();
        let length: f64 = sampling.segments()[segs]
            .iter()
            .map(|s| dist(samples[s.samples[0] as usize], samples[s.samples[1] as usize]))
            .sum();
        let splines: Vec<CurveSplineReport> =
            curve.splines.iter().map(|s| CurveSplineReport { spline: s.spline, reversed: s.reversed }).collect();
        let names = spline_list(&splines);
        if length < surface.mean_edge_length() {
            warnings.push(format!(
                "{}: curve {k} (spline{} {names}) is {length:.4} long, shorter than one mean mesh edge ({:.4})",
                c.path,
                plural(splines.len()),
                surface.mean_edge_length()
            ));
        }
        if n_segments < 2 {
            warnings.push(format!(
                "{}: curve {k} (spline{} {names}) has {n_segments} segment; fewer than 2 leaves it no interior sample",
                c.path,
                plural(splines.len())
            ));
        }
        curves.push(CurveReport {
            splines,
            start: curve.start.into(),
            end: curve.end.into(),
            samples: sampling.curve_samples(k).len(),
            segments: n_segments,
            length,
        });
    }

    // Distance of every neutral sample from the surface, worst per spline.
    let distances = samples
        .iter()
        .map(|&p| surface.closest_points().closest_point(p).map(|h| h.distance))
        .collect::<Result<Vec<f64>, _>>()?;
    let limit = FAR_FROM_SURFACE * surface.diagonal();
    let (mut max_distance, mut max_spline) = (0.0f64, 0u32);
    for s in 0..c.splines.len() {
        let (sample, d) = sampling
            .spline_samples(s)
            .map(|q| (q, distances[q as usize]))
            .fold((0, f64::NEG_INFINITY), |a, b| if b.1 > a.1 { b } else { a });
        if d > max_distance {
            (max_distance, max_spline) = (d, s as u32);
        }
        if d > limit {
            warnings.push(format!(
                "{}: spline {s} is {d:.4} from the surface of {} at sample {sample} ({:.1}% of its bounding-box \
                 diagonal {:.4}; the limit is {:.0}%)",
                c.path,
                mesh_path,
                100.0 * d / surface.diagonal(),
                surface.diagonal(),
                100.0 * FAR_FROM_SURFACE
            ));
        }
    }

    Ok(Analysis {
        mesh: mesh_path.to_string(),
        mean_edge_length: surface.mean_edge_length(),
        bounding_box_diagonal: surface.diagonal(),
        control_points: c.pool.len(),
        unused_control_points,
        splines: c.splines.len(),
        intersections,
        intersections_by_valence,
        anchors: topology.anchors().to_vec(),
        curves,
        isolated_closed_curves: topology.isolated_closed_curves().collect(),
        samples: layout.n_samples(),
        segments: layout.n_segments(),
        max_distance_to_surface: max_distance,
        max_distance_spline: max_spline,
    })
}

fn spline_list(splines: &[CurveSplineReport]) -> String {
    let s: Vec<String> = splines
        .iter()
        .map(|s| if s.reversed { format!("{} (reversed)", s.spline) } else { s.spline.to_string() })
        .collect();
    s.join(", ")
}

pub(super) fn analysis_text(s: &mut String, a: &Analysis) {
    let by_valence: Vec<String> =
        a.intersections_by_valence.iter().rev().map(|(v, n)| format!("{n} of valence {v}")).collect();
    let _ = writeln!(
        s,
        "  analysis against {} (neutral pool, projection pose): {} intersections ({}), {} anchors, {} curves, \
         {} isolated closed curve{}, {} samples, {} segments",
        a.mesh,
        a.intersections.len(),
        if by_valence.is_empty() { "none".to_string() } else { by_valence.join(", ") },
        a.anchors.len(),
        a.curves.len(),
        a.isolated_closed_curves.len(),
        plural(a.isolated_closed_curves.len()),
        a.samples,
        a.segments
    );
    let _ = writeln!(
        s,
        "  farthest sample from the surface: {:.4} ({:.2}% of the diagonal {:.4}), on spline {}; unused control points: {}",
        a.max_distance_to_surface,
        100.0 * a.max_distance_to_surface / a.bounding_box_diagonal,
        a.bounding_box_diagonal,
        a.max_distance_spline,
        if a.unused_control_points.is_empty() { "none".to_string() } else { list(&a.unused_control_points) }
    );
    for i in &a.intersections {
        let curves: Vec<String> = i.curves_ccw.iter().map(|c| c.to_string()).collect();
        let _ = writeln!(
            s,
            "  intersection at control point {}: valence {}, sample {}, curves counter-clockwise {}",
            i.point,
            i.valence,
            i.sample,
            curves.join(", ")
        );
    }
    if !a.anchors.is_empty() {
        let anchors: Vec<String> = a.anchors.iter().map(|p| p.to_string()).collect();
        let _ = writeln!(s, "  anchors at control points {}", anchors.join(", "));
    }
    for (k, c) in a.curves.iter().enumerate() {
        let ends = if c.start.kind == "closed" { c.start.to_string() } else { format!("{} to {}", c.start, c.end) };
        let _ = writeln!(
            s,
            "  curve {k}: {ends}, spline{} {}, {} samples, {} segments, length {:.4}",
            plural(c.splines.len()),
            spline_list(&c.splines),
            c.samples,
            c.segments,
            c.length
        );
    }
    if !a.isolated_closed_curves.is_empty() {
        let closed: Vec<String> = a.isolated_closed_curves.iter().map(|c| c.to_string()).collect();
        let _ = writeln!(s, "  isolated closed curves: {}", closed.join(", "));
    }
}
