//! `POST /v1/bake`: path checks against the configured roots, then the bake
//! itself through a [`Baker`] the command line supplies (the bake command
//! lives in the binary, `cli::bake`; tests supply their own).
//!
//! A path is allowed when, after resolving `..` and symlinks, it lies in a
//! root. So is every layer the stage opens: the baker opens the stage with a
//! resolver that refuses anything outside the roots (`BakeJob::roots`). The stage must exist; the output's parent directory must exist
//! (and, if the output exists, the output itself is resolved too, so a
//! symlink inside a root cannot point the write outside it).

use std::path::{Component, Path, PathBuf};
use std::sync::Arc;

use crate::error::{Code, ServiceError};

/// One bake, with checked, canonical paths.
#[derive(Debug, Clone)]
pub struct BakeJob {
    pub stage: PathBuf,
    pub output: PathBuf,
    /// `A-B` or `A`, as the bake command takes it.
    pub frames: Option<String>,
    /// The canonical bake roots: every layer and asset the stage opens
    /// (sublayers, references, payloads) must resolve inside one.
    pub roots: Vec<PathBuf>,
}

/// Why a bake failed.
#[derive(Debug, Clone)]
pub enum BakeFailure {
    /// Bad input (the stage breaks the contract, a bad frame range, ...): 422.
    Input(String),
    /// Worth retrying (an I/O failure): 503.
    Retry(String),
    /// The stage opens a layer or asset outside the roots: 403 `path_forbidden`.
    Forbidden(String),
}

/// Runs a bake to completion (blocking).
pub type Baker = Arc<dyn Fn(&BakeJob) -> Result<(), BakeFailure> + Send + Sync>;

fn forbidden(path: &str, roots: &[PathBuf]) -> ServiceError {
    if roots.is_empty() {
        return ServiceError::new(Code::PathForbidden, "baking is disabled: the server has no --bake-root");
    }
    let roots: Vec<String> = roots.iter().map(|r| r.display().to_string()).collect();
    ServiceError::new(Code::PathForbidden, format!("{path} is outside the bake roots ({})", roots.join(", ")))
}

/// `path` made absolute (relative to the first root) with `.` and `..`
/// removed lexically: a first check that needs no file system access.
fn lexical(path: &str, roots: &[PathBuf]) -> Option<PathBuf> {
    let p = Path::new(path);
    let joined = if p.is_absolute() { p.to_path_buf() } else { roots.first()?.join(p) };
    let mut out = PathBuf::new();
    for c in joined.components() {
        match c {
            Component::ParentDir => {
                if !out.pop() {
                    return None;
                }
            }
            Component::CurDir => {}
            other => out.push(other),
        }
    }
    Some(out)
}

fn inside(path: &Path, roots: &[PathBuf]) -> bool {
    roots.iter().any(|r| path.starts_with(r))
}

/// Checks the stage path: inside a root before and after canonicalisation, and existing.
pub fn check_stage(path: &str, roots: &[PathBuf]) -> Result<PathBuf, ServiceError> {
    let lex = lexical(path, roots).filter(|p| inside(p, roots)).ok_or_else(|| forbidden(path, roots))?;
    let canonical = std::fs::canonicalize(&lex)
        .map_err(|e| ServiceError::new(Code::StageNotFound, format!("stage {path}: {e}")))?;
    if !inside(&canonical, roots) {
        return Err(forbidden(path, roots));
    }
    if !canonical.is_file() {
        return Err(ServiceError::new(Code::StageNotFound, format!("stage {path} is not a file")));
    }
    Ok(canonical)
}

/// Checks the output path: its parent resolved inside a root, and the
/// output itself too when it already exists (e.g. a symlink).
pub fn check_output(path: &str, roots: &[PathBuf]) -> Result<PathBuf, ServiceError> {
    let lex = lexical(path, roots).filter(|p| inside(p, roots)).ok_or_else(|| forbidden(path, roots))?;
    let name = lex.file_name().ok_or_else(|| forbidden(path, roots))?.to_owned();
    let parent = lex.parent().ok_or_else(|| forbidden(path, roots))?;
    let parent = std::fs::canonicalize(parent).map_err(|e| {
        ServiceError::new(Code::BakeFailed, format!("output {path}: its directory cannot be resolved: {e}"))
    })?;
    let out = parent.join(name);
    let resolved = match std::fs::symlink_metadata(&out) {
        Ok(_) => std::fs::canonicalize(&out)
            .map_err(|e| ServiceError::new(Code::BakeFailed, format!("output {path}: {e}")))?,
        Err(_) => out,
    };
    if !inside(&resolved, roots) {
        return Err(forbidden(path, roots));
    }
    Ok(resolved)
}
