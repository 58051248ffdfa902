//! Process-wide counters of the binding's expensive steps, for tests that
//! check a frame never rebuilds the binding (`tests/rebuild_count.rs`).
//! Compiled only with the `counters` feature, so library builds carry no
//! test instrumentation.

use std::sync::atomic::{AtomicUsize, Ordering};

static CUT_MESH_BUILDS: AtomicUsize = AtomicUsize::new(0);
static NUMERIC_FACTORIZATIONS: AtomicUsize = AtomicUsize::new(0);
static LANE_ROW_GROUPS: AtomicUsize = AtomicUsize::new(0);

/// How many cut-meshes this process has built.
pub fn cut_mesh_builds() -> usize {
    CUT_MESH_BUILDS.load(Ordering::Relaxed)
}

/// How many numeric factorisations this process has computed.
pub fn numeric_factorizations() -> usize {
    NUMERIC_FACTORIZATIONS.load(Ordering::Relaxed)
}

/// How many groups of frames made their constraint rows lane by lane
/// (`Binding::lanes_rows`), rather than frame by frame.
pub fn lane_row_groups() -> usize {
    LANE_ROW_GROUPS.load(Ordering::Relaxed)
}

pub(crate) fn lane_rows_made() {
    LANE_ROW_GROUPS.fetch_add(1, Ordering::Relaxed);
}

pub(crate) fn cut_mesh_built() {
    CUT_MESH_BUILDS.fetch_add(1, Ordering::Relaxed);
}

pub(crate) fn numeric_factorization_done() {
    NUMERIC_FACTORIZATIONS.fetch_add(1, Ordering::Relaxed);
}
