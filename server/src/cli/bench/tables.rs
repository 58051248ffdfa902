//! The text report's tables of the hand rows: Table 1, the binding's
//! stages, sizes, where a frame goes, throughput, frames in groups, the
//! frames' sanity and the issues' targets.

use std::fmt::Write as _;

use super::hand::MeshBench;
use super::inputs::MAX_ANGLE_DEG;
use super::measure::ratio;
use crate::cli::bench_batch;

pub(super) fn text(meshes: &[MeshBench], repeats: usize, frames: usize, threads: usize, simd: &str) -> String {
    let mut s = String::new();
    let w = meshes.iter().map(|m| m.mesh.len()).max().unwrap_or(4).max(10);
    let _ = writeln!(
        s,
        "curvenet bench: medians of {} bindings and {} frames per mesh (frame 0 neutral, then a finger curl up to {}°); {} thread(s) for throughput; triangular sweeps on {}",
        repeats, frames, MAX_ANGLE_DEG, threads, simd
    );
    let _ = writeln!(s);
    let _ = writeln!(s, "Table 1 (paper columns)");
    let _ = writeln!(
        s,
        "{:<w$} {:>7} {:>8} {:>6} {:>8} {:>11} {:>10} {:>15}",
        "mesh", "faces", "vertices", "knots", "samples", "cutting ms", "factor ms", "solve ms/frame"
    );
    for m in meshes {
        let _ = writeln!(
            s,
            "{:<w$} {:>7} {:>8} {:>6} {:>8} {:>11.2} {:>10.2} {:>15.3}",
            m.mesh, m.faces, m.vertices, m.knots, m.samples, m.cutting_ms, m.factor_ms, m.solve_ms
        );
    }
    let _ = writeln!(
        s,
        "  paper (Xeon E5-2699, CHOLMOD; its Factor = assembly + factorisation; 448 knots): Hand Tri 2896/1459 verts: 33.4 / 11.8 / 1.4 ms; Hand Subd 10447 verts: 51.1 / 46.2 / 6.3 ms; Hand Dense 93991 verts: 153.7 / 408.2 / 35.4 ms"
    );
    let _ = writeln!(s);
    let _ = writeln!(
        s,
        "Binding (ms, medians of Deformer::new; stages as its timings report them; total = its wall time less the analysis; deformer = its wall time, cpu = its thread CPU time; other = after the factorisation)"
    );
    let _ = writeln!(
        s,
        "{:<w$} {:>8} {:>8} {:>9} {:>8} {:>7} {:>8} {:>9} {:>9} {:>14} {:>9}",
        "mesh",
        "surface",
        "cutting",
        "assembly",
        "factor",
        "other",
        "total",
        "deformer",
        "cpu",
        "| analysis §3",
        "load USD"
    );
    for m in meshes {
        let cpu = m.deformer_cpu_ms.map_or_else(|| "-".to_string(), |c| format!("{c:.2}"));
        let _ = writeln!(
            s,
            "{:<w$} {:>8.2} {:>8.2} {:>9.2} {:>8.2} {:>7.2} {:>8.2} {:>9.2} {:>9} {:>14.2} {:>9.1}",
            m.mesh,
            m.surface_ms,
            m.cutting_ms,
            m.assembly_ms,
            m.factor_ms,
            m.binding_other_ms,
            m.binding_ms,
            m.deformer_ms,
            cpu,
            m.analysis_ms,
            m.load_ms
        );
    }
    let _ = writeln!(s);
    let _ = writeln!(s, "Sizes");
    let _ = writeln!(
        s,
        "{:<w$} {:>8} {:>9} {:>9} {:>11} {:>10} {:>12} {:>9} {:>9} {:>14}",
        "mesh",
        "splines",
        "segments",
        "cut faces",
        "cut verts",
        "unknowns",
        "constraints",
        "L nnz",
        "ordering",
        "binding B/vert"
    );
    for m in meshes {
        let _ = writeln!(
            s,
            "{:<w$} {:>8} {:>9} {:>9} {:>11} {:>10} {:>12} {:>9} {:>9} {:>14.0}",
            m.mesh,
            m.splines,
            m.segments,
            m.cut_faces,
            m.cut_vertices,
            m.unknowns,
            m.constraints,
            m.factor_nonzeros,
            m.ordering,
            m.binding_bytes_per_vertex
        );
    }
    let _ = writeln!(s);
    let _ = writeln!(
        s,
        "Per frame (ms, medians; deform = Deformer::frame (its pooled workspace reused); timed right after each frame: tri9/tri3 = solve_in_place::<9>/<3>"
    );
    let _ = writeln!(
        s,
        "           on random right-hand sides, curve = the curvenet part (samples, frames, gradients), ref = copying factor-nnz × 8 bytes there and back;"
    );
    let _ = writeln!(
        s,
        "           rest = deform − tri9 − tri3 − curve: constraint rows, B products, per-face gradients, output; cpu = thread CPU time, without preemption)"
    );
    let _ = writeln!(
        s,
        "{:<w$} {:<5} {:>8} {:>8} {:>8} {:>7} {:>7} {:>9} {:>7} {:>7} {:>7} {:>10} {:>8}",
        "mesh",
        "clock",
        "deform",
        "min",
        "max",
        "tri9",
        "tri3",
        "tri share",
        "curve",
        "rest",
        "ref",
        "deform/ref",
        "tri/ref"
    );
    for m in meshes {
        let _ = writeln!(
            s,
            "{:<w$} {:<5} {:>8.3} {:>8.3} {:>8.3} {:>7.3} {:>7.3} {:>8.0}% {:>7.3} {:>7.3} {:>7.3} {:>10.1} {:>8.1}",
            m.mesh,
            "wall",
            m.solve_ms,
            m.solve_min_ms,
            m.solve_max_ms,
            m.tri9_ms,
            m.tri3_ms,
            100.0 * m.tri_share,
            m.curvenet_eval_ms,
            m.rest_of_frame_ms,
            m.reference_ms,
            m.solve_over_reference,
            m.tri_over_reference
        );
        if let (Some(d), Some(t9), Some(t3), Some(share), Some(curve), Some(rest), Some(reference)) = (
            m.solve_cpu_ms,
            m.tri9_cpu_ms,
            m.tri3_cpu_ms,
            m.tri_share_cpu,
            m.curvenet_eval_cpu_ms,
            m.rest_of_frame_cpu_ms,
            m.reference_cpu_ms,
        ) {
            let _ = writeln!(
                s,
                "{:<w$} {:<5} {:>8.3} {:>8} {:>8} {:>7.3} {:>7.3} {:>8.0}% {:>7.3} {:>7.3} {:>7.3} {:>10.1} {:>8.1}",
                "",
                "cpu",
                d,
                "",
                "",
                t9,
                t3,
                100.0 * share,
                curve,
                rest,
                reference,
                ratio(d, reference),
                ratio(t9 + t3, reference)
            );
        }
    }
    for m in meshes {
        let _ = writeln!(
            s,
            "{:<w$} a frame with its own rest pose (bakes over skinning): {:.3} ms ({:.2}× the frame above)",
            m.mesh,
            m.rest_pose_frame_ms,
            m.rest_pose_frame_ms / m.solve_ms
        );
    }
    let _ = writeln!(s);
    let _ =
        writeln!(s, "Throughput across frames (frames/s; Deformer::frame on every thread, workspaces from its pool)");
    let _ = writeln!(s, "{:<w$} {:>10} {:>14} {:>8}", "mesh", "1 thread", format!("{} threads", threads), "speedup");
    for m in meshes {
        let _ = writeln!(
            s,
            "{:<w$} {:>10.1} {:>14.1} {:>7.2}×",
            m.mesh, m.serial_frames_per_s, m.parallel_frames_per_s, m.parallel_speedup
        );
    }
    let _ = writeln!(s);
    s += &bench_batch::text_table(
        meshes.iter().map(|m| (m.mesh.as_str(), m.solve_ms, m.parallel_frames_per_s, &m.batch)),
        threads,
    );
    let _ = writeln!(s);
    let _ = writeln!(s, "Frames (relative to the bounding-box diagonal)");
    for m in meshes {
        let _ = writeln!(
            s,
            "{:<w$} neutral pose reproduces the mesh to {:.1e}; largest displacement {:.3}",
            m.mesh, m.neutral_max_error, m.max_displacement
        );
        for warning in &m.warnings {
            let _ = writeln!(s, "{:<w$} warning: {warning}", "");
        }
    }
    let with_targets: Vec<&MeshBench> = meshes.iter().filter(|m| m.targets.is_some()).collect();
    if !with_targets.is_empty() {
        let _ = writeln!(s);
        let _ = writeln!(s, "Targets of the issues (informative; the bench never fails on them)");
        let met = |b: bool| if b { "met" } else { "NOT met" };
        for m in with_targets {
            let t = m.targets.expect("filtered");
            let _ = writeln!(
                s,
                "{:<w$} solve {:.2} ms ≤ {} ms: {} (stretch ≤ {} ms: {}); binding {:.1} ms ≤ {} ms: {}",
                m.mesh,
                m.solve_ms,
                t.solve_ms,
                met(t.solve_met),
                t.solve_stretch_ms,
                met(t.solve_stretch_met),
                m.binding_ms,
                t.binding_ms,
                met(t.binding_met)
            );
            let group16 = m.batch.over_reference_at(16);
            let _ = writeln!(
                s,
                "{:<w$} issue #19: frame {:.2} ms ≤ {} ms: {}; best group {:.0} frames/s ≥ {}: {}; group of 16 {} ≤ {}× the copy reference: {}",
                "",
                m.solve_ms,
                t.frame_ms,
                met(t.frame_met),
                m.batch.batch_frames_per_s,
                t.batch_frames_per_s,
                met(t.batch_met),
                group16.map_or("not run".to_string(), |g| format!("{g:.1}×")),
                t.group16_over_reference,
                t.group16_met.map_or("not run", met),
            );
            if let (Some(sc), Some(dc)) = (m.solve_cpu_ms, m.deformer_cpu_ms) {
                let _ = writeln!(
                    s,
                    "{:<w$} (judged on wall-clock medians; in thread CPU time: solve {sc:.2} ms, Deformer::new {dc:.1} ms of which analysis {:.1} ms wall)",
                    "", m.analysis_ms
                );
            }
        }
    }
    s
}
