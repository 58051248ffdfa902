//! A resolver that keeps a stage inside given directories: it wraps
//! openusd's default resolver and refuses to resolve or open any asset
//! (layer, sublayer, reference, payload, package) whose canonical path —
//! symlinks followed, `..` resolved — is outside every root. The first
//! refusal is recorded so the caller can name it ([`super::UsdError::Forbidden`]).

use std::borrow::Cow;
use std::io;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use openusd::ar::{Asset, AssetInfo, DefaultResolver, ResolvedPath, Resolver};

/// The first asset refused: (asset path as authored, where it resolved).
pub(crate) type Refused = Arc<Mutex<Option<(String, String)>>>;

pub(crate) struct Confined {
    inner: DefaultResolver,
    roots: Vec<PathBuf>,
    refused: Refused,
}

impl Confined {
    /// `roots` should be canonical (the check compares canonical paths).
    pub(crate) fn new(roots: Vec<PathBuf>, refused: Refused) -> Self {
        Self { inner: DefaultResolver::new(), roots, refused }
    }

    /// Whether `resolved` lies in a root. A packaged path
    /// (`/dir/pkg.usdz[inner.usda]`) is judged by its package file.
    fn allowed(&self, resolved: &Path) -> bool {
        let text = resolved.to_string_lossy();
        let outer = match text.find('[') {
            Some(i) if text.ends_with(']') => Path::new(&text[..i]).to_path_buf(),
            _ => resolved.to_path_buf(),
        };
        // Canonicalise again: the default resolver canonicalises what exists,
        // but a path it returns unchanged (another platform's, a new asset) must not slip through.
        let Ok(canonical) = std::fs::canonicalize(&outer) else { return false };
        self.roots.iter().any(|r| canonical.starts_with(r))
    }

    fn refuse(&self, asset: &str, resolved: &Path) {
        let mut first = self.refused.lock().unwrap_or_else(|e| e.into_inner());
        if first.is_none() {
            *first = Some((asset.to_string(), resolved.display().to_string()));
        }
    }

    fn check(&self, asset: &str, resolved: Option<ResolvedPath>) -> Option<ResolvedPath> {
        let resolved = resolved?;
        if self.allowed(&resolved) {
            Some(resolved)
        } else {
            self.refuse(asset, &resolved);
            None
        }
    }
}

impl Resolver for Confined {
    fn create_identifier(&self, asset_path: &str, anchor: Option<&ResolvedPath>) -> String {
        self.inner.create_identifier(asset_path, anchor)
    }

    fn resolve(&self, asset_path: &str) -> Option<ResolvedPath> {
        self.check(asset_path, self.inner.resolve(asset_path))
    }

    fn resolve_for_new_asset(&self, asset_path: &str) -> Option<ResolvedPath> {
        // Reading a stage creates nothing; refuse rather than reason about paths that do not exist.
        let resolved = self.inner.resolve_for_new_asset(asset_path)?;
        self.refuse(asset_path, &resolved);
        None
    }

    fn open_asset(&self, resolved_path: &ResolvedPath) -> io::Result<Box<dyn Asset>> {
        if !self.allowed(resolved_path) {
            let text = resolved_path.to_string_lossy().into_owned();
            self.refuse(&text, resolved_path);
            return Err(io::Error::new(
                io::ErrorKind::PermissionDenied,
                format!("{text} is outside the allowed directories"),
            ));
        }
        self.inner.open_asset(resolved_path)
    }

    fn get_extension<'a>(&self, asset_path: &'a str) -> &'a str {
        self.inner.get_extension(asset_path)
    }

    fn is_context_dependent_path(&self, asset_path: &str) -> bool {
        self.inner.is_context_dependent_path(asset_path)
    }

    fn in_memory_identifier<'a>(&self, asset_path: &'a str) -> Cow<'a, str> {
        self.inner.in_memory_identifier(asset_path)
    }

    fn get_asset_info(&self, asset_path: &str, resolved_path: &ResolvedPath) -> AssetInfo {
        self.inner.get_asset_info(asset_path, resolved_path)
    }

    fn get_modification_timestamp(
        &self,
        asset_path: &str,
        resolved_path: &ResolvedPath,
    ) -> Option<std::time::SystemTime> {
        self.inner.get_modification_timestamp(asset_path, resolved_path)
    }

    fn identity(&self) -> String {
        let roots: Vec<String> = self.roots.iter().map(|r| r.display().to_string()).collect();
        format!("curvenet-confined({});{}", roots.join(","), self.inner.identity())
    }

    fn cache_id(&self) -> Option<u64> {
        // Never share the default resolver's caches: they were filled unconfined.
        None
    }
}
