//! What a warning or a refused binding is about, as the viewer highlights
//! it: the curvenet elements (segments, a spline, a sample, a control
//! point) and the mesh elements (faces, vertices) a core error or warning
//! names, turned into geometry to draw (lines, markers, face triangles) and
//! a box to frame.
//!
//! The elements come from the typed core values (`curvenet_core::Error`,
//! `BindWarning` through the wire `Warning`), never from parsing messages.
//! Segments are numbered as everywhere: (curvenet, spline, segment within
//! the spline from its control point 0).

use curvenet_core::Surface;
use curvenet_core::{CurvenetLayout, Error};
use curvenet_schema::wire::{SegmentId, Warning};
use serde::Serialize;
use utoipa::ToSchema;

/// Points per spline when a curvenet is drawn from its Bézier control
/// points (a refused binding whose curvenet could not be sampled).
pub const SPLINE_POINTS: usize = 24;

/// An element to highlight: what a warning or a refusal names, with its
/// geometry in the projection pose.
#[derive(Debug, Clone, Default, Serialize, ToSchema)]
pub struct Highlight {
    /// The warning's code, or the refusal's error code.
    pub code: String,
    pub message: String,
    /// The most specific element named: `segment`, `sample`, `spline`,
    /// `control_point`, `faces`, `vertices`, or `none` (nothing to point at).
    pub element: String,
    /// The curvenet (binding order) of the curvenet elements below.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub curvenet: Option<u32>,
    /// Splines of `curvenet`.
    pub splines: Vec<u32>,
    /// Segments (each naming its own curvenet).
    pub segments: Vec<SegmentId>,
    /// A sample of `curvenet` (its index among the curvenet's samples).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sample: Option<u32>,
    /// A control point of `curvenet`'s pool.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub control_point: Option<u32>,
    /// Input faces.
    pub faces: Vec<u32>,
    /// Mesh vertices.
    pub vertices: Vec<u32>,
    /// The highlighted segments as pairs of sample indices of their
    /// curvenet, per curvenet (`[curvenet, a, b, curvenet, a, b, ...]`),
    /// when the curvenet was sampled: the viewer draws them in every pose.
    pub sample_segments: Vec<u32>,
    /// Lines in the projection pose, flat `f32` endpoint pairs: the
    /// highlighted splines, and segments that have no samples.
    pub lines: Vec<f32>,
    /// Markers in the projection pose, flat `f32` xyz: positions named by
    /// the error or warning, samples, control points, vertices.
    pub points: Vec<f32>,
    /// Triangles of the highlighted faces (mesh vertex triples, flat).
    pub triangles: Vec<u32>,
    /// The box to frame, `[min x, min y, min z, max x, max y, max z]` in the
    /// projection pose; absent when nothing has a place.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub bounds: Option<[f32; 6]>,
}

/// One curvenet as the highlights see it.
pub struct NetGeometry<'a> {
    pub pool: &'a [[f64; 3]],
    pub splines: &'a [[u32; 4]],
    /// Its analysis against the surface, when that succeeded.
    pub layout: Option<&'a CurvenetLayout>,
}

/// The input a highlight is looked up in: the mesh in its projection pose,
/// the surface when it could be built, the curvenets.
pub struct Scene<'a> {
    pub points: &'a [[f64; 3]],
    /// The input faces' corners (`None` for a face whose corners are out
    /// of range); read only when there is no surface.
    pub faces: Vec<Option<&'a [u32]>>,
    pub surface: Option<&'a Surface>,
    pub nets: Vec<NetGeometry<'a>>,
}

impl Scene<'_> {
    /// Input faces from raw face arrays: each face's corners, `None` where
    /// the arrays end early or a corner is no vertex.
    pub fn raw_faces<'b>(counts: &[u32], indices: &'b [u32], n_points: usize) -> Vec<Option<&'b [u32]>> {
        let mut start = 0usize;
        counts
            .iter()
            .map(|&n| {
                let face = indices.get(start..start.saturating_add(n as usize));
                start = start.saturating_add(n as usize);
                face.filter(|f| f.iter().all(|&v| (v as usize) < n_points))
            })
            .collect()
    }

    /// Triangles of input faces `faces`: the surface's own triangulation
    /// when there is a surface, else a fan per face.
    pub fn face_triangles(&self, faces: &[u32]) -> Vec<u32> {
        let mut out = Vec::new();
        if let Some(s) = self.surface {
            let mut wanted = faces.to_vec();
            wanted.sort_unstable();
            for (t, f) in s.triangles() {
                if wanted.binary_search(&f).is_ok() {
                    out.extend(t);
                }
            }
            return out;
        }
        for &f in faces {
            if let Some(Some(face)) = self.faces.get(f as usize) {
                for k in 1..face.len().saturating_sub(1) {
                    out.extend([face[0], face[k], face[k + 1]]);
                }
            }
        }
        out
    }

    /// The Bézier polyline of spline `s` of curvenet `k` (`SPLINE_POINTS` points).
    pub fn spline_polyline(&self, k: usize, s: usize) -> Vec<[f64; 3]> {
        let Some(net) = self.nets.get(k) else { return Vec::new() };
        let Some(cv) = net.splines.get(s) else { return Vec::new() };
        let Some(p) = cv.iter().map(|&i| net.pool.get(i as usize).copied()).collect::<Option<Vec<_>>>() else {
            return Vec::new();
        };
        (0..SPLINE_POINTS)
            .map(|i| {
                let t = i as f64 / (SPLINE_POINTS - 1) as f64;
                let u = 1.0 - t;
                let w = [u * u * u, 3.0 * u * u * t, 3.0 * u * t * t, t * t * t];
                std::array::from_fn(|c| (0..4).map(|j| w[j] * p[j][c]).sum())
            })
            .collect()
    }

    /// The sample pair of segment `seg` of spline `s` of curvenet `k`, if it was sampled.
    fn segment_samples(&self, k: usize, s: u32, seg: u32) -> Option<[u32; 2]> {
        let layout = self.nets.get(k)?.layout?;
        let sampling = layout.sampling();
        if s as usize >= sampling.splines().len() || seg >= sampling.spline_segments(s as usize) {
            return None;
        }
        let samples: Vec<u32> = sampling.spline_samples(s as usize).collect();
        Some([samples[seg as usize], samples[seg as usize + 1]])
    }

    fn sample_position(&self, k: usize, i: u32) -> Option<[f64; 3]> {
        self.nets.get(k)?.layout?.neutral_samples().get(i as usize).copied()
    }

    /// The highlight of a core error: the element it names.
    pub fn error(&self, e: &Error, code: &str, message: &str) -> Highlight {
        let mut h = Highlight { code: code.into(), message: message.into(), ..Highlight::default() };
        self.name_error(e, &mut h);
        self.finish(h)
    }

    fn name_error(&self, e: &Error, h: &mut Highlight) {
        let seg = |s: &curvenet_core::SegmentRef| SegmentId::from(*s);
        match e {
            Error::Curvenet { curvenet, source } => {
                h.curvenet = Some(*curvenet);
                self.name_error(source, h);
            }
            Error::RestPose { source } => self.name_error(source, h),
            Error::SampleFarFromSurface { at, position, .. } => {
                h.curvenet = Some(at.curvenet);
                h.splines.push(at.spline);
                h.sample = Some(at.sample);
                h.points.extend(position.map(|x| x as f32));
            }
            Error::SegmentNotTraced { segment } => h.segments.push(seg(segment)),
            Error::SegmentDetour { segment, position, .. } => {
                h.segments.push(seg(segment));
                h.points.extend(position.map(|x| x as f32));
            }
            Error::CurvesOverlap { segment, other } => h.segments.extend([seg(segment), seg(other)]),
            Error::CurvesCross { segment, other, face } => {
                h.segments.extend([seg(segment), seg(other)]);
                h.faces.push(self.input_face(*face));
            }
            Error::SegmentCrossesFaceBoundary { segment, face } => {
                h.segments.push(seg(segment));
                h.faces.push(self.input_face(*face));
            }
            Error::CurveCollapsedOnSurface { segment, position } => {
                h.segments.push(seg(segment));
                h.points.extend(position.map(|x| x as f32));
            }
            Error::UntouchedComponent { component, .. } => {
                if let Some(s) = self.surface {
                    let components = s.components();
                    let mut faces: Vec<u32> = (0..s.mesh().n_faces() as u32)
                        .filter(|&f| components.of_face(f) as usize == *component)
                        .map(|f| s.input_face(f))
                        .collect();
                    faces.dedup();
                    h.faces = faces;
                }
            }
            Error::NonManifoldEdge { a, b, faces, .. } => {
                h.faces.extend(faces);
                h.vertices.extend([*a, *b]);
            }
            Error::InconsistentOrientation { a, b, faces } => {
                h.faces.extend(faces);
                h.vertices.extend([*a, *b]);
            }
            Error::NonManifoldVertex { vertex, .. } => h.vertices.push(*vertex),
            Error::CoincidentFaceVertices { face, a, b } => {
                h.faces.push(*face as u32);
                h.vertices.extend([*a, *b]);
            }
            Error::ZeroAreaFace { face, vertices, .. } | Error::IllConditionedFace { face, vertices, .. } => {
                h.faces.push(*face as u32);
                h.vertices.extend(vertices);
            }
            Error::FoldedFace { face } | Error::DegenerateFaceCount { face, .. } => h.faces.push(*face as u32),
            Error::RepeatedFaceVertex { face, vertex } => {
                h.faces.push(*face as u32);
                h.vertices.push(*vertex);
            }
            Error::DegenerateSurfaceFace { point, face } => {
                h.control_point = Some(*point);
                h.faces.push(self.input_face(*face as u32));
            }
            Error::ZeroLengthSpline { spline } | Error::TooManySegments { spline, .. } => {
                h.splines.push(*spline as u32)
            }
            Error::CoincidentTangents { point, splines } => {
                h.control_point = Some(*point);
                h.splines.extend(splines.map(|s| s as u32));
            }
            Error::TangentAlongNormal { point, spline } => {
                h.control_point = Some(*point);
                h.splines.push(*spline as u32);
            }
            Error::SegmentCollapsed { spline, segment, .. } => {
                if let Some(k) = h.curvenet {
                    h.segments.push(SegmentId { curvenet: k, spline: *spline as u32, segment: *segment as u32 });
                } else {
                    h.splines.push(*spline as u32);
                }
            }
            Error::DegenerateIntersection { point } | Error::UndeterminedKnotOrientation { point } => {
                h.control_point = Some(*point)
            }
            _ => {}
        }
    }

    /// A surface face's input face (the same number unless faces were split).
    fn input_face(&self, f: u32) -> u32 {
        match self.surface {
            Some(s) if (f as usize) < s.mesh().n_faces() => s.input_face(f),
            _ => f,
        }
    }

    /// The highlight of a binding warning (as the wire carries it).
    pub fn warning(&self, w: &Warning) -> Highlight {
        let mut h = Highlight { code: w.code.clone(), message: w.message.clone(), ..Highlight::default() };
        if let Some(s) = &w.segment {
            h.segments.push(SegmentId { curvenet: s.curvenet, spline: s.spline, segment: s.segment });
            h.points.extend(s.position.map(|x| x as f32));
        }
        for t in &w.touches {
            for s in [t.segment, t.other] {
                if !h.segments.contains(&s) {
                    h.segments.push(s);
                }
            }
            h.points.extend(t.position.map(|x| x as f32));
        }
        h.faces.extend(&w.faces);
        if let Some(c) = w.component {
            self.name_error(&Error::UntouchedComponent { component: c, vertices: 0 }, &mut h);
        }
        self.finish(h)
    }

    /// Fills in the geometry of the named elements, the element kind and the bounds.
    pub fn finish(&self, mut h: Highlight) -> Highlight {
        let k = h.curvenet.map(|k| k as usize);
        for s in h.segments.clone() {
            match self.segment_samples(s.curvenet as usize, s.spline, s.segment) {
                Some([a, b]) => {
                    h.sample_segments.extend([s.curvenet, a, b]);
                    for i in [a, b] {
                        if let Some(p) = self.sample_position(s.curvenet as usize, i) {
                            grow(&mut h.bounds, p);
                        }
                    }
                }
                // Not sampled: the whole spline stands for it.
                None => push_polyline(&mut h, &self.spline_polyline(s.curvenet as usize, s.spline as usize)),
            }
        }
        if let Some(k) = k {
            for s in h.splines.clone() {
                push_polyline(&mut h, &self.spline_polyline(k, s as usize));
            }
            if let Some(i) = h.sample
                && h.points.is_empty()
                && let Some(p) = self.sample_position(k, i)
            {
                h.points.extend(p.map(|x| x as f32));
            }
            if let Some(p) = h.control_point.and_then(|i| self.nets.get(k)?.pool.get(i as usize).copied()) {
                h.points.extend(p.map(|x| x as f32));
            }
        }
        for &v in &h.vertices {
            if let Some(p) = self.points.get(v as usize) {
                h.points.extend(p.map(|x| x as f32));
            }
        }
        h.triangles = self.face_triangles(&h.faces);
        for &v in &h.triangles {
            if let Some(&p) = self.points.get(v as usize) {
                grow(&mut h.bounds, p);
            }
        }
        for p in h.points.chunks_exact(3).chain(h.lines.chunks_exact(3)) {
            grow(&mut h.bounds, [p[0] as f64, p[1] as f64, p[2] as f64]);
        }
        h.element = if !h.segments.is_empty() {
            "segment"
        } else if h.sample.is_some() {
            "sample"
        } else if !h.splines.is_empty() {
            "spline"
        } else if h.control_point.is_some() {
            "control_point"
        } else if !h.faces.is_empty() {
            "faces"
        } else if !h.vertices.is_empty() {
            "vertices"
        } else {
            "none"
        }
        .into();
        h
    }
}

fn push_polyline(h: &mut Highlight, line: &[[f64; 3]]) {
    for w in line.windows(2) {
        for p in w {
            h.lines.extend(p.map(|x| x as f32));
        }
    }
}

fn grow(bounds: &mut Option<[f32; 6]>, p: [f64; 3]) {
    let p = p.map(|x| x as f32);
    if !p.iter().all(|x| x.is_finite()) {
        return;
    }
    let b = bounds.get_or_insert([p[0], p[1], p[2], p[0], p[1], p[2]]);
    for c in 0..3 {
        b[c] = b[c].min(p[c]);
        b[c + 3] = b[c + 3].max(p[c]);
    }
}
