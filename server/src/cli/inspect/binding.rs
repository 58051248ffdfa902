//! `inspect --bind`: every reported mesh bound to its curvenets as the bake
//! binds it, its counts, stage times and warnings (or its error), and its
//! lines of the text report.

use std::fmt::Write as _;

use curvenet_schema::MeshData;
use curvenet_schema::usd::Stage;
use curvenet_schema::wire::{BindingStats, BindingTimings};
use serde::Serialize;

use super::wording::plural;
use crate::cli::CliResult;

/// `inspect --bind`: what `Binding::new` built, and how long each stage took.
#[derive(Serialize)]
pub(super) struct BindingReport {
    /// `None` when the binding failed (then `error` says why).
    /// The same counts and times, by the same names, as the service's
    /// binding response (`schema::wire`).
    stats: Option<BindingStats>,
    timings: Option<BindingTimings>,
    pub(super) warnings: Vec<String>,
    pub(super) error: Option<String>,
}

/// Binds `m` as the bake does (`crate::cli::deformer`). A core error is part of
/// the report (the command then exits 2); a stage that breaks the contract is
/// an error of the command.
pub(super) fn binding_report(stage: &Stage, m: &MeshData) -> CliResult<BindingReport> {
    let nets = m.curvenets.iter().map(|p| stage.curvenet(p)).collect::<Result<Vec<_>, _>>()?;
    let start = std::time::Instant::now();
    // The binding is of the projection pose: the rig and the cage under it
    // change frames, not the binding (they are reported on their own).
    let bound = crate::cli::bind::deformer(m, &nets, None, None);
    let total_ms = start.elapsed().as_secs_f64() * 1e3;
    Ok(match bound {
        Ok(d) => BindingReport {
            stats: Some(BindingStats::from(&d.binding().stats())),
            timings: Some(BindingTimings::new(d.timings().analysis_ms, &d.binding().timings(), total_ms)),
            warnings: d.binding().warnings().iter().map(|w| w.to_string()).collect(),
            error: None,
        },
        Err(e) => BindingReport { stats: None, timings: None, warnings: Vec::new(), error: Some(e.to_string()) },
    })
}

pub(super) fn binding_text(s: &mut String, b: &BindingReport) {
    if let Some(e) = &b.error {
        let _ = writeln!(s, "  binding failed: {e}");
    }
    if let (Some(st), Some(t)) = (&b.stats, &b.timings) {
        let _ = writeln!(
            s,
            "  binding: {} samples, {} segments -> {} cut-vertices, {} cut-faces, {} cut-halfedges, {} crack{}, {} island{} removed",
            st.samples,
            st.segments,
            st.cut_vertices,
            st.cut_faces,
            st.cut_halfedges,
            st.cracks,
            plural(st.cracks),
            st.islands_removed,
            plural(st.islands_removed)
        );
        let _ = writeln!(
            s,
            "  segments embedded: {} inside one face, {} by straightest path, {} by fallback path, {} left out; {} detour{}",
            st.chord_paths,
            st.straightest_paths,
            st.fallback_paths,
            st.segments_left_out,
            st.detours,
            plural(st.detours)
        );
        let _ = writeln!(
            s,
            "  binding: {} unknowns, {} constraint rows, {} factor nonzeros",
            st.unknowns, st.constraints, st.factor_nonzeros
        );
        let _ = writeln!(
            s,
            "  binding time: {:.1} ms (analysis {:.1}, surface {:.1}, cutting {:.1}, assembly {:.1}, factor {:.1})",
            t.total_ms, t.analysis_ms, t.surface_ms, t.cutting_ms, t.assembly_ms, t.factor_ms
        );
    }
}
