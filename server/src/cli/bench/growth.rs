//! The growth row of `curvenet bench` (unless `--no-growth`): the 94k hand
//! (`--growth-mesh`) subdivided once 1-to-4 at run time (not committed: a
//! 376k-vertex stage is too large) and bound to the same curvenets.
//!
//! Subdivision: every edge gets its midpoint; a triangle becomes its three
//! corner triangles and the middle one; any other face (the hands are all
//! triangles) becomes one quad per corner around its vertex centroid. Midpoints lie
//! on the original flat triangles, so the surface the curvenets project onto is
//! unchanged and only the density grows.
//!
//! Measured: `Deformer::new` (binding wall time less the analysis,
//! medians of `--growth-repeats`), frames through `Deformer::frame`
//! (`--growth-frames`, the bench's finger curl, after one warm-up), factor
//! nonzeros, the binding's heap bytes per vertex, and the peak resident
//! memory of this part: the process's high-water mark (`VmHWM` in
//! `/proc/self/status`) after resetting it (writing 5 to
//! `/proc/self/clear_refs`) before the first binding; when the reset is
//! refused the process-wide peak is reported and `peak_rss_reset` is false.
//! The targets of the issue: binding ≤ 1.5 s, a frame ≤ 4.5× the base
//! mesh's frame median of the same run.

use std::collections::HashMap;
use std::path::Path;

use curvenet_schema::{CurvenetData, MeshData};
use serde::Serialize;

use super::inputs::{TriSolve, build, load, pose};
use super::measure::{Stopwatch, median, ms_since};
use crate::cli::{CliError, CliResult};
use curvenet_core::Frame;

/// Binding target (ms) and frame target (× the base frame).
const BINDING_TARGET_MS: f64 = 1500.0;
const FRAME_TARGET_RATIO: f64 = 4.5;

#[derive(Serialize)]
pub(super) struct GrowthBench {
    /// The base fixture and how it was grown.
    pub base: String,
    pub subdivision: &'static str,
    pub vertices: usize,
    pub faces: usize,
    pub unknowns: usize,
    pub factor_nonzeros: usize,
    pub ordering: &'static str,
    pub subdivide_ms: f64,
    pub repeats: usize,
    pub analysis_ms: f64,
    /// `Deformer::new` less the analysis, median.
    pub binding_ms: f64,
    pub surface_ms: f64,
    pub cutting_ms: f64,
    pub assembly_ms: f64,
    pub factor_ms: f64,
    pub binding_other_ms: f64,
    pub frames: usize,
    pub solve_ms: f64,
    /// The frame's two triangular solves (9 and 3 columns) on random
    /// right-hand sides, timed right after each frame (medians), as the
    /// per-mesh rows' `tri9_ms` and `tri3_ms`.
    pub tri9_ms: f64,
    pub tri3_ms: f64,
    /// The base mesh's frame median in this run, if it was benched.
    pub base_solve_ms: Option<f64>,
    pub solve_over_base: Option<f64>,
    pub binding_bytes: usize,
    pub binding_bytes_per_vertex: f64,
    pub peak_rss_bytes: Option<u64>,
    pub peak_rss_reset: bool,
    pub binding_target_ms: f64,
    pub binding_met: bool,
    pub frame_target_ratio: f64,
    pub frame_met: Option<bool>,
    /// The grown deformer written in the store's format and read back
    /// (`bench/stored.rs`), against its full `Deformer::new` (median).
    pub stored: super::stored::StoredBench,
    /// AMD against METIS on the grown binding's matrix (with `--orderings`).
    pub orderings: Option<super::ordering::OrderingComparison>,
}

/// `mesh` subdivided once 1-to-4 (module docs).
pub(super) fn subdivide(mesh: &MeshData) -> CliResult<MeshData> {
    let pts = &mesh.projection_points;
    let mut points = pts.clone();
    let mut midpoint: HashMap<(u32, u32), u32> = HashMap::new();
    let mut mid = |a: u32, b: u32, points: &mut Vec<[f64; 3]>| -> u32 {
        let key = (a.min(b), a.max(b));
        *midpoint.entry(key).or_insert_with(|| {
            let (p, q) = (pts[a as usize], pts[b as usize]);
            points.push([0.5 * (p[0] + q[0]), 0.5 * (p[1] + q[1]), 0.5 * (p[2] + q[2])]);
            (points.len() - 1) as u32
        })
    };
    let (mut counts, mut indices) = (Vec::new(), Vec::new());
    let mut start = 0usize;
    for (f, &c) in mesh.face_vertex_counts.iter().enumerate() {
        let c = c as usize;
        let face = mesh
            .face_vertex_indices
            .get(start..start + c)
            .ok_or_else(|| CliError::Input(format!("{}: face {f} runs past faceVertexIndices", mesh.path)))?;
        start += c;
        if let Some(&v) = face.iter().find(|&&v| v as usize >= pts.len()) {
            return Err(CliError::Input(format!("{}: face {f} names vertex {v} of {}", mesh.path, pts.len())));
        }
        let m: Vec<u32> = (0..c).map(|i| mid(face[i], face[(i + 1) % c], &mut points)).collect();
        if c == 3 {
            for i in 0..3 {
                counts.push(3);
                indices.extend([face[i], m[i], m[(i + 2) % 3]]);
            }
            counts.push(3);
            indices.extend([m[0], m[1], m[2]]);
        } else {
            let mut centre = [0.0; 3];
            for &v in face {
                for k in 0..3 {
                    centre[k] += pts[v as usize][k] / c as f64;
                }
            }
            points.push(centre);
            let ci = (points.len() - 1) as u32;
            for i in 0..c {
                counts.push(4);
                indices.extend([face[i], m[i], ci, m[(i + c - 1) % c]]);
            }
        }
    }
    Ok(MeshData {
        path: format!("{} (subdivided 1-to-4)", mesh.path),
        face_vertex_counts: counts,
        face_vertex_indices: indices,
        projection_points: points,
        rest_sample_times: Vec::new(),
        curvenets: mesh.curvenets.clone(),
        blend_shapes: Vec::new(),
        blend_shape_animation: None,
    })
}

/// Resets the process's peak resident memory (`VmHWM`); false when refused.
fn reset_peak_rss() -> bool {
    std::fs::write("/proc/self/clear_refs", "5").is_ok()
}

/// The process's peak resident memory in bytes (`VmHWM`), if readable.
fn peak_rss_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

pub(super) fn bench_growth(
    base_name: &str,
    file: &Path,
    repeats: usize,
    frames: usize,
    base_solve_ms: Option<f64>,
    orderings: bool,
) -> CliResult<GrowthBench> {
    let (base, nets, _) = load(file)?;
    let t = std::time::Instant::now();
    let mesh = subdivide(&base)?;
    let subdivide_ms = ms_since(t);
    drop(base);
    let context = format!("{} {}", file.display(), mesh.path);
    let peak_rss_reset = reset_peak_rss();
    let (mut analysis, mut binding, mut factor, mut whole) = (vec![], vec![], vec![], vec![]);
    let (mut surface, mut cutting, mut assembly, mut other) = (vec![], vec![], vec![], vec![]);
    let mut bound = None;
    for _ in 0..repeats.max(1) {
        drop(bound.take());
        let (deformer, lap) = build(&mesh, &nets, &context)?;
        let tm = deformer.timings();
        analysis.push(tm.analysis_ms);
        let b = tm.binding;
        whole.push(lap.wall_ms);
        let wall = lap.wall_ms - tm.analysis_ms;
        binding.push(wall);
        surface.push(b.surface_ms);
        cutting.push(b.cutting_ms);
        assembly.push(b.assembly_ms);
        factor.push(b.factor_ms);
        other.push(wall - (b.surface_ms + b.cutting_ms + b.assembly_ms + b.factor_ms));
        bound = Some(deformer);
    }
    let deformer = bound.expect("at least one binding");
    let (frame_times, tri9_ms, tri3_ms) = solve_frames(&deformer, &nets, frames, &context)?;
    let peak = peak_rss_bytes();
    let stored = {
        let pools = pose(&nets, 1, 4);
        let posed: Vec<Option<&[[f64; 3]]>> = pools.iter().map(|p| Some(p.as_slice())).collect();
        super::stored::measure(&deformer, median(whole), repeats, &posed)?
    };
    let b = deformer.binding();
    // After the peak is read: the comparison's two extra factors are not the binding's memory.
    let orderings = if orderings { Some(super::ordering::compare(b, repeats.max(1), frames.max(1))?) } else { None };
    let stats = b.stats();
    let bytes = b.heap_bytes();
    let (binding_ms, solve_ms) = (median(binding), median(frame_times));
    let solve_over_base = base_solve_ms.filter(|&s| s > 0.0).map(|s| solve_ms / s);
    Ok(GrowthBench {
        base: base_name.to_string(),
        subdivision: "1-to-4 midpoint (triangles), once",
        stored,
        vertices: stats.mesh_vertices,
        faces: stats.mesh_faces,
        unknowns: stats.unknowns,
        factor_nonzeros: stats.factor_nonzeros,
        ordering: b.factor().ordering().name(),
        subdivide_ms,
        repeats: repeats.max(1),
        analysis_ms: median(analysis),
        binding_ms,
        surface_ms: median(surface),
        cutting_ms: median(cutting),
        assembly_ms: median(assembly),
        factor_ms: median(factor),
        binding_other_ms: median(other),
        frames,
        solve_ms,
        tri9_ms,
        tri3_ms,
        base_solve_ms,
        solve_over_base,
        binding_bytes: bytes,
        binding_bytes_per_vertex: bytes as f64 / stats.mesh_vertices.max(1) as f64,
        peak_rss_bytes: peak,
        peak_rss_reset,
        binding_target_ms: BINDING_TARGET_MS,
        binding_met: binding_ms <= BINDING_TARGET_MS,
        frame_target_ratio: FRAME_TARGET_RATIO,
        frame_met: solve_over_base.map(|r| r <= FRAME_TARGET_RATIO),
        orderings,
    })
}

/// Frame wall times (ms) of the finger curl, after one untimed frame, and
/// the medians of the two triangular solves timed right after each frame.
fn solve_frames(
    deformer: &curvenet_core::Deformer,
    nets: &[CurvenetData],
    frames: usize,
    context: &str,
) -> CliResult<(Vec<f64>, f64, f64)> {
    let frames = frames.max(1);
    let mut out = vec![[0.0; 3]; deformer.n_vertices()];
    let mut times = Vec::with_capacity(frames);
    let binding = deformer.binding();
    let mut tri9 = TriSolve::<9>::new(binding.n_unknowns(), 9);
    let mut tri3 = TriSolve::<3>::new(binding.n_unknowns(), 3);
    let (mut tri9_t, mut tri3_t) = (Vec::with_capacity(frames), Vec::with_capacity(frames));
    for i in 0..=frames {
        let pools = pose(nets, i.saturating_sub(1), frames);
        let posed: Vec<Option<&[[f64; 3]]>> = pools.iter().map(|p| Some(p.as_slice())).collect();
        let clock = Stopwatch::start();
        deformer
            .frame(&Frame { posed: &posed, ..Frame::default() }, &mut out, None)
            .map_err(|source| CliError::Core { context: format!("{context}, growth frame {i}"), source })?;
        if i > 0 {
            times.push(clock.stop().wall_ms);
            tri9_t.push(tri9.time(binding).wall_ms);
            tri3_t.push(tri3.time(binding).wall_ms);
        }
    }
    Ok((times, median(tri9_t), median(tri3_t)))
}

/// The growth row as text.
pub(super) fn text(g: &GrowthBench) -> String {
    use std::fmt::Write as _;
    let mut s = String::new();
    let _ = writeln!(s);
    let _ = writeln!(
        s,
        "Growth ({} {}: {} vertices, {} faces; made in {:.0} ms; medians of {} bindings and {} frames)",
        g.base, g.subdivision, g.vertices, g.faces, g.subdivide_ms, g.repeats, g.frames
    );
    let peak = g.peak_rss_bytes.map_or_else(|| "-".into(), |b| format!("{:.2} GB", b as f64 / 1e9));
    let scope = if g.peak_rss_reset { "this part" } else { "whole process" };
    let _ = writeln!(
        s,
        "  unknowns {}, L nnz {} ({}), binding {:.0} ms (surface {:.0}, cutting {:.0}, assembly {:.0}, factor {:.0}, other {:.0} ms; analysis {:.0} ms apart), frame {:.1} ms (triangular solves {:.1} + {:.1} ms), binding {:.0} bytes/vertex, peak RSS {peak} ({scope})",
        g.unknowns,
        g.factor_nonzeros,
        g.ordering,
        g.binding_ms,
        g.surface_ms,
        g.cutting_ms,
        g.assembly_ms,
        g.factor_ms,
        g.binding_other_ms,
        g.analysis_ms,
        g.solve_ms,
        g.tri9_ms,
        g.tri3_ms,
        g.binding_bytes_per_vertex
    );
    let met = |b: bool| if b { "met" } else { "NOT met" };
    let frame = match (g.base_solve_ms, g.solve_over_base, g.frame_met) {
        (Some(b), Some(r), Some(m)) => {
            format!("frame {r:.1}× the base's {b:.1} ms ≤ {}×: {}", g.frame_target_ratio, met(m))
        }
        _ => "frame ratio: the base mesh was not benched in this run".into(),
    };
    let _ = writeln!(
        s,
        "  targets: binding {:.0} ms ≤ {} ms: {}; {frame}",
        g.binding_ms,
        g.binding_target_ms,
        met(g.binding_met)
    );
    s
}
