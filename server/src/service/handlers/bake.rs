//! Bakes: `POST /v1/bake`: path checks against the configured roots, then
//! the bake itself through a [`Baker`](crate::config::Baker) the command line supplies (the bake
//! command lives in the binary, `cli::bake`; tests supply their own), holding
//! a solve permit.
//!
//! A path is allowed when, after resolving `..` and symlinks, it lies in a
//! root. So is every layer the stage opens: the baker opens the stage with a
//! resolver that refuses anything outside the roots (`BakeJob::roots`). The stage must exist; the output's parent directory must exist
//! (and, if the output exists, the output itself is resolved too, so a
//! symlink inside a root cannot point the write outside it).

use std::path::{Component, Path, PathBuf};
use std::time::Instant;

use axum::Json;
use axum::extract::State;
use axum::response::{IntoResponse, Response};
use curvenet_schema::wire::{BakeRequest, BakeResponse, ErrorBody};

use crate::config::{BakeFailure, BakeJob};
use crate::error::{Code, ServiceError};
use crate::extract::{Admission, ContentType, JsonOnly, SizedBody, parse_json};
use crate::state::{AppState, blocking};

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

/// Checks the stage path: inside a root before (`roots`, canonical, or
/// `names`, the roots as configured) and after canonicalisation (`roots`),
/// and existing.
pub fn check_stage(path: &str, roots: &[PathBuf], names: &[PathBuf]) -> Result<PathBuf, ServiceError> {
    let lex =
        lexical(path, roots).filter(|p| inside(p, roots) || inside(p, names)).ok_or_else(|| forbidden(path, roots))?;
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

/// Whether an output path names a directory by its spelling (a trailing `/`
/// or `/.`): never a layer file. `curvenet bake` and `POST /v1/bake` both
/// refuse it before any work; the service must look at the text, since the
/// canonical path it hands the bake has lost the slash.
pub fn names_a_directory(path: &str) -> bool {
    path.ends_with('/') || path.ends_with("/.")
}

/// Checks the output path: its parent resolved inside a root, and the
/// output itself too when it already exists (e.g. a symlink).
pub fn check_output(path: &str, roots: &[PathBuf], names: &[PathBuf]) -> Result<PathBuf, ServiceError> {
    // As the command line: a path naming a directory is never a layer file.
    if names_a_directory(path) {
        return Err(ServiceError::new(
            Code::BakeFailed,
            format!("output {path}: the output names a directory, not a layer file"),
        ));
    }
    let lex =
        lexical(path, roots).filter(|p| inside(p, roots) || inside(p, names)).ok_or_else(|| forbidden(path, roots))?;
    let name = lex.file_name().ok_or_else(|| forbidden(path, roots))?.to_owned();
    let parent = lex.parent().ok_or_else(|| forbidden(path, roots))?;
    // A directory that does not exist (yet) is worth retrying, as `curvenet
    // bake` exits 75 for it: a farm's output mount may come up late.
    let parent = std::fs::canonicalize(parent).map_err(|e| {
        let code = if e.kind() == std::io::ErrorKind::NotFound { Code::Unavailable } else { Code::BakeFailed };
        ServiceError::new(code, format!("output {path}: its directory {} cannot be resolved: {e}", parent.display()))
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

/// Bakes a shot stage on the server's file system (inside the bake roots).
#[utoipa::path(post, path = "/v1/bake", tag = "bake", security(("bearer" = [])),
    request_body = BakeRequest,
    responses(
        (status = 200, description = "Baked", body = BakeResponse),
        (status = 400, description = "malformed_json", body = ErrorBody),
        (status = 403, description = "path_forbidden: a path outside the bake roots", body = ErrorBody),
        (status = 404, description = "stage_not_found", body = ErrorBody),
        (status = 408, description = "request_timeout: the body stalled or arrived too slowly", body = ErrorBody),
        (status = 413, description = "payload_too_large", body = ErrorBody),
        (status = 415, description = "unsupported_media_type", body = ErrorBody),
        (status = 422, description = "bake_failed", body = ErrorBody),
        (status = 503, description = "saturated, or unavailable (Retry-After): an I/O failure, or the output's directory does not exist (`curvenet bake` exits 75 for both)", body = ErrorBody),
    ))]
pub(crate) async fn bake(
    State(state): State<AppState>,
    _: ContentType<JsonOnly>,
    SizedBody(bytes): SizedBody,
) -> Result<Response, ServiceError> {
    let req: BakeRequest = parse_json(&bytes)?;
    let roots = state.inner.bake_roots.clone();
    // The roots as configured (absolute, symlinks kept): a path given
    // through a root's own name passes the lexical check, then resolves, as
    // every path does, against the canonical roots.
    let names: Vec<PathBuf> = state.config().bake_roots.iter().filter_map(|r| std::path::absolute(r).ok()).collect();
    // Dropped with this handler when the client goes away: the bake stops.
    let guard = state.inner.bakes.start();
    let (cancel, max_points_bytes) = (guard.cancel_flag(), state.config().max_bake_bytes);
    let job = blocking(move || {
        Ok(BakeJob {
            stage: check_stage(&req.stage, &roots, &names)?,
            output: check_output(&req.output, &roots, &names)?,
            frames: req.frames,
            roots,
            max_points_bytes,
            cancel,
        })
    })
    .await?;
    let baker =
        state.inner.baker.clone().ok_or_else(|| ServiceError::internal("this server was started without a baker"))?;
    let admission = Admission::one(&state).await?;
    let t = Instant::now();
    let job2 = job.clone();
    let result = blocking(move || {
        let _admission = admission;
        baker(&job2).map_err(|f| match f {
            BakeFailure::Input(m) => ServiceError::new(Code::BakeFailed, m),
            BakeFailure::Retry(m) => ServiceError::new(Code::Unavailable, m),
            BakeFailure::Forbidden(m) => ServiceError::new(Code::PathForbidden, m),
            BakeFailure::Limit(m) => ServiceError::new(Code::LimitExceeded, m),
            // Only the drain deadline leaves anyone to read this; the log
            // says it either way (this closure runs to its end even when the
            // handler was dropped with its client).
            BakeFailure::Cancelled => {
                tracing::warn!(
                    stage = %job2.stage.display(),
                    output = %job2.output.display(),
                    elapsed_ms = t.elapsed().as_secs_f64() * 1e3,
                    "bake stopped before writing anything: its client went away or the server is draining"
                );
                ServiceError::new(
                    Code::Unavailable,
                    "the server is shutting down and stopped the bake before it wrote anything; retry",
                )
            }
        })
    })
    .await;
    guard.finish();
    let warnings = result?;
    Ok(Json(BakeResponse {
        stage: job.stage.display().to_string(),
        output: job.output.display().to_string(),
        elapsed_ms: t.elapsed().as_secs_f64() * 1e3,
        warnings,
    })
    .into_response())
}
