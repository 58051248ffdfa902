//! Binding stage 2b: what cutting found out about how the curvenet was
//! drawn — input faces split because they fold over themselves, curves whose
//! projections touch without a shared knot, segments bound along a detour —
//! as warnings, or with `strict` as the error of the first (a stretch of two
//! curves first, as the graver).

use glam::DVec3;

use crate::curvenet::CurvenetLayout;
use crate::error::{Error, Result};

use super::cut::{CutMesh, Touch};
use super::join::Joined;
use super::locate::Location;
use super::parts::BindWarning;
use super::surface::Surface;

pub(crate) fn check_drawing(
    surface: &Surface,
    cut: &CutMesh,
    joined: &Joined,
    curvenets: &[&CurvenetLayout],
    strict: bool,
) -> Result<Vec<BindWarning>> {
    let mut warnings = Vec::new();
    if !surface.split_faces().is_empty() {
        warnings.push(BindWarning::FacesSplit { faces: surface.split_faces().to_vec() });
    }
    let segment_ref = &joined.segment_ref;
    let worst = cut.touches().iter().find(|t| t.stretch).or(cut.touches().first());
    if let Some(first) = worst {
        let at = |t: &Touch| {
            (segment_ref[t.segment as usize], segment_ref[t.other as usize], cut.vertex(t.vertex).pos.to_array())
        };
        if strict {
            let (segment, other, _) = at(first);
            let face = match cut.vertex(first.vertex).loc {
                Location::Face { face, .. } => face,
                loc => {
                    let mut faces = Vec::new();
                    surface.faces_of(loc, &mut faces);
                    faces.first().copied().unwrap_or(0)
                }
            };
            return Err(if first.stretch {
                Error::CurvesOverlap { segment, other }
            } else {
                Error::CurvesCross { segment, other, face: surface.input_face(face) }
            });
        }
        let touches = cut.touches();
        warnings.push(BindWarning::CurvesTouch {
            count: touches.len(),
            examples: touches.iter().take(BindWarning::EXAMPLES).map(at).collect(),
        });
    }
    for d in cut.detours() {
        let seg = segment_ref[d.segment as usize];
        let layout = curvenets[seg.curvenet as usize];
        let n = layout.sampling().spline_segments(seg.spline as usize).max(1) as f64;
        let [i, j] = joined.segments[d.segment as usize];
        let (qi, qj) = (DVec3::from_array(joined.samples[i as usize]), DVec3::from_array(joined.samples[j as usize]));
        let (t, position) = ((seg.segment as f64 + 0.5) / n, ((qi + qj) * 0.5).to_array());
        let (path_length, segment_length) = (d.path_length, d.segment_length);
        if strict {
            return Err(Error::SegmentDetour { segment: seg, t, position, path_length, segment_length });
        }
        warnings.push(BindWarning::SegmentDetour { segment: seg, t, position, path_length, segment_length });
    }
    Ok(warnings)
}
