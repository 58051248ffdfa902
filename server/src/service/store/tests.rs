//! The store's tests: each behaviour against the directory backend and,
//! where it is the backends' common contract, against the object store
//! backend over `InMemory`.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, SystemTime};

use object_store::memory::InMemory;
use object_store::{ObjectStore, ObjectStoreExt as _, PutPayload};

use super::*;

/// A directory under the system's temporary directory, unique to the test
/// and the process, removed when dropped.
struct TempDir(PathBuf);

impl TempDir {
    fn new(tag: &str) -> Self {
        let p = std::env::temp_dir().join(format!(
            "curvenet-store-{tag}-{}-{:016x}",
            std::process::id(),
            names::unique_bits()
        ));
        TempDir(p)
    }

    fn path(&self) -> &Path {
        &self.0
    }

    fn location(&self) -> String {
        self.0.display().to_string()
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn key(n: u8) -> [u8; 32] {
    let mut k = [0u8; 32];
    k[0] = n;
    k[31] = n.wrapping_mul(7);
    k
}

/// A blob whose content says its length: the magic every blob starts with
/// (`BLOB_MAGIC`), 8 bytes of length, then a pattern of it (at least 16
/// bytes). A torn or mixed blob fails [`check_blob`].
fn blob(len: usize) -> Vec<u8> {
    let len = len.max(16);
    let mut b = BLOB_MAGIC.to_vec();
    b.extend_from_slice(&(len as u64).to_le_bytes());
    b.extend((0..len - 16).map(|i| (i * 31 + len) as u8));
    b
}

fn check_blob(b: &[u8]) -> bool {
    b.len() >= 16 && b == blob(u64::from_le_bytes(b[8..16].try_into().unwrap()) as usize).as_slice()
}

async fn dir_store(dir: &TempDir, max_bytes: Option<u64>) -> (BindingStore, Arc<Metrics>) {
    let metrics = Arc::new(Metrics::new());
    let store = BindingStore::open(&dir.location(), max_bytes, metrics.clone()).await.expect("open the store");
    (store, metrics)
}

fn memory_store(max_bytes: Option<u64>) -> (BindingStore, Arc<dyn ObjectStore>, Arc<Metrics>) {
    let metrics = Arc::new(Metrics::new());
    let objects: Arc<dyn ObjectStore> = Arc::new(InMemory::new());
    let store =
        BindingStore::with_object_store(objects.clone(), "bindings/v1", "memory://test", max_bytes, metrics.clone())
            .expect("a valid prefix");
    (store, objects, metrics)
}

/// The value of one metric line (`name value`) in the exposition, 0 if absent.
fn metric(metrics: &Metrics, name: &str) -> f64 {
    metrics
        .render()
        .lines()
        .find_map(|l| l.strip_prefix(name).and_then(|rest| rest.strip_prefix(' ')).map(|v| v.trim().parse().unwrap()))
        .unwrap_or(0.0)
}

/// Long enough that file times (kernel ticks, a few ms apart) order the steps.
async fn tick() {
    tokio::time::sleep(Duration::from_millis(30)).await;
}

// ---- the common contract, run against both backends ----

async fn round_trip(store: &BindingStore, metrics: &Metrics) {
    assert_eq!(store.get(&key(1)).await.unwrap(), None, "absent key");
    store.put(&key(1), blob(1000)).await.unwrap();
    assert_eq!(store.get(&key(1)).await.unwrap(), Some(blob(1000)));
    assert_eq!(store.get(&key(2)).await.unwrap(), None, "another key is still absent");
    assert_eq!(store.usage().await.unwrap(), (1000, 1));
    // Overwrite: the new blob, whole, and the size follows.
    store.put(&key(1), blob(300)).await.unwrap();
    assert_eq!(store.get(&key(1)).await.unwrap(), Some(blob(300)));
    assert_eq!(store.usage().await.unwrap(), (300, 1));
    // An empty blob is a blob, not an absence.
    store.put(&key(3), Vec::new()).await.unwrap();
    assert_eq!(store.get(&key(3)).await.unwrap(), Some(Vec::new()));
    assert!(store.contains(&key(1)).await.unwrap() && !store.contains(&key(2)).await.unwrap());
    assert!(store.remove(&key(1)).await.unwrap(), "the entry was there");
    assert!(!store.remove(&key(1)).await.expect("removing an absent entry is no error"), "and is gone");
    assert!(!store.contains(&key(1)).await.unwrap());
    assert_eq!(store.get(&key(1)).await.unwrap(), None);
    assert_eq!(store.usage().await.unwrap(), (0, 1));
    assert_eq!(metric(metrics, "curvenet_store_hits_total"), 3.0);
    assert_eq!(metric(metrics, "curvenet_store_misses_total"), 3.0);
    assert_eq!(metric(metrics, "curvenet_store_written_total"), 3.0);
    assert_eq!(metric(metrics, "curvenet_store_written_bytes_total"), 1300.0);
    assert_eq!(metric(metrics, "curvenet_store_read_bytes_total"), 1300.0);
    assert_eq!(metric(metrics, "curvenet_store_errors_total"), 0.0);
    assert_eq!(metric(metrics, "curvenet_store_bytes"), 0.0);
    assert!(metrics.render().contains("curvenet_store_load_seconds_count 3"));
    assert!(metrics.render().contains("curvenet_store_write_seconds_count 3"));
}

/// With room for two 100-byte entries: a third evicts the least recently
/// used, and a get makes an old entry recent again.
async fn lru(store: &BindingStore, metrics: &Metrics) {
    assert_eq!(store.max_bytes(), Some(250));
    store.put(&key(1), blob(100)).await.unwrap();
    tick().await;
    store.put(&key(2), blob(100)).await.unwrap();
    tick().await;
    store.put(&key(3), blob(100)).await.unwrap();
    assert_eq!(store.get(&key(1)).await.unwrap(), None, "the oldest went");
    assert_eq!(store.usage().await.unwrap(), (200, 2));
    tick().await;
    // Touch 2 (older than 3): now 3 is the least recently used.
    assert_eq!(store.get(&key(2)).await.unwrap(), Some(blob(100)));
    tick().await;
    store.put(&key(4), blob(100)).await.unwrap();
    assert_eq!(store.get(&key(3)).await.unwrap(), None, "the least recently used went");
    assert_eq!(store.get(&key(2)).await.unwrap(), Some(blob(100)), "the touched entry stayed");
    assert_eq!(store.get(&key(4)).await.unwrap(), Some(blob(100)));
    assert_eq!(metric(metrics, "curvenet_store_evictions_total"), 2.0);
    assert_eq!(metric(metrics, "curvenet_store_bytes"), 200.0);
    // A blob larger than the limit stays alone: everything else goes, never the key just written.
    tick().await;
    store.put(&key(5), blob(400)).await.unwrap();
    assert_eq!(store.usage().await.unwrap(), (400, 1));
    assert_eq!(store.get(&key(5)).await.unwrap(), Some(blob(400)));
    assert_eq!(metric(metrics, "curvenet_store_evictions_total"), 4.0);
    assert_eq!(metric(metrics, "curvenet_store_errors_total"), 0.0);
}

#[tokio::test]
async fn dir_round_trip() {
    let dir = TempDir::new("round-trip");
    let (store, metrics) = dir_store(&dir, None).await;
    round_trip(&store, &metrics).await;
    // Exactly the entries' files are left, no temporaries.
    let mut names: Vec<String> =
        std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name().into_string().unwrap()).collect();
    names.sort();
    assert_eq!(names, vec![names::blob_name(&key(3))]);
}

#[tokio::test]
async fn memory_round_trip() {
    let (store, objects, metrics) = memory_store(None);
    round_trip(&store, &metrics).await;
    let listed: Vec<String> = futures_util::StreamExt::collect::<Vec<_>>(objects.list(None))
        .await
        .into_iter()
        .map(|m| m.unwrap().location.to_string())
        .filter(|l| l.ends_with(".cnb"))
        .collect();
    assert_eq!(listed, vec![format!("bindings/v1/{}", names::blob_name(&key(3)))]);
}

#[tokio::test]
async fn dir_lru_eviction() {
    let dir = TempDir::new("lru");
    let (store, metrics) = dir_store(&dir, Some(250)).await;
    lru(&store, &metrics).await;
}

#[tokio::test]
async fn memory_lru_eviction() {
    let (store, objects, metrics) = memory_store(Some(250));
    lru(&store, &metrics).await;
    // The evicted entries' markers went with them; the kept entry's marker stays.
    let markers: Vec<String> = futures_util::StreamExt::collect::<Vec<_>>(objects.list(None))
        .await
        .into_iter()
        .map(|m| m.unwrap().location.to_string())
        .filter(|l| l.ends_with(".used"))
        .collect();
    assert_eq!(markers, vec![format!("bindings/v1/{}", names::marker_name(&key(5)))]);
}

#[tokio::test]
async fn open_relative_and_file_url_locations() {
    let dir = TempDir::new("file-url");
    let metrics = Arc::new(Metrics::new());
    let nested = dir.path().join("a/b");
    let store = BindingStore::open(&format!("file://{}", nested.display()), None, metrics.clone()).await.unwrap();
    assert_eq!(store.location(), nested.display().to_string(), "created, and named by its absolute path");
    store.put(&key(1), blob(10)).await.unwrap();
    assert!(nested.join(names::blob_name(&key(1))).is_file());
    // A relative path is made absolute against the working directory at open.
    let cwd = std::env::current_dir().unwrap();
    if let Ok(relative) = nested.strip_prefix(&cwd) {
        let again = BindingStore::open(&relative.display().to_string(), None, metrics).await.unwrap();
        assert_eq!(again.location(), store.location());
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn concurrent_writers_of_one_key_and_a_reader_never_see_a_partial_blob() {
    let dir = TempDir::new("concurrent");
    let (store, metrics) = dir_store(&dir, None).await;
    let store = Arc::new(store);
    let k = key(9);
    store.put(&k, blob(8)).await.unwrap();
    let done = Arc::new(AtomicBool::new(false));
    let writer = |seed: usize| {
        let store = store.clone();
        tokio::spawn(async move {
            for i in 0..60 {
                // Lengths from 8 bytes to ~400 KB, different in each writer and step.
                let len = 8 + (i * 7919 + seed * 104_729) % 400_000;
                store.put(&k, blob(len)).await.unwrap();
            }
        })
    };
    let reader = {
        let (store, done) = (store.clone(), done.clone());
        tokio::spawn(async move {
            let mut reads = 0usize;
            while !done.load(Ordering::Relaxed) || reads == 0 {
                let b = store.get(&k).await.unwrap().expect("the key is always present: a rename replaces it");
                assert!(check_blob(&b), "a partial or mixed blob of {} bytes", b.len());
                reads += 1;
            }
            reads
        })
    };
    let (a, b) = (writer(1), writer(2));
    a.await.unwrap();
    b.await.unwrap();
    done.store(true, Ordering::Relaxed);
    let reads = reader.await.unwrap();
    assert!(reads > 0);
    assert!(check_blob(&store.get(&k).await.unwrap().unwrap()));
    assert_eq!(store.usage().await.unwrap().1, 1);
    assert_eq!(metric(&metrics, "curvenet_store_errors_total"), 0.0);
    // No temporary file outlives its write.
    let leftovers: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .filter(|n| names::is_temp(n))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn memory_concurrent_writers_and_a_reader_see_whole_blobs() {
    let (store, _objects, _metrics) = memory_store(None);
    let store = Arc::new(store);
    let k = key(9);
    store.put(&k, blob(8)).await.unwrap();
    let writers: Vec<_> = (1..=2)
        .map(|seed| {
            let store = store.clone();
            tokio::spawn(async move {
                for i in 0..40 {
                    store.put(&k, blob(8 + (i * 7919 + seed * 104_729) % 50_000)).await.unwrap();
                }
            })
        })
        .collect();
    for _ in 0..200 {
        assert!(check_blob(&store.get(&k).await.unwrap().unwrap()));
    }
    for w in writers {
        w.await.unwrap();
    }
}

#[tokio::test]
async fn foreign_and_temporary_files_are_ignored_and_stale_temporaries_swept() {
    let dir = TempDir::new("foreign");
    let (store, metrics) = dir_store(&dir, Some(1 << 20)).await;
    let d = dir.path();
    let hex1 = names::hex(&key(1));
    let write = |name: &str, len: usize| std::fs::write(d.join(name), vec![b'x'; len]).unwrap();
    let age = |name: &str, secs: u64| {
        let f = std::fs::File::options().write(true).open(d.join(name)).unwrap();
        f.set_modified(SystemTime::now() - Duration::from_secs(secs)).unwrap();
    };
    write("README.txt", 100);
    write(&format!("{}.cnb", names::hex(&key(0xab)).to_uppercase()), 100);
    write(&format!("{hex1}.cnb.bak"), 100);
    write(&format!("{}.cnb", &hex1[..63]), 100);
    std::fs::create_dir(d.join(names::blob_name(&key(2)))).unwrap();
    let fresh_temp = names::temp_name(&hex1, 1, "00aa");
    let stale_temp = names::temp_name(&hex1, 2, "00bb");
    let stale_probe = names::temp_name("probe", 3, "00cc");
    write(&fresh_temp, 100);
    write(&stale_temp, 100);
    write(&stale_probe, 100);
    age(&stale_temp, 2 * 3600);
    age(&stale_probe, 2 * 3600);
    // Another program's old hidden file (an NFS silly rename) is never taken for a temporary.
    write(".nfs0000000000001234", 100);
    age(".nfs0000000000001234", 2 * 3600);

    assert_eq!(store.usage().await.unwrap(), (0, 0), "nothing there is an entry");
    assert_eq!(store.get(&key(2)).await.unwrap(), None, "a directory under an entry's name is a miss");
    store.put(&key(1), blob(50)).await.unwrap();
    assert_eq!(store.usage().await.unwrap(), (50, 1));
    assert_eq!(store.get(&key(1)).await.unwrap(), Some(blob(50)));
    assert!(!d.join(&stale_temp).exists() && !d.join(&stale_probe).exists(), "the sweep deletes stale temporaries");
    for kept in [
        "README.txt".to_string(),
        format!("{}.cnb", names::hex(&key(0xab)).to_uppercase()),
        format!("{hex1}.cnb.bak"),
        fresh_temp,
        ".nfs0000000000001234".into(),
    ] {
        assert!(d.join(&kept).exists(), "{kept} was deleted");
    }
    assert!(d.join(names::blob_name(&key(2))).is_dir());
    assert_eq!(metric(&metrics, "curvenet_store_evictions_total"), 0.0, "temporaries are not evictions");
}

#[tokio::test]
async fn memory_foreign_objects_are_ignored() {
    let (store, objects, _metrics) = memory_store(Some(150));
    let hex1 = names::hex(&key(1));
    for foreign in [
        format!("bindings/v1/deeper/{hex1}.cnb"),
        format!("bindings/v1/{}.cnb", names::hex(&key(0xab)).to_uppercase()),
        "bindings/v1/README".into(),
        format!("bindings/v10/{hex1}.cnb"),
        format!("other/{hex1}.cnb"),
    ] {
        objects.put(&foreign.as_str().into(), PutPayload::from(vec![0u8; 100])).await.unwrap();
    }
    assert_eq!(store.usage().await.unwrap(), (0, 0));
    store.put(&key(1), blob(100)).await.unwrap();
    store.put(&key(2), blob(100)).await.unwrap();
    assert_eq!(store.usage().await.unwrap(), (100, 1), "the limit counts entries only");
    let all = futures_util::StreamExt::collect::<Vec<_>>(objects.list(None)).await;
    assert_eq!(all.len(), 5 + 1, "the foreign objects are untouched");
}

#[tokio::test]
async fn a_file_deleted_between_listing_and_reading_is_a_miss() {
    let dir = TempDir::new("deleted");
    let (store, metrics) = dir_store(&dir, Some(100)).await;
    store.put(&key(1), blob(100)).await.unwrap();
    store.put(&key(2), blob(100)).await.unwrap();
    assert_eq!(store.get(&key(1)).await.unwrap(), None, "evicted by the second put");
    let Backend::Dir(d) = &store.backend else { unreachable!() };
    tick().await;
    d.put_blocking(&key(3), &blob(100)).unwrap();
    let listing = d.list_blocking().unwrap();
    assert_eq!(listing.entries.len(), 2);
    // Another process deletes both entries after the listing.
    std::fs::remove_file(dir.path().join(names::blob_name(&key(2)))).unwrap();
    std::fs::remove_file(dir.path().join(names::blob_name(&key(3)))).unwrap();
    assert!(d.get_blocking(&key(2), None).unwrap().value.is_none());
    assert_eq!(store.get(&key(3)).await.unwrap(), None);
    let swept = d.evict_listed(listing, Some(0), &key(9));
    assert!(swept.problems.is_empty(), "{:?}", swept.problems);
    assert_eq!(swept.value.evicted, 0, "another process deleted them first");
    assert_eq!(metric(&metrics, "curvenet_store_errors_total"), 0.0);
}

#[tokio::test]
async fn memory_an_object_deleted_between_listing_and_eviction_is_no_error() {
    let (store, objects, _metrics) = memory_store(None);
    store.put(&key(1), blob(100)).await.unwrap();
    store.put(&key(2), blob(100)).await.unwrap();
    let Backend::Objects(o) = &store.backend else { unreachable!() };
    let listing = o.list().await.unwrap();
    objects.delete(&format!("bindings/v1/{}", names::blob_name(&key(1))).as_str().into()).await.unwrap();
    assert_eq!(store.get(&key(1)).await.unwrap(), None);
    let swept = o.evict_listed(listing, Some(0), &key(9)).await;
    assert!(swept.problems.is_empty(), "{:?}", swept.problems);
    assert_eq!(store.usage().await.unwrap(), (0, 0));
}

#[tokio::test]
async fn open_of_an_unwritable_location_is_a_typed_error_naming_it() {
    let dir = TempDir::new("unwritable");
    std::fs::create_dir_all(dir.path()).unwrap();
    let file = dir.path().join("a-file");
    std::fs::write(&file, b"not a directory").unwrap();
    let metrics = Arc::new(Metrics::new());
    // Beneath a regular file (fails even as root, which may write anywhere).
    let beneath = file.join("store");
    let e = BindingStore::open(&beneath.display().to_string(), None, metrics.clone()).await.unwrap_err();
    assert!(matches!(e, StoreError::Open { ref location, .. } if *location == beneath.display().to_string()), "{e:?}");
    assert!(e.to_string().contains(&beneath.display().to_string()), "{e}");
    // A file itself.
    let e = BindingStore::open(&file.display().to_string(), None, metrics.clone()).await.unwrap_err();
    assert!(matches!(e, StoreError::Open { .. }), "{e:?}");
    assert!(e.to_string().contains(&file.display().to_string()), "{e}");
    // A read-only directory, where permissions apply (not as root).
    let readonly = dir.path().join("readonly");
    std::fs::create_dir(&readonly).unwrap();
    use std::os::unix::fs::PermissionsExt as _;
    std::fs::set_permissions(&readonly, std::fs::Permissions::from_mode(0o555)).unwrap();
    let probe = readonly.join("probe");
    if std::fs::write(&probe, b"x").is_err() {
        // Opened for reading: a farm's chunks read what its bind step wrote.
        let store = BindingStore::open(&readonly.display().to_string(), None, metrics.clone()).await.unwrap();
        assert!(store.read_only());
        let e = store.put(&[7; 32], b"CNENTRY\0x".to_vec()).await.unwrap_err();
        assert!(matches!(e, StoreError::ReadOnly { .. }), "{e:?}");
        assert_eq!(store.get(&[7; 32]).await.unwrap(), None);
    } else {
        let _ = std::fs::remove_file(&probe);
    }
    std::fs::set_permissions(&readonly, std::fs::Permissions::from_mode(0o755)).unwrap();
    assert!(metric(&metrics, "curvenet_store_errors_total") >= 2.0);
}

#[tokio::test]
async fn bad_locations_are_typed_errors_naming_them() {
    let metrics = Arc::new(Metrics::new());
    for (location, says) in [
        ("s3://", "no bucket"),
        ("s3:///prefix", "no bucket"),
        ("s3://bad bucket/x", "not a bucket name"),
        ("s3://bucket/a//b", "not an object path"),
        ("s3://bucket/a/../b", "'.' or '..'"),
        ("s3://bucket/p?versionId=3", "no query"),
        ("gs://bucket/p", "unsupported scheme"),
        ("", "empty"),
        ("file://", "names no directory"),
    ] {
        let e = BindingStore::open(location, None, metrics.clone()).await.unwrap_err();
        assert!(matches!(&e, StoreError::Location { location: l, .. } if l == location), "{location}: {e:?}");
        let text = e.to_string();
        assert!(text.contains(&format!("{location:?}")) && text.contains(says), "{location}: {text}");
    }
    let e =
        BindingStore::with_object_store(Arc::new(InMemory::new()), "a//b", "memory://x", None, metrics).unwrap_err();
    assert!(matches!(&e, StoreError::Location { location, .. } if location == "memory://x"), "{e:?}");
}

#[test]
fn s3_urls_parse_to_a_bucket_and_a_prefix() {
    let u = s3::S3Url::parse("s3://my-bucket").unwrap();
    assert_eq!(
        (u.bucket.as_str(), u.prefix.to_string().as_str(), u.display().as_str()),
        ("my-bucket", "", "s3://my-bucket")
    );
    let u = s3::S3Url::parse("s3://my.bucket/shows/a/").unwrap();
    assert_eq!((u.bucket.as_str(), u.prefix.to_string().as_str()), ("my.bucket", "shows/a"));
    assert_eq!(u.display(), "s3://my.bucket/shows/a");
    assert!(matches!(parse_location("s3://b/p").unwrap(), Location::S3(_)));
    assert_eq!(parse_location("file:///x/y").unwrap(), Location::Dir("/x/y".into()));
    assert_eq!(parse_location("rel/dir").unwrap(), Location::Dir("rel/dir".into()));
    // A colon in a plain path is a path, not a scheme.
    assert_eq!(parse_location("/data/a:b").unwrap(), Location::Dir("/data/a:b".into()));
}

/// An S3 endpoint nobody listens on (loopback only): `open` lists the prefix
/// once, so it fails there, typed and naming the location, within the retries.
#[tokio::test]
async fn s3_open_against_an_unreachable_endpoint_fails_naming_the_location() {
    let url = s3::S3Url::parse("s3://bucket/prefix").unwrap();
    let vars = [
        ("AWS_ACCESS_KEY_ID", "test"),
        ("AWS_SECRET_ACCESS_KEY", "test"),
        ("AWS_REGION", "us-east-1"),
        ("AWS_ENDPOINT_URL", "http://127.0.0.1:1"),
        ("AWS_ALLOW_HTTP", "true"),
        ("AWS_NOT_A_SETTING", "ignored"),
        ("HOME", "/nowhere"),
    ]
    .map(|(k, v)| (k.to_string(), v.to_string()));
    let started = std::time::Instant::now();
    let e = open_s3(&url, vars, Duration::from_secs(60)).await.map(|_| ()).unwrap_err();
    assert!(started.elapsed() < Duration::from_secs(30), "took {:?}", started.elapsed());
    assert!(matches!(&e, StoreError::Unreachable { location, .. } if location == "s3://bucket/prefix"), "{e:?}");
    assert!(e.to_string().contains("s3://bucket/prefix") && e.to_string().contains("cannot list"), "{e}");
    assert!(!e.is_config(), "an unreachable endpoint may come back: {e}");
}

fn vars(pairs: &[(&str, &str)]) -> Vec<(String, String)> {
    pairs.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect()
}

/// What object_store fails on late, obscurely or with a panic is refused
/// before any request, naming the variable.
#[tokio::test]
async fn s3_configuration_mistakes_name_the_variable() {
    let url = s3::S3Url::parse("s3://bucket").unwrap();
    let keys = [("AWS_ACCESS_KEY_ID", "k"), ("AWS_SECRET_ACCESS_KEY", "s"), ("AWS_REGION", "us-east-1")];
    let cases: &[(&[(&str, &str)], &str)] = &[
        (
            &[("AWS_ENDPOINT_URL", "not a url"), ("AWS_ALLOW_HTTP", "true")],
            "AWS_ENDPOINT_URL=\"not a url\" is not a URL",
        ),
        (&[("AWS_ENDPOINT_URL", "ftp://host:21")], "not an http:// or https:// URL"),
        (&[("AWS_ENDPOINT_URL", "http://")], "is not a URL"),
        (&[("AWS_ENDPOINT_URL", "http://127.0.0.1:9000")], "set too"),
        (&[("AWS_ENDPOINT_URL", "http://127.0.0.1:9000"), ("AWS_ALLOW_HTTP", "false")], "AWS_ALLOW_HTTP=true"),
        // The S3-specific endpoint wins, so it is the one checked.
        (&[("AWS_ENDPOINT_URL", "https://ok.example"), ("aws_endpoint_url_s3", "https//bad")], "AWS_ENDPOINT_URL_S3="),
    ];
    for (extra, says) in cases {
        let mut v = vars(&keys);
        v.extend(vars(extra));
        let e = open_s3(&url, v, Duration::from_secs(5)).await.map(|_| ()).unwrap_err();
        assert!(matches!(&e, StoreError::Config { .. }) && e.is_config(), "{extra:?}: {e:?}");
        assert!(e.to_string().contains(says) && e.to_string().contains("s3://bucket"), "{extra:?}: {e}");
    }
    for (set, missing) in
        [("AWS_ACCESS_KEY_ID", "AWS_SECRET_ACCESS_KEY"), ("AWS_SECRET_ACCESS_KEY", "AWS_ACCESS_KEY_ID")]
    {
        let e = open_s3(&url, vars(&[(set, "x"), ("AWS_REGION", "us-east-1")]), Duration::from_secs(5))
            .await
            .map(|_| ())
            .unwrap_err();
        assert!(e.is_config() && e.to_string().contains(&format!("{missing} is not")), "{e}");
    }
}

/// Without keys the client asks the instance metadata service; the error
/// says so, so that a missing variable is not mistaken for a network fault.
/// The metadata endpoint is pointed at a closed loopback port.
#[tokio::test]
async fn s3_without_credentials_says_none_were_set() {
    let url = s3::S3Url::parse("s3://bucket").unwrap();
    let v = vars(&[
        ("AWS_REGION", "us-east-1"),
        ("AWS_ENDPOINT_URL", "http://127.0.0.1:1"),
        ("AWS_ALLOW_HTTP", "true"),
        ("AWS_METADATA_ENDPOINT", "http://127.0.0.1:1"),
    ]);
    let e = open_s3(&url, v, Duration::from_secs(60)).await.map(|_| ()).unwrap_err();
    assert!(e.to_string().contains("no AWS_ACCESS_KEY_ID and AWS_SECRET_ACCESS_KEY are set"), "{e}");
}

/// A loopback listener that accepts connections and never answers (kept
/// open while the returned listener lives), and S3 settings pointing at it.
fn silent_endpoint() -> (std::net::TcpListener, Vec<(String, String)>) {
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = listener.local_addr().unwrap().port();
    let v = vars(&[
        ("AWS_ACCESS_KEY_ID", "k"),
        ("AWS_SECRET_ACCESS_KEY", "s"),
        ("AWS_REGION", "us-east-1"),
        ("AWS_ENDPOINT_URL", &format!("http://127.0.0.1:{port}")),
        ("AWS_ALLOW_HTTP", "true"),
    ]);
    (listener, v)
}

/// An endpoint that accepts connections and never answers fails the open
/// at the probe's deadline, not never.
#[tokio::test]
async fn s3_open_against_a_silent_endpoint_times_out() {
    let (listener, v) = silent_endpoint();
    let url = s3::S3Url::parse("s3://bucket").unwrap();
    let started = std::time::Instant::now();
    let e = open_s3(&url, v, Duration::from_millis(500)).await.map(|_| ()).unwrap_err();
    assert!(started.elapsed() < Duration::from_secs(10), "took {:?}", started.elapsed());
    assert!(matches!(&e, StoreError::Unreachable { .. }) && !e.is_config(), "{e:?}");
    assert!(e.to_string().contains("did not answer"), "{e}");
    drop(listener);
}

/// A store opened before its endpoint went silent (accepting connections,
/// never answering): the first call is bounded, and the store is then left
/// alone: the next calls answer `Paused` at once, not counted as errors.
#[tokio::test]
async fn a_store_that_stops_answering_is_paused_after_one_bounded_call() {
    let (listener, v) = silent_endpoint();
    let url = s3::S3Url::parse("s3://bucket/p").unwrap();
    let client = s3::s3_client(&url, v).unwrap();
    let metrics = Arc::new(Metrics::new());
    let store = BindingStore::with_object_store(client.store, "p", "s3://bucket/p", None, metrics.clone()).unwrap();
    let started = std::time::Instant::now();
    let e = store.contains(&key(1)).await.unwrap_err();
    let first = started.elapsed();
    assert!(matches!(e, StoreError::TimedOut { .. }), "{e:?}");
    assert!(first < CHECK_TIMEOUT + Duration::from_secs(1), "the check took {first:?}");
    assert_eq!(metric(&metrics, "curvenet_store_errors_total"), 1.0);
    let started = std::time::Instant::now();
    for e in [
        store.get(&key(1)).await.map(|_| ()).unwrap_err(),
        store.put(&key(1), BLOB_MAGIC.to_vec()).await.unwrap_err(),
        store.contains(&key(1)).await.map(|_| ()).unwrap_err(),
        store.remove(&key(1)).await.map(|_| ()).unwrap_err(),
    ] {
        assert!(matches!(e, StoreError::Paused { .. }), "{e:?}");
        assert!(e.to_string().contains("not asked for"), "{e}");
    }
    assert!(started.elapsed() < Duration::from_millis(100), "paused calls waited {:?}", started.elapsed());
    assert_eq!(metric(&metrics, "curvenet_store_errors_total"), 1.0, "paused calls counted as errors");
    drop(listener);
}

/// A blob that does not start with the magic is answered with its first
/// bytes only, in both backends: garbage under an entry's name is never
/// read whole.
#[tokio::test]
async fn a_blob_without_the_magic_is_answered_with_its_first_bytes_only() {
    let garbage = vec![0x5au8; 1 << 20];
    let (store, objects, metrics) = memory_store(None);
    let name = format!("bindings/v1/{}", names::blob_name(&key(9)));
    objects.put(&name.as_str().into(), PutPayload::from(garbage.clone())).await.unwrap();
    assert_eq!(store.get(&key(9)).await.unwrap(), Some(garbage[..8].to_vec()));
    assert_eq!(metric(&metrics, "curvenet_store_read_bytes_total"), 8.0);
    let dir = TempDir::new("garbage");
    let (store, metrics) = dir_store(&dir, None).await;
    std::fs::write(dir.0.join(names::blob_name(&key(9))), &garbage).unwrap();
    assert_eq!(store.get(&key(9)).await.unwrap(), Some(garbage[..8].to_vec()));
    assert_eq!(metric(&metrics, "curvenet_store_read_bytes_total"), 8.0);
    std::fs::write(dir.0.join(names::blob_name(&key(9))), &BLOB_MAGIC[..5]).unwrap();
    assert_eq!(store.get(&key(9)).await.unwrap(), Some(BLOB_MAGIC[..5].to_vec()), "a file shorter than the magic");
}

/// A blob larger than `with_max_blob_bytes` is refused before a byte of it
/// is read (a sparse file, or garbage that starts like a blob, under an
/// entry's name), in both backends; one within the bound is read.
#[tokio::test]
async fn a_blob_larger_than_the_bound_is_not_read() {
    let dir = TempDir::new("max-blob");
    let (store, metrics) = dir_store(&dir, None).await;
    let store = store.with_max_blob_bytes(1000);
    let f = std::fs::File::create(dir.0.join(names::blob_name(&key(1)))).unwrap();
    f.set_len(100 << 30).unwrap(); // 100 GiB, sparse
    drop(f);
    let e = store.get(&key(1)).await.unwrap_err();
    assert!(matches!(e, StoreError::TooLarge { bytes, max: 1000, .. } if bytes == 100 << 30), "{e:?}");
    assert_eq!(metric(&metrics, "curvenet_store_read_bytes_total"), 0.0);
    store.put(&key(2), blob(1000)).await.unwrap();
    assert_eq!(store.get(&key(2)).await.unwrap(), Some(blob(1000)));
    let (store, objects, _) = memory_store(None);
    let store = store.with_max_blob_bytes(1000);
    let name = format!("bindings/v1/{}", names::blob_name(&key(3)));
    objects.put(&name.as_str().into(), PutPayload::from(blob(1001))).await.unwrap();
    let e = store.get(&key(3)).await.unwrap_err();
    assert!(matches!(e, StoreError::TooLarge { bytes: 1001, .. }), "{e:?}");
}

/// A FIFO under an entry's name (opening it would block until a writer
/// comes, as a hung NFS read would) is a miss, at once.
#[tokio::test]
async fn a_fifo_under_an_entry_name_is_a_miss_not_a_hang() {
    let dir = TempDir::new("fifo");
    let (store, _) = dir_store(&dir, None).await;
    let path = dir.0.join(names::blob_name(&key(4)));
    let c = std::ffi::CString::new(path.as_os_str().as_encoded_bytes()).unwrap();
    // SAFETY: a valid NUL-terminated path; mkfifo only creates the node.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o644) }, 0);
    let got = tokio::time::timeout(Duration::from_secs(5), store.get(&key(4))).await;
    assert_eq!(got.expect("the get blocked on the FIFO").unwrap(), None);
}

#[test]
fn the_store_is_send_and_sync_and_its_futures_are_send() {
    fn send_sync<T: Send + Sync>() {}
    fn send<T: Send>(_: &T) {}
    send_sync::<BindingStore>();
    send_sync::<StoreError>();
    let metrics = Arc::new(Metrics::new());
    let (store, _, _) = memory_store(None);
    send(&BindingStore::open("/nonexistent", None, metrics));
    send(&store.get(&key(1)));
    send(&store.put(&key(1), Vec::new()));
    send(&store.remove(&key(1)));
    send(&store.usage());
}
