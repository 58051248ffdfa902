//! The directory backend: one file per entry, `<64 hex>.cnb`, in a local or
//! NFS directory, written with std::fs on tokio's blocking threads.
//!
//! Only what works the same on NFS is used: a write goes to a fresh
//! temporary file in the same directory (created exclusively), is synced and
//! renamed over the entry, so a reader opens either the old file or the new
//! one, whole. No hard links and no locks. Recency is the file's mtime, set
//! to now by a hit. Any entry may be deleted or replaced by another process
//! at any moment: a file gone between the listing and the read is a miss,
//! and gone before eviction deletes it, already evicted.

use std::fs::{self, File, OpenOptions};
use std::io::{ErrorKind, Read as _, Write as _};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::SystemTime;

use super::error::{Op, Outcome, StoreError};
use super::names::{self, BLOB_MAGIC, BLOB_SUFFIX, Listed, STALE_AGE, Swept};

/// A store directory (cheap to clone into a blocking task).
#[derive(Debug, Clone)]
pub(super) struct Dir {
    inner: Arc<Inner>,
}

#[derive(Debug)]
struct Inner {
    /// The directory, absolute.
    root: PathBuf,
    /// `root` for error messages and logs.
    location: String,
    /// This process cannot write in it: reads only.
    read_only: bool,
}

/// A listing of the directory: the entries, and the temporary files old enough to be a dead writer's.
#[derive(Debug, Default)]
pub(super) struct Listing {
    pub entries: Vec<Listed>,
    pub stale_temps: Vec<PathBuf>,
}

impl Dir {
    /// Creates `path` if missing and checks that it is a directory this
    /// process can write (a probe file is created, synced and removed), so
    /// a misconfigured store fails at startup and not at the first bake.
    pub async fn open(path: PathBuf) -> Result<Self, StoreError> {
        let shown = path.display().to_string();
        blocking(&shown, Op::Open, None, move || open_blocking(path)).await
    }

    /// The directory's display form (absolute).
    pub fn location(&self) -> &str {
        &self.inner.location
    }

    /// The blob `key`, or None. A hit sets the file's mtime to now; failing
    /// that is a problem, not an error (the blob was read whole).
    pub async fn get(&self, key: [u8; 32], max_bytes: Option<u64>) -> Result<Outcome<Option<Vec<u8>>>, StoreError> {
        let dir = self.clone();
        blocking(self.location(), Op::Get, Some(&key), move || dir.get_blocking(&key, max_bytes)).await
    }

    /// Writes `bytes` as entry `key`, atomically.
    pub async fn put(&self, key: [u8; 32], bytes: Vec<u8>) -> Result<(), StoreError> {
        let dir = self.clone();
        blocking(self.location(), Op::Put, Some(&key), move || dir.put_blocking(&key, &bytes)).await
    }

    /// Whether entry `key` exists (a regular file under its name).
    pub async fn contains(&self, key: [u8; 32]) -> Result<bool, StoreError> {
        let path = self.entry_path(&key);
        let err = self.io(Op::Get, Some(&key), &path);
        blocking(self.location(), Op::Get, Some(&key), move || match fs::metadata(&path) {
            Ok(meta) => Ok(meta.is_file()),
            Err(e) if gone(&e) => Ok(false),
            Err(e) => Err(err(e)),
        })
        .await
    }

    /// Deletes entry `key`; absent is fine. Whether it was there.
    pub async fn remove(&self, key: [u8; 32]) -> Result<bool, StoreError> {
        let dir = self.clone();
        blocking(self.location(), Op::Remove, Some(&key), move || dir.remove_blocking(&key)).await
    }

    /// The directory's entries and stale temporaries.
    pub async fn list(&self) -> Result<Listing, StoreError> {
        let dir = self.clone();
        blocking(self.location(), Op::List, None, move || dir.list_blocking()).await
    }

    /// Lists, then deletes the least recently used entries until the rest
    /// hold at most `max_bytes` (never `keep`), and the stale temporaries.
    pub async fn sweep(&self, max_bytes: Option<u64>, keep: [u8; 32]) -> Result<Outcome<Swept>, StoreError> {
        let dir = self.clone();
        blocking(self.location(), Op::Evict, None, move || {
            let listing = dir.list_blocking()?;
            Ok(dir.evict_listed(listing, max_bytes, &keep))
        })
        .await
    }

    fn entry_path(&self, key: &[u8; 32]) -> PathBuf {
        self.inner.root.join(names::blob_name(key))
    }

    fn io(&self, op: Op, key: Option<&[u8; 32]>, path: &Path) -> impl FnOnce(std::io::Error) -> StoreError + use<> {
        let location = self.inner.location.clone();
        let path = path.to_path_buf();
        let key = key.copied();
        move |source| StoreError::io(&location, op, key.as_ref(), &path, source)
    }

    pub(super) fn get_blocking(
        &self,
        key: &[u8; 32],
        max_bytes: Option<u64>,
    ) -> Result<Outcome<Option<Vec<u8>>>, StoreError> {
        let path = self.entry_path(key);
        // A stat before the open: opening a FIFO (or a device) under an
        // entry's name would block; only regular files are entries.
        match fs::metadata(&path) {
            Ok(m) if m.is_file() => {}
            Ok(_) => return Ok(Outcome::clean(None)),
            Err(e) if gone(&e) => return Ok(Outcome::clean(None)),
            Err(e) => return Err(self.io(Op::Get, Some(key), &path)(e)),
        }
        let mut file = match File::open(&path) {
            Ok(f) => f,
            Err(e) if gone(&e) => return Ok(Outcome::clean(None)),
            Err(e) => return Err(self.io(Op::Get, Some(key), &path)(e)),
        };
        let meta = match file.metadata() {
            Ok(m) => m,
            Err(e) if gone(&e) => return Ok(Outcome::clean(None)),
            Err(e) => return Err(self.io(Op::Get, Some(key), &path)(e)),
        };
        if !meta.is_file() {
            // A directory or device under an entry's name is not the store's: a miss, as the listing ignores it.
            return Ok(Outcome::clean(None));
        }
        if let Some(max) = max_bytes
            && meta.len() > max
        {
            return Err(StoreError::TooLarge {
                location: self.inner.location.clone(),
                key: names::hex(key),
                bytes: meta.len(),
                max,
            });
        }
        // The first bytes first: a file that does not start as every blob
        // does is answered with those bytes alone (which its reader then
        // refuses), not read whole: garbage under an entry's name may be
        // of any size.
        let mut head = [0u8; BLOB_MAGIC.len()];
        let mut got = 0;
        while got < head.len() {
            match file.read(&mut head[got..]) {
                Ok(0) => break,
                Ok(n) => got += n,
                Err(e) if e.kind() == ErrorKind::Interrupted => {}
                Err(e) if gone(&e) => return Ok(Outcome::clean(None)),
                Err(e) => return Err(self.io(Op::Get, Some(key), &path)(e)),
            }
        }
        if head[..got] != BLOB_MAGIC[..got] || got < head.len() {
            return Ok(Outcome::clean(Some(head[..got].to_vec())));
        }
        let mut bytes = Vec::new();
        let reserve = usize::try_from(meta.len()).unwrap_or(usize::MAX);
        bytes.try_reserve_exact(reserve).map_err(|e| {
            self.io(Op::Get, Some(key), &path)(std::io::Error::new(ErrorKind::OutOfMemory, e.to_string()))
        })?;
        bytes.extend_from_slice(&head);
        match file.read_to_end(&mut bytes) {
            Ok(_) => {}
            // Deleted on another NFS client after the open: the handle went stale.
            Err(e) if gone(&e) => return Ok(Outcome::clean(None)),
            Err(e) => return Err(self.io(Op::Get, Some(key), &path)(e)),
        }
        let mut out = Outcome::clean(Some(bytes));
        // The file we hold may have been renamed over since the open; then
        // this touches the replaced file and the new one keeps its own mtime,
        // which is as recent anyway.
        if !self.inner.read_only
            && let Err(e) = file.set_modified(SystemTime::now())
            && !gone(&e)
        {
            out.problems.push(self.io(Op::Touch, Some(key), &path)(e));
        }
        Ok(out)
    }

    /// Whether the directory was opened for reading only.
    pub fn read_only(&self) -> bool {
        self.inner.read_only
    }

    pub(super) fn put_blocking(&self, key: &[u8; 32], bytes: &[u8]) -> Result<(), StoreError> {
        if self.inner.read_only {
            return Err(StoreError::ReadOnly { location: self.inner.location.clone(), key: names::hex(key) });
        }
        let temp = self.temp_path(&names::hex(key));
        let path = self.entry_path(key);
        let err = |p: &Path| self.io(Op::Put, Some(key), p);
        let mut file = OpenOptions::new().write(true).create_new(true).open(&temp).map_err(err(&temp))?;
        let guard = RemoveOnDrop(Some(temp.clone()));
        file.write_all(bytes).map_err(err(&temp))?;
        file.sync_all().map_err(err(&temp))?;
        drop(file);
        fs::rename(&temp, &path).map_err(err(&path))?;
        guard.disarm();
        // Not syncing the directory: after a crash the entry may be missing,
        // which is a miss of a cache; it is never partial, the data was synced first.
        Ok(())
    }

    pub(super) fn remove_blocking(&self, key: &[u8; 32]) -> Result<bool, StoreError> {
        let path = self.entry_path(key);
        match fs::remove_file(&path) {
            Ok(()) => Ok(true),
            Err(e) if gone(&e) => Ok(false),
            Err(e) => Err(self.io(Op::Remove, Some(key), &path)(e)),
        }
    }

    /// Reads the directory once. Only regular files named `<64 lowercase
    /// hex>.cnb` are entries; the store's own temporary files are skipped
    /// (and kept as stale when older than [`STALE_AGE`]); anything else is
    /// another program's and ignored.
    pub(super) fn list_blocking(&self) -> Result<Listing, StoreError> {
        let root = &self.inner.root;
        let read = fs::read_dir(root).map_err(self.io(Op::List, None, root))?;
        let now = SystemTime::now();
        let mut listing = Listing::default();
        for item in read {
            let item = item.map_err(self.io(Op::List, None, root))?;
            let name = item.file_name();
            let Some(name) = name.to_str() else { continue };
            let key = names::parse_name(name, BLOB_SUFFIX);
            let temp = key.is_none() && names::is_temp(name);
            if key.is_none() && !temp {
                continue;
            }
            // Does not follow symbolic links: a link is not the store's file.
            let meta = match item.metadata() {
                Ok(m) => m,
                Err(e) if gone(&e) => continue,
                Err(e) => return Err(self.io(Op::List, None, &item.path())(e)),
            };
            if !meta.is_file() {
                continue;
            }
            let modified = meta.modified().map_err(self.io(Op::List, None, &item.path()))?;
            match key {
                Some(key) => listing.entries.push(Listed { key, bytes: meta.len(), used: modified }),
                None => {
                    if now.duration_since(modified).is_ok_and(|age| age > STALE_AGE) {
                        listing.stale_temps.push(item.path());
                    }
                }
            }
        }
        Ok(listing)
    }

    /// Deletes what [`names::plan`] chooses from `listing`, and its stale
    /// temporaries. A file already gone counts as deleted by someone else;
    /// a file that cannot be deleted is a problem and counts as kept.
    pub(super) fn evict_listed(&self, listing: Listing, max_bytes: Option<u64>, keep: &[u8; 32]) -> Outcome<Swept> {
        let mut problems = Vec::new();
        for temp in &listing.stale_temps {
            if let Err(e) = fs::remove_file(temp)
                && !gone(&e)
            {
                problems.push(self.io(Op::Evict, None, temp)(e));
            }
        }
        let plan = names::plan(listing.entries, max_bytes, keep);
        let mut swept = Swept { bytes: plan.kept_bytes, entries: plan.kept_entries, evicted: 0 };
        for e in plan.evict {
            let path = self.entry_path(&e.key);
            match fs::remove_file(&path) {
                Ok(()) => swept.evicted += 1,
                Err(err) if gone(&err) => {}
                Err(err) => {
                    swept.bytes += e.bytes;
                    swept.entries += 1;
                    problems.push(self.io(Op::Evict, Some(&e.key), &path)(err));
                }
            }
        }
        Outcome { value: swept, problems }
    }

    /// A fresh temporary path in the store directory for a file about `tag`.
    fn temp_path(&self, tag: &str) -> PathBuf {
        temp_in(&self.inner.root, tag)
    }
}

/// A fresh temporary file name in `root` (this process's, 64 random bits).
fn temp_in(root: &Path, tag: &str) -> PathBuf {
    let unique = format!("{:016x}", names::unique_bits());
    root.join(names::temp_name(tag, std::process::id(), &unique))
}

/// Whether an I/O error means the file is not there (any more): deleted, or
/// its NFS handle stale because another client deleted it.
fn gone(e: &std::io::Error) -> bool {
    matches!(e.kind(), ErrorKind::NotFound | ErrorKind::StaleNetworkFileHandle)
}

fn open_blocking(path: PathBuf) -> Result<Dir, StoreError> {
    let shown = path.display().to_string();
    let fail = |what: &'static str| {
        let location = shown.clone();
        move |source| StoreError::Open { location, what, source }
    };
    let root = std::path::absolute(&path).map_err(fail("make the path absolute"))?;
    let location = root.display().to_string();
    let fail = |what: &'static str| {
        let location = location.clone();
        move |source| StoreError::Open { location, what, source }
    };
    fs::create_dir_all(&root).map_err(fail("create the directory"))?;
    let meta = fs::metadata(&root).map_err(fail("read the directory's metadata"))?;
    if !meta.is_dir() {
        return Err(fail("use it as a directory")(std::io::Error::new(ErrorKind::NotADirectory, "not a directory")));
    }
    let probe = temp_in(&root, "probe");
    let written = OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&probe)
        .and_then(|mut f| f.write_all(b"curvenet").and_then(|()| f.sync_all()));
    let removed = fs::remove_file(&probe);
    // A store the farm's bind step writes and its chunks only read (mounted
    // read-only, or owned by another user) is opened for reading, if it can
    // be listed: each write answers `StoreError::ReadOnly`.
    let unwritable = match written {
        Ok(()) => {
            removed.map_err(fail("delete a file in it"))?;
            None
        }
        Err(e) if matches!(e.kind(), ErrorKind::PermissionDenied | ErrorKind::ReadOnlyFilesystem) => Some(e),
        Err(e) => return Err(fail("write a file in it")(e)),
    };
    let dir = Dir { inner: Arc::new(Inner { root, location: location.clone(), read_only: unwritable.is_some() }) };
    match (dir.list_blocking(), unwritable) {
        (Ok(_), _) => Ok(dir),
        (Err(_), Some(e)) => Err(fail("write a file in it")(e)),
        (Err(e), None) => Err(e),
    }
}

/// Runs `work` on a blocking thread; a panic or a shut-down runtime becomes [`StoreError::Task`].
async fn blocking<T: Send + 'static>(
    location: &str,
    op: Op,
    key: Option<&[u8; 32]>,
    work: impl FnOnce() -> Result<T, StoreError> + Send + 'static,
) -> Result<T, StoreError> {
    match tokio::task::spawn_blocking(work).await {
        Ok(result) => result,
        Err(source) => Err(StoreError::Task { location: location.to_string(), op, key: key.map(names::hex), source }),
    }
}

/// Deletes a temporary file unless disarmed: a failed write leaves nothing behind.
struct RemoveOnDrop(Option<PathBuf>);

impl RemoveOnDrop {
    fn disarm(mut self) {
        self.0 = None;
    }
}

impl Drop for RemoveOnDrop {
    fn drop(&mut self) {
        if let Some(p) = self.0.take() {
            let _ = fs::remove_file(p);
        }
    }
}
