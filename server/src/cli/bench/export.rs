//! `curvenet bench --export DIR`: per hand mesh, the binding's system and
//! one frame's two solves as files other sparse solvers read, so that
//! CHOLMOD, Eigen, MKL PARDISO, ... can be timed on exactly these systems
//! and checked against the same answers:
//!
//! - `<mesh>.mtx`: `VᵀL_hV` in MatrixMarket `coordinate real symmetric`,
//!   the lower triangle (row ≥ column), 1-based, in the unknowns' original
//!   order (the binding's numbering, not the factor's permutation), sorted
//!   by column then row, values in Rust's shortest round-trip form;
//! - `<mesh>.rhs9.f64`, `<mesh>.x9.f64`: Eq. 4's right-hand side and its
//!   solution f_v (n×9: per unknown a row-major 3×3 gradient);
//! - `<mesh>.rhs3.f64`, `<mesh>.x3.f64`: Eq. 5's right-hand side and its
//!   solution x_v (n×3 positions): raw little-endian f64, column-major (all
//!   n values of column 0, then column 1, ...), no header;
//! - `<mesh>.unknown_vertex.u32`: per unknown (row of the matrix and the
//!   vectors) its mesh vertex, 0-based, raw little-endian u32 (the binding
//!   numbers unknowns along a space-filling curve, not in vertex order);
//! - `manifest.json`: per mesh the file names, `n`, `nnz` (stored entries
//!   of the lower triangle), `columns`, the frame (`index` of `frames` of
//!   the bench's finger curl, its angle) and the format of each file.
//!
//! The right-hand sides and solutions are those of the frame's own solve
//! (`Binding::frame_system` records them), not recomputed.

use std::io::Write as _;
use std::path::{Path, PathBuf};

use curvenet_core::Binding;
use serde::Serialize;

use crate::cli::{CliError, CliResult};

/// One exported mesh in the manifest.
#[derive(Serialize)]
pub(super) struct Exported {
    pub mesh: String,
    pub n: usize,
    pub nnz: usize,
    pub matrix: String,
    pub rhs9: String,
    pub x9: String,
    pub rhs3: String,
    pub x3: String,
    pub unknown_vertex: String,
    pub frame: ExportedFrame,
}

#[derive(Serialize)]
pub(super) struct ExportedFrame {
    pub index: usize,
    pub frames: usize,
    pub angle_deg: f64,
}

#[derive(Serialize)]
struct Manifest<'a> {
    format: Format,
    meshes: &'a [Exported],
}

#[derive(Serialize)]
struct Format {
    matrix: &'static str,
    vectors: &'static str,
    rhs9: &'static str,
    rhs3: &'static str,
    unknown_vertex: &'static str,
    frame: &'static str,
}

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> CliError + '_ {
    move |source| CliError::Io { context: format!("bench --export: {}", path.display()), source }
}

/// Makes `dir` ready before any mesh is benched: refused when it is a
/// file, created when missing, and an earlier export's manifest removed.
/// The manifest is written last, so a directory holding one holds a whole
/// export; an earlier one would name files a failed run overwrote or removed.
pub(super) fn prepare(dir: &Path) -> CliResult {
    if dir.exists() && !dir.is_dir() {
        return Err(CliError::Input(format!("bench --export {}: exists and is not a directory", dir.display())));
    }
    std::fs::create_dir_all(dir).map_err(io_err(dir))?;
    let manifest = dir.join("manifest.json");
    if manifest.is_file() {
        std::fs::remove_file(&manifest).map_err(io_err(&manifest))?;
    }
    Ok(())
}

/// Writes `mesh`'s files into `dir` ([`prepare`]d) for the frame posed as
/// `posed`.
pub(super) fn export_mesh(
    dir: &Path,
    mesh: &str,
    binding: &Binding,
    posed: &[Option<&[[f64; 3]]>],
    frame: ExportedFrame,
    written: &mut Vec<PathBuf>,
) -> CliResult<Exported> {
    let a = binding.system_matrix();
    let sys = binding.frame_system(posed).map_err(|source| CliError::Core {
        context: format!("bench --export {mesh}, frame {}", frame.index),
        source,
    })?;
    let name = |ext: &str| format!("{mesh}.{ext}");
    let matrix = name("mtx");
    {
        let path = dir.join(&matrix);
        written.push(path.clone());
        let file = std::fs::File::create(&path).map_err(io_err(&path))?;
        let mut w = std::io::BufWriter::new(file);
        let write = |w: &mut std::io::BufWriter<std::fs::File>| -> std::io::Result<()> {
            writeln!(w, "%%MatrixMarket matrix coordinate real symmetric")?;
            writeln!(
                w,
                "% curvenet binding system V^T L_h V of {mesh}: lower triangle, unknowns in the binding's order, 1-based"
            )?;
            writeln!(w, "{} {} {}", a.n, a.n, a.entries.len())?;
            for &(r, c, v) in &a.entries {
                writeln!(w, "{} {} {:e}", r + 1, c + 1, v)?;
            }
            w.flush()
        };
        write(&mut w).map_err(io_err(&path))?;
    }
    let vectors = [("rhs9.f64", &sys.rhs9), ("x9.f64", &sys.x9), ("rhs3.f64", &sys.rhs3), ("x3.f64", &sys.x3)];
    for (ext, values) in vectors {
        let path = dir.join(name(ext));
        written.push(path.clone());
        let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        std::fs::write(&path, bytes).map_err(io_err(&path))?;
    }
    let unknown_vertex = name("unknown_vertex.u32");
    {
        let path = dir.join(&unknown_vertex);
        written.push(path.clone());
        let bytes: Vec<u8> =
            (0..a.n as u32).flat_map(|u| binding.unknown_vertex(curvenet_core::Unknown(u)).0.to_le_bytes()).collect();
        std::fs::write(&path, bytes).map_err(io_err(&path))?;
    }
    Ok(Exported {
        mesh: mesh.to_string(),
        n: a.n,
        nnz: a.entries.len(),
        matrix,
        rhs9: name("rhs9.f64"),
        x9: name("x9.f64"),
        rhs3: name("rhs3.f64"),
        x3: name("x3.f64"),
        unknown_vertex,
        frame,
    })
}

/// Writes `DIR/manifest.json` for the exported meshes.
pub(super) fn write_manifest(dir: &Path, meshes: &[Exported], written: &mut Vec<PathBuf>) -> CliResult {
    let manifest = Manifest {
        format: Format {
            matrix: "MatrixMarket coordinate real symmetric, lower triangle, 1-based, unknowns in the binding's order",
            vectors: "raw little-endian f64, column-major (column 0's n values first), no header",
            rhs9: "Eq. 4: n x 9, per unknown a row-major 3x3 deformation gradient; x9 its solution",
            rhs3: "Eq. 5: n x 3 positions; x3 its solution",
            unknown_vertex: "per unknown (row) its mesh vertex, 0-based, raw little-endian u32",
            frame: "the exported pose: frame `index` of a `frames`-frame cycle of the bench's finger curl, bent \
                    `angle_deg` (fixed, whatever --frames is)",
        },
        meshes,
    };
    let path = dir.join("manifest.json");
    written.push(path.clone());
    let text = serde_json::to_string_pretty(&manifest).map_err(|e| CliError::Input(e.to_string()))?;
    std::fs::write(&path, text + "\n").map_err(io_err(&path))
}
