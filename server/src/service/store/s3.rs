//! The object store backend: one object per entry, `<prefix>/<64 hex>.cnb`,
//! over any `object_store::ObjectStore` (S3 in service, `InMemory` in the
//! tests). A single PUT is atomic, so a reader sees an old blob or a new
//! one, whole. Recency is the later of the blob's `last_modified` and that
//! of its `<hex>.used` marker, rewritten (empty) on every hit; see the
//! module docs of `store` for why.

use std::collections::HashMap;
use std::sync::Arc;
use std::time::{Duration, SystemTime};

use futures_util::StreamExt as _;
use object_store::aws::{AmazonS3Builder, AmazonS3ConfigKey};
use object_store::path::Path;
use object_store::{BackoffConfig, ClientConfigKey, ObjectStore, ObjectStoreExt as _, PutPayload, RetryConfig};

use super::error::{Op, Outcome, StoreError};
use super::names::{self, BLOB_MAGIC, BLOB_SUFFIX, Listed, MARKER_SUFFIX, STALE_AGE, Swept};

/// The entries of one prefix of an object store.
#[derive(Debug, Clone)]
pub(super) struct Objects {
    store: Arc<dyn ObjectStore>,
    /// The folder of the entries (the root for none).
    prefix: Path,
    /// How errors and logs name the store (`s3://bucket/prefix`).
    location: String,
}

/// A listing of the prefix: the entries with their recency, and the markers
/// whose blob is gone and that are old enough to delete.
#[derive(Debug, Default)]
pub(super) struct Listing {
    pub entries: Vec<Listed>,
    pub orphan_markers: Vec<Path>,
}

/// A bucket and prefix parsed from `s3://bucket/optional/prefix`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(super) struct S3Url {
    pub bucket: String,
    pub prefix: Path,
}

impl S3Url {
    /// `s3://BUCKET` or `s3://BUCKET/PREFIX` (a trailing `/` is dropped).
    /// A bad URL is [`StoreError::Location`] saying what is wrong: no
    /// bucket, characters no bucket name holds, an empty, `.` or `..`
    /// segment in the prefix, a query or fragment.
    pub fn parse(location: &str) -> Result<Self, StoreError> {
        let bad = |problem: String| StoreError::Location { location: location.to_string(), problem };
        let rest = location
            .strip_prefix("s3://")
            .ok_or_else(|| bad("an S3 location starts with s3:// (s3://bucket/optional/prefix)".into()))?;
        if rest.contains(['?', '#']) {
            return Err(bad("an S3 location has no query or fragment (s3://bucket/optional/prefix)".into()));
        }
        let (bucket, prefix) = rest.split_once('/').unwrap_or((rest, ""));
        if bucket.is_empty() {
            return Err(bad("no bucket name (s3://bucket/optional/prefix)".into()));
        }
        if bucket.len() > 255 || !bucket.bytes().all(|b| b.is_ascii_alphanumeric() || matches!(b, b'.' | b'-' | b'_')) {
            return Err(bad(format!("{bucket:?} is not a bucket name (letters, digits, '.', '-', '_')")));
        }
        Ok(S3Url { bucket: bucket.to_string(), prefix: parse_prefix(location, prefix)? })
    }

    /// `s3://bucket/prefix`, normalised: how the store names itself.
    pub fn display(&self) -> String {
        if self.prefix.is_root() {
            format!("s3://{}", self.bucket)
        } else {
            format!("s3://{}/{}", self.bucket, self.prefix)
        }
    }
}

/// The folder `prefix` of the store at `location` (empty: the root; a
/// trailing `/` is dropped). An empty, `.` or `..` segment, or one that is
/// no object path segment, is [`StoreError::Location`].
pub(super) fn parse_prefix(location: &str, prefix: &str) -> Result<Path, StoreError> {
    let bad = |problem: String| StoreError::Location { location: location.to_string(), problem };
    let prefix = prefix.strip_suffix('/').unwrap_or(prefix);
    if prefix.split('/').any(|s| s == "." || s == "..") {
        return Err(bad(format!("the prefix {prefix:?} has a '.' or '..' segment")));
    }
    Path::parse(prefix).map_err(|e| bad(format!("the prefix {prefix:?} is not an object path: {e}")))
}

/// How long one request may take, unless `AWS_TIMEOUT` says otherwise:
/// object_store's 30 s default would fail the download of a large binding
/// on an ordinary link (a 376k character's 732 MB at 100 Mbit/s: 60 s).
const REQUEST_TIMEOUT: &str = "120s";
/// How long a request may stall without a byte (unless `AWS_READ_TIMEOUT`):
/// short, because the service waits for the store while it answers a post
/// (S3 answers within milliseconds; AWS suggests timeouts of seconds).
const READ_TIMEOUT: &str = "5s";
/// Retries of a failed request: fewer than object_store's default (10
/// within 3 minutes), because a store that is down should make a bake
/// compute its bindings, not wait.
const RETRY: RetryConfig = RetryConfig {
    backoff: BackoffConfig { init_backoff: Duration::from_millis(100), max_backoff: Duration::from_secs(5), base: 2.0 },
    max_retries: 3,
    retry_timeout: Duration::from_secs(10),
};

/// The S3 client of `url`, configured by `vars` (the process's `AWS_*`
/// variables in service; the names are object_store's, case-insensitive:
/// `AWS_ACCESS_KEY_ID`, `AWS_SECRET_ACCESS_KEY`, `AWS_SESSION_TOKEN`,
/// `AWS_REGION`, which wins over `AWS_DEFAULT_REGION`, `AWS_ENDPOINT_URL`,
/// `AWS_ENDPOINT_URL_S3`, which wins over `AWS_ENDPOINT_URL`,
/// `AWS_ALLOW_HTTP`, ...). Unknown `AWS_*` names are ignored, as the AWS
/// tools do. Makes no request.
///
/// What object_store would fail on late or obscurely is refused here as
/// [`StoreError::Config`] naming the variable: an endpoint that is no
/// `http(s)://host` URL (object_store panics on some), a plain-http endpoint
/// without `AWS_ALLOW_HTTP` (its request fails with only "builder error"),
/// one half of the key pair.
pub(super) fn s3_client(url: &S3Url, vars: impl IntoIterator<Item = (String, String)>) -> Result<S3Client, StoreError> {
    let config = |problem: String| StoreError::Config { location: url.display(), problem };
    let mut builder = AmazonS3Builder::new()
        .with_config(AmazonS3ConfigKey::Client(ClientConfigKey::Timeout), REQUEST_TIMEOUT)
        .with_config(AmazonS3ConfigKey::Client(ClientConfigKey::ReadTimeout), READ_TIMEOUT)
        .with_retry(RETRY);
    let (mut endpoint, mut s3_endpoint, mut allow_http) = (None, None, None);
    let (mut key_id, mut secret, mut other_credentials) = (false, false, false);
    for (name, value) in vars {
        let upper = name.to_ascii_uppercase();
        if !upper.starts_with("AWS_") {
            continue;
        }
        let Ok(key) = name.to_ascii_lowercase().parse::<AmazonS3ConfigKey>() else { continue };
        match key {
            AmazonS3ConfigKey::Endpoint => endpoint = Some((upper, value.clone())),
            AmazonS3ConfigKey::S3Endpoint => s3_endpoint = Some((upper, value.clone())),
            AmazonS3ConfigKey::Client(ClientConfigKey::AllowHttp) => allow_http = Some(value.clone()),
            AmazonS3ConfigKey::AccessKeyId => key_id = !value.is_empty(),
            AmazonS3ConfigKey::SecretAccessKey => secret = !value.is_empty(),
            AmazonS3ConfigKey::WebIdentityTokenFile
            | AmazonS3ConfigKey::ContainerCredentialsRelativeUri
            | AmazonS3ConfigKey::ContainerCredentialsFullUri => other_credentials = true,
            _ => {}
        }
        builder = builder.with_config(key, value);
    }
    if let Some((name, value)) = s3_endpoint.or(endpoint) {
        let parsed = ::url::Url::parse(&value)
            .map_err(|e| config(format!("{name}={value:?} is not a URL ({e}); write http(s)://host[:port]")))?;
        if !matches!(parsed.scheme(), "http" | "https") || parsed.host_str().is_none_or(str::is_empty) {
            return Err(config(format!("{name}={value:?} is not an http:// or https:// URL with a host")));
        }
        let allowed = allow_http
            .as_deref()
            .is_some_and(|v| matches!(v.to_ascii_lowercase().as_str(), "1" | "true" | "on" | "yes" | "y"));
        if parsed.scheme() == "http" && !allowed {
            return Err(config(format!(
                "{name}={value:?} is plain http, which is refused unless AWS_ALLOW_HTTP=true is set too"
            )));
        }
    }
    match (key_id, secret) {
        (true, false) => return Err(config("AWS_ACCESS_KEY_ID is set but AWS_SECRET_ACCESS_KEY is not".into())),
        (false, true) => return Err(config("AWS_SECRET_ACCESS_KEY is set but AWS_ACCESS_KEY_ID is not".into())),
        _ => {}
    }
    let client = builder
        .with_bucket_name(&url.bucket)
        .build()
        .map_err(|source| config(format!("cannot configure the S3 client: {source}")))?;
    let credentials_hint = (!key_id && !other_credentials).then_some(
        "no AWS_ACCESS_KEY_ID and AWS_SECRET_ACCESS_KEY are set, so credentials were asked of the instance \
         metadata service",
    );
    Ok(S3Client { store: Arc::new(client), credentials_hint })
}

/// An S3 client, and what to add to an error of its first request when the
/// environment gave it no credentials.
pub(super) struct S3Client {
    pub store: Arc<dyn ObjectStore>,
    pub credentials_hint: Option<&'static str>,
}

impl Objects {
    /// The entries under `prefix` of `store`, named `location` in errors and logs.
    pub fn new(store: Arc<dyn ObjectStore>, prefix: Path, location: String) -> Self {
        Objects { store, prefix, location }
    }

    /// How the store names itself.
    pub fn location(&self) -> &str {
        &self.location
    }

    fn blob(&self, key: &[u8; 32]) -> Path {
        self.prefix.clone().join(names::blob_name(key))
    }

    fn marker(&self, key: &[u8; 32]) -> Path {
        self.prefix.clone().join(names::marker_name(key))
    }

    fn err(&self, op: Op, key: Option<&[u8; 32]>, object: &Path) -> impl FnOnce(object_store::Error) -> StoreError {
        let location = self.location.clone();
        let object = object.clone();
        let key = key.copied();
        move |source| StoreError::object(&location, op, key.as_ref(), &object, source)
    }

    /// Lists the first page of the prefix: the credentials, the bucket and
    /// the permission to list (which usage and eviction need) are checked
    /// before the store is used.
    pub async fn probe(&self) -> Result<(), object_store::Error> {
        let prefix = (!self.prefix.is_root()).then_some(&self.prefix);
        match self.store.list(prefix).next().await {
            None | Some(Ok(_)) => Ok(()),
            Some(Err(e)) => Err(e),
        }
    }

    /// The blob `key`, or None. A hit rewrites the key's marker; failing
    /// that is a problem, not an error (the blob was read whole).
    pub async fn get(&self, key: &[u8; 32], max_bytes: Option<u64>) -> Result<Outcome<Option<Vec<u8>>>, StoreError> {
        let blob = self.blob(key);
        let got = match self.store.get(&blob).await {
            Ok(got) => got,
            Err(object_store::Error::NotFound { .. }) => return Ok(Outcome::clean(None)),
            Err(e) => return Err(self.err(Op::Get, Some(key), &blob)(e)),
        };
        // Larger than this process reads: not downloaded at all.
        if let Some(max) = max_bytes
            && got.meta.size > max
        {
            return Err(StoreError::TooLarge {
                location: self.location.clone(),
                key: names::hex(key),
                bytes: got.meta.size,
                max,
            });
        }
        let size = usize::try_from(got.meta.size).unwrap_or(usize::MAX);
        // Streamed: once the first bytes are in, an object that does not
        // start as every blob does is answered with those bytes alone (for
        // the reader to refuse) and the rest is not downloaded.
        let mut stream = got.into_stream();
        let mut bytes: Vec<u8> = Vec::new();
        let mut checked = false;
        while let Some(chunk) = stream.next().await {
            let chunk = match chunk {
                Ok(c) => c,
                // Deleted between the answer's head and its body.
                Err(object_store::Error::NotFound { .. }) => return Ok(Outcome::clean(None)),
                Err(e) => return Err(self.err(Op::Get, Some(key), &blob)(e)),
            };
            bytes.extend_from_slice(&chunk);
            if !checked && bytes.len() >= BLOB_MAGIC.len() {
                if bytes[..BLOB_MAGIC.len()] != BLOB_MAGIC {
                    bytes.truncate(BLOB_MAGIC.len());
                    return Ok(Outcome::clean(Some(bytes)));
                }
                checked = true;
                let more = size.saturating_sub(bytes.len());
                if bytes.try_reserve_exact(more).is_err() {
                    return Err(StoreError::object(
                        &self.location,
                        Op::Get,
                        Some(key),
                        &blob,
                        object_store::Error::Generic {
                            store: "S3",
                            source: format!("cannot allocate {size} bytes for the blob").into(),
                        },
                    ));
                }
            }
        }
        let mut out = Outcome::clean(Some(bytes));
        let marker = self.marker(key);
        if let Err(e) = self.store.put(&marker, PutPayload::default()).await {
            out.problems.push(self.err(Op::Touch, Some(key), &marker)(e));
        }
        Ok(out)
    }

    /// Writes `bytes` as entry `key` in one PUT (atomic).
    pub async fn put(&self, key: &[u8; 32], bytes: Vec<u8>) -> Result<(), StoreError> {
        let blob = self.blob(key);
        self.store.put(&blob, PutPayload::from(bytes)).await.map_err(self.err(Op::Put, Some(key), &blob))?;
        Ok(())
    }

    /// Whether entry `key` exists (one HEAD).
    pub async fn contains(&self, key: &[u8; 32]) -> Result<bool, StoreError> {
        self.head(key, Op::Get).await
    }

    /// Whether the blob of `key` exists, a failure reported as `op`'s.
    async fn head(&self, key: &[u8; 32], op: Op) -> Result<bool, StoreError> {
        let blob = self.blob(key);
        match self.store.head(&blob).await {
            Ok(_) => Ok(true),
            Err(object_store::Error::NotFound { .. }) => Ok(false),
            Err(e) => Err(self.err(op, Some(key), &blob)(e)),
        }
    }

    /// Deletes entry `key` and its marker; absent is fine. Whether the blob
    /// was there (a HEAD first: S3 answers a DELETE of nothing as success).
    pub async fn remove(&self, key: &[u8; 32]) -> Result<bool, StoreError> {
        let held = self.head(key, Op::Remove).await?;
        for object in [self.blob(key), self.marker(key)] {
            match self.store.delete(&object).await {
                Ok(()) | Err(object_store::Error::NotFound { .. }) => {}
                Err(e) => return Err(self.err(Op::Remove, Some(key), &object)(e)),
            }
        }
        Ok(held)
    }

    /// Lists the prefix once. Only objects directly in it named `<64
    /// lowercase hex>.cnb` are entries, and `<64 hex>.used` their markers;
    /// anything else (deeper folders, other names) is ignored.
    pub async fn list(&self) -> Result<Listing, StoreError> {
        let prefix = (!self.prefix.is_root()).then_some(&self.prefix);
        let mut stream = self.store.list(prefix);
        let mut blobs: HashMap<[u8; 32], (u64, SystemTime)> = HashMap::new();
        let mut markers: HashMap<[u8; 32], (SystemTime, Path)> = HashMap::new();
        while let Some(meta) = stream.next().await {
            let meta = meta.map_err(self.err(Op::List, None, &self.prefix))?;
            let Some(mut parts) = meta.location.prefix_match(&self.prefix) else { continue };
            let (Some(name), None) = (parts.next(), parts.next()) else { continue };
            let name = name.as_ref();
            let modified = SystemTime::from(meta.last_modified);
            if let Some(key) = names::parse_name(name, BLOB_SUFFIX) {
                blobs.insert(key, (meta.size, modified));
            } else if let Some(key) = names::parse_name(name, MARKER_SUFFIX) {
                markers.insert(key, (modified, meta.location.clone()));
            }
        }
        let now = SystemTime::now();
        let mut listing = Listing::default();
        for (key, (used, path)) in &markers {
            if !blobs.contains_key(key) && now.duration_since(*used).is_ok_and(|age| age > STALE_AGE) {
                listing.orphan_markers.push(path.clone());
            }
        }
        listing.entries = blobs
            .into_iter()
            .map(|(key, (bytes, written))| {
                let used = markers.get(&key).map_or(written, |(touched, _)| written.max(*touched));
                Listed { key, bytes, used }
            })
            .collect();
        Ok(listing)
    }

    /// Lists, then deletes the least recently used entries (blob, then
    /// marker) until the rest hold at most `max_bytes` (never `keep`), and
    /// the orphan markers. A deletion that fails is a problem and its entry
    /// counts as kept.
    pub async fn sweep(&self, max_bytes: Option<u64>, keep: &[u8; 32]) -> Result<Outcome<Swept>, StoreError> {
        let listing = self.list().await?;
        Ok(self.evict_listed(listing, max_bytes, keep).await)
    }

    /// The deleting half of [`Objects::sweep`].
    pub async fn evict_listed(&self, listing: Listing, max_bytes: Option<u64>, keep: &[u8; 32]) -> Outcome<Swept> {
        let mut problems = Vec::new();
        for marker in &listing.orphan_markers {
            match self.store.delete(marker).await {
                Ok(()) | Err(object_store::Error::NotFound { .. }) => {}
                Err(e) => problems.push(self.err(Op::Evict, None, marker)(e)),
            }
        }
        let plan = names::plan(listing.entries, max_bytes, keep);
        let mut swept = Swept { bytes: plan.kept_bytes, entries: plan.kept_entries, evicted: 0 };
        for e in plan.evict {
            let blob = self.blob(&e.key);
            match self.store.delete(&blob).await {
                Ok(()) | Err(object_store::Error::NotFound { .. }) => swept.evicted += 1,
                Err(err) => {
                    swept.bytes += e.bytes;
                    swept.entries += 1;
                    problems.push(self.err(Op::Evict, Some(&e.key), &blob)(err));
                    continue;
                }
            }
            let marker = self.marker(&e.key);
            match self.store.delete(&marker).await {
                Ok(()) | Err(object_store::Error::NotFound { .. }) => {}
                Err(err) => problems.push(self.err(Op::Evict, Some(&e.key), &marker)(err)),
            }
        }
        Outcome { value: swept, problems }
    }
}
