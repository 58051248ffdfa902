//! The binding store (`serve --store`, `bake --store`) against a real store
//! directory: replicas (two service states over one directory, driven
//! through their routers) answer each other's bindings by id bit for bit;
//! damaged store files are never used; bakes read their bindings from the
//! store and write the same bytes; a shot's chunks bind once.

mod common;

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use axum::Router;
use axum::body::Body;
use axum::http::{Request, StatusCode};
use common::router::{get, metric_opt, post_binding, post_json, send};
use common::{curvenet, repo, stderr, temp_dir};
use curvenet_schema::usd::Stage;
use curvenet_schema::wire::{BindingRequest, BindingResponse, FrameRequest};
use curvenet_server::{AppState, Config, app};
use serde_json::Value;

fn hand() -> &'static BindingRequest {
    static HAND: OnceLock<BindingRequest> = OnceLock::new();
    HAND.get_or_init(|| {
        let stage = Stage::open(repo().join("fixtures/hand/hand_1k4.usda")).unwrap();
        let mesh = stage.deformed_meshes().unwrap().into_iter().next().unwrap();
        let nets: Vec<_> = mesh.curvenets.iter().map(|p| stage.curvenet(p).unwrap()).collect();
        BindingRequest::from_stage(&mesh, &nets)
    })
}

/// A replica: a service state over the store directory `dir`.
async fn replica(dir: &Path) -> Router {
    let config = Config { solve_threads: 2, ..Config::default() };
    app(AppState::open(config, None, dir.to_str().unwrap(), None).await.unwrap())
}

/// A frame: the first curvenet's pool rotated by 30° about z.
fn frame() -> FrameRequest {
    let (s, c) = 30f64.to_radians().sin_cos();
    let pool: Vec<[f64; 3]> =
        hand().curvenets[0].pool.iter().map(|p| [c * p[0] - s * p[1], s * p[0] + c * p[1], p[2]]).collect();
    let mut posed = vec![None; hand().curvenets.len()];
    posed[0] = Some(pool);
    FrameRequest { posed: Some(posed), ..Default::default() }
}

/// The frame's answer from `app` for binding `id` (status, raw JSON points).
async fn frame_points(app: &Router, id: &str) -> (StatusCode, Value) {
    let (status, _, body) = send(app, post_json(&format!("/v1/bindings/{id}/frames"), &frame())).await;
    let v: Value = serde_json::from_slice(&body).unwrap_or(Value::Null);
    (status, v)
}

fn blobs(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "cnb"))
        .collect();
    v.sort();
    v
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_binding_built_by_one_replica_is_answered_by_another_by_id_bit_for_bit() {
    let dir = temp_dir("store", "replicas");
    let a = replica(&dir).await;
    let b = replica(&dir).await;
    let posted = post_binding(&a, hand()).await;
    assert!(!posted.cached);
    assert_eq!(blobs(&dir).len(), 1, "the post answered before its binding was written");
    let id = posted.binding_id;
    // B never saw the mesh: it answers the id from the store.
    let (status, _, body) = send(&b, get(&format!("/v1/bindings/{id}"))).await;
    assert_eq!(status, StatusCode::OK, "{}", String::from_utf8_lossy(&body));
    let described: BindingResponse = serde_json::from_slice(&body).unwrap();
    assert_eq!(described.binding_id, id);
    assert_eq!(described.vertices, posted.vertices);
    assert_eq!(described.stats.factor_nonzeros, posted.stats.factor_nonzeros);
    let (sa, pa) = frame_points(&a, &id).await;
    let (sb, pb) = frame_points(&b, &id).await;
    assert_eq!((sa, sb), (StatusCode::OK, StatusCode::OK));
    assert_eq!(pa["points"], pb["points"], "replica B's frame differs from A's");
    assert_eq!(metric_opt(&b, "curvenet_bindings_computed_total").await.unwrap_or(0.0), 0.0);
    assert!(metric_opt(&b, "curvenet_store_hits_total").await.unwrap_or(0.0) >= 1.0);
    // Posting the mesh to B now finds it cached (loaded), not computed.
    assert!(post_binding(&b, hand()).await.cached);
    assert_eq!(metric_opt(&b, "curvenet_bindings_computed_total").await.unwrap_or(0.0), 0.0);
    let _ = std::fs::remove_dir_all(&dir);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn damaged_store_files_are_never_used_and_are_rebuilt() {
    let dir = temp_dir("store", "damaged");
    let a = replica(&dir).await;
    let id = post_binding(&a, hand()).await.binding_id;
    let (_, want) = frame_points(&a, &id).await;
    let path = blobs(&dir).pop().unwrap();
    let good = std::fs::read(&path).unwrap();
    let n = good.len();
    // Damage: bytes flipped in the envelope's header, its meta, the
    // deformer's header and deep in its payload; truncations; nothing; a
    // blob stored under another key's name.
    let mut damaged: Vec<(String, Vec<u8>)> = Vec::new();
    for at in [0, 9, 20, 60, 70, 100, 130, n / 3, n / 2, n - 1] {
        let mut b = good.clone();
        b[at] ^= 0x40;
        damaged.push((format!("byte {at} flipped"), b));
    }
    for len in [0, 7, 63, 100, n / 2, n - 1] {
        damaged.push((format!("truncated to {len}"), good[..len].to_vec()));
    }
    let mut longer = good.clone();
    longer.extend_from_slice(b"junk");
    damaged.push(("junk appended".into(), longer));
    for (what, bytes) in damaged {
        std::fs::write(&path, &bytes).unwrap();
        // A fresh replica: nothing in memory.
        let c = replica(&dir).await;
        let (status, _, _) = send(&c, get(&format!("/v1/bindings/{id}"))).await;
        assert_eq!(status, StatusCode::NOT_FOUND, "{what}: a damaged binding was used");
        let (status, _) = frame_points(&c, &id).await;
        assert_eq!(status, StatusCode::NOT_FOUND, "{what}: a frame was answered from a damaged binding");
        assert!(metric_opt(&c, "curvenet_store_rejected_total").await.unwrap_or(0.0) >= 1.0, "{what}: not counted");
        // The post carries the mesh: built again, written again, correct.
        let posted = post_binding(&c, hand()).await;
        assert!(!posted.cached, "{what}");
        let (status, got) = frame_points(&c, &id).await;
        assert_eq!(status, StatusCode::OK, "{what}");
        assert_eq!(got["points"], want["points"], "{what}: the rebuilt binding's frame differs");
        // Written again whole: a fresh replica answers the id from it.
        let d = replica(&dir).await;
        let (status, _, _) = send(&d, get(&format!("/v1/bindings/{id}"))).await;
        assert_eq!(status, StatusCode::OK, "{what}: the rebuilt binding was not written again");
    }
    // A good blob under another id's name is refused too (wrong key).
    let other = format!("{}{}", &id[..63], if id.ends_with('0') { '1' } else { '0' });
    std::fs::copy(&path, dir.join(format!("{other}.cnb"))).unwrap();
    let c = replica(&dir).await;
    let (status, _, _) = send(&c, get(&format!("/v1/bindings/{other}"))).await;
    assert_eq!(status, StatusCode::NOT_FOUND, "a blob renamed to another key was used");
    assert!(metric_opt(&c, "curvenet_store_rejected_total").await.unwrap_or(0.0) >= 1.0);
    let _ = std::fs::remove_dir_all(&dir);
}

fn bake(shot: &str, out: &Path, extra: &[&str]) -> std::process::Output {
    let mut args = vec!["bake", shot, "--out", out.to_str().unwrap()];
    args.extend_from_slice(extra);
    let run = curvenet(&args);
    assert!(run.status.success(), "bake {shot} {extra:?}: {}", stderr(&run));
    run
}

#[test]
fn every_shot_bakes_the_same_bytes_built_and_loaded_from_the_store() {
    // The skinned, rigged (spline skinning), caged, cage-only, adjusted and
    // plain shots: each layer of the rig goes through the stored format.
    let dir = temp_dir("store", "shots");
    for shot in ["hand_wave", "hand_skinned", "hand_rigged", "hand_caged", "hand_cage_only", "hand_adjusted"] {
        let input = format!("fixtures/shots/{shot}/shot.usda");
        let plain = dir.join(format!("{shot}.plain.usda"));
        let built = dir.join(format!("{shot}.built.usda"));
        let loaded = dir.join(format!("{shot}.loaded.usda"));
        // A store per shot: some shots share their mesh and curvenets (one binding).
        let store = dir.join(format!("{shot}.store"));
        bake(&input, &plain, &["--frames", "1-4"]);
        let first = bake(&input, &built, &["--frames", "1-4", "--store", store.to_str().unwrap()]);
        assert!(stderr(&first).contains("(built, written to the store)"), "{shot}: {}", stderr(&first));
        let second = bake(&input, &loaded, &["--frames", "1-4", "--store", store.to_str().unwrap()]);
        assert!(stderr(&second).contains("loaded from the store"), "{shot}: {}", stderr(&second));
        let p = std::fs::read(&plain).unwrap();
        assert!(p == std::fs::read(&built).unwrap(), "{shot}: the bake that wrote the store differs");
        assert!(p == std::fs::read(&loaded).unwrap(), "{shot}: the bake from the store differs");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// `bind N ms` from a bake's summary line.
fn bind_ms(run: &std::process::Output) -> f64 {
    let err = stderr(run);
    let at = err.find(": bind ").unwrap_or_else(|| panic!("no bind time in: {err}"));
    err[at + 7..].split_whitespace().next().unwrap().parse().unwrap()
}

#[test]
fn a_four_chunk_bake_binds_once_and_stitches_to_the_whole_bake() {
    let dir = temp_dir("store", "chunks");
    let store = dir.join("store");
    let s = store.to_str().unwrap();
    let shot = "fixtures/shots/hand_wave/shot.usda";
    let whole = dir.join("whole.usda");
    bake(shot, &whole, &[]);
    // As the farm template runs them: the first chunk binds (the template's
    // bind step does the same with --frames of one frame), then the other
    // three run at once and load.
    let chunks = ["1-6", "7-12", "13-18", "19-24"];
    let paths: Vec<PathBuf> = chunks.iter().map(|c| dir.join(format!("chunk.{c}.usda"))).collect();
    let first = bake(shot, &paths[0], &["--frames", chunks[0], "--store", s]);
    assert!(stderr(&first).contains("(built, written to the store)"), "{}", stderr(&first));
    let rest: Vec<std::process::Output> = std::thread::scope(|scope| {
        let handles: Vec<_> = (1..4)
            .map(|k| {
                let (p, c) = (&paths[k], chunks[k]);
                scope.spawn(move || bake(shot, p, &["--frames", c, "--store", s]))
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    eprintln!("chunk 1 bound in {:.0} ms (built)", bind_ms(&first));
    for (k, run) in rest.iter().enumerate() {
        assert!(stderr(run).contains("(loaded from the store)"), "chunk {}: {}", k + 2, stderr(run));
        eprintln!("chunk {} bound in {:.0} ms (loaded)", k + 2, bind_ms(run));
    }
    assert_eq!(blobs(&store).len(), 1, "one binding for the shot's one mesh");
    let stitched = dir.join("stitched.usda");
    let mut args = vec!["stitch"];
    args.extend(paths.iter().map(|p| p.to_str().unwrap()));
    args.extend(["--out", stitched.to_str().unwrap()]);
    let run = curvenet(&args);
    assert!(run.status.success(), "{}", stderr(&run));
    assert!(
        std::fs::read(&whole).unwrap() == std::fs::read(&stitched).unwrap(),
        "stitched chunks differ from the whole"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_binding_the_store_lost_is_written_again_and_deletes_reach_the_store() {
    let dir = temp_dir("store", "lost");
    let a = replica(&dir).await;
    let id = post_binding(&a, hand()).await.binding_id;
    let path = blobs(&dir).pop().unwrap();
    // Another replica's size limit (or an operator) deleted the file while A keeps the binding in memory.
    std::fs::remove_file(&path).unwrap();
    let again = post_binding(&a, hand()).await;
    assert!(again.cached, "found in A's memory");
    assert_eq!(blobs(&dir), vec![path.clone()], "a post hitting in memory did not write the lost binding again");
    let b = replica(&dir).await;
    let (status, _, _) = send(&b, get(&format!("/v1/bindings/{id}"))).await;
    assert_eq!(status, StatusCode::OK, "B does not find the rewritten binding");
    // A replica that never held the binding in memory deletes it from the store, and says so.
    let c = replica(&dir).await;
    let delete = || Request::delete(format!("/v1/bindings/{id}")).body(Body::empty()).unwrap();
    let (status, _, body) = send(&c, delete()).await;
    assert_eq!(status, StatusCode::NO_CONTENT, "{}", String::from_utf8_lossy(&body));
    assert!(blobs(&dir).is_empty(), "the stored file is still there");
    let (status, _, _) = send(&c, delete()).await;
    assert_eq!(status, StatusCode::NOT_FOUND, "deleting it twice");
    let _ = std::fs::remove_dir_all(&dir);
}

/// `curvenet ARGS` with extra environment variables.
fn curvenet_env(args: &[&str], env: &[(&str, &str)]) -> std::process::Output {
    let mut cmd = std::process::Command::new(env!("CARGO_BIN_EXE_curvenet"));
    cmd.args(args).current_dir(repo());
    for (k, v) in env {
        cmd.env(k, v);
    }
    cmd.output().expect("runs")
}

/// S3 settings pointing at a closed loopback port: a store that is down.
const S3_DOWN: [(&str, &str); 5] = [
    ("AWS_ACCESS_KEY_ID", "k"),
    ("AWS_SECRET_ACCESS_KEY", "s"),
    ("AWS_REGION", "us-east-1"),
    ("AWS_ENDPOINT_URL", "http://127.0.0.1:1"),
    ("AWS_ALLOW_HTTP", "true"),
];

#[test]
fn a_store_that_is_down_fails_serve_retryably_and_a_bake_goes_on_without_it() {
    // serve: 75 (a supervisor restarts it later), the store named once.
    let run = curvenet_env(&["serve", "--addr", "127.0.0.1:0", "--store", "s3://bucket/p"], &S3_DOWN);
    let err = stderr(&run);
    assert_eq!(run.status.code(), Some(75), "{err}");
    let line =
        err.lines().find(|l| l.starts_with("curvenet: error:")).unwrap_or_else(|| panic!("no error line: {err}"));
    assert_eq!(line.matches("binding store").count(), 1, "the store is named once: {line}");
    assert!(err.contains("s3://bucket/p") && err.contains("cannot list"), "{err}");
    // A location or configuration that cannot work is bad input: 2.
    let run = curvenet_env(&["serve", "--addr", "127.0.0.1:0", "--store", "ftp://host/x"], &[]);
    assert_eq!(run.status.code(), Some(2), "{}", stderr(&run));
    let mut plain_http = S3_DOWN;
    plain_http[4] = ("AWS_ALLOW_HTTP", "false");
    let run = curvenet_env(&["serve", "--addr", "127.0.0.1:0", "--store", "s3://bucket"], &plain_http);
    assert_eq!(run.status.code(), Some(2), "{}", stderr(&run));
    assert!(stderr(&run).contains("AWS_ALLOW_HTTP=true"), "{}", stderr(&run));
    // bake: warned, baked without the store, the same bytes.
    let dir = temp_dir("store", "down");
    let (plain, stored) = (dir.join("plain.usda"), dir.join("stored.usda"));
    bake(common::SHOT, &plain, &["--frames", "1-2"]);
    let run = curvenet_env(
        &["bake", common::SHOT, "--out", stored.to_str().unwrap(), "--frames", "1-2", "--store", "s3://bucket/p"],
        &S3_DOWN,
    );
    let err = stderr(&run);
    assert!(run.status.success(), "{err}");
    assert!(err.contains("binding without the store") && err.contains("s3://bucket/p"), "{err}");
    assert!(std::fs::read(&plain).unwrap() == std::fs::read(&stored).unwrap(), "the bake without its store differs");
    // A configuration mistake fails the bake (every chunk would fail alike).
    let run = curvenet_env(
        &["bake", common::SHOT, "--out", stored.to_str().unwrap(), "--store", "s3://bucket"],
        &[("AWS_ENDPOINT_URL", "not a url")],
    );
    assert_eq!(run.status.code(), Some(2), "{}", stderr(&run));
    assert!(stderr(&run).contains("AWS_ENDPOINT_URL"), "{}", stderr(&run));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_store_limit_below_one_binding_is_warned_about() {
    let dir = temp_dir("store", "tiny");
    let store = dir.join("store");
    let out = dir.join("out.usda");
    let args = ["--frames", "1", "--store", store.to_str().unwrap(), "--store-bytes", "1000"];
    let run = bake(common::SHOT, &out, &args);
    assert!(stderr(&run).contains("alone is larger than --store-bytes (1000)"), "{}", stderr(&run));
    let _ = std::fs::remove_dir_all(&dir);
}

/// The stored file of `id` in `dir`.
fn blob_of(dir: &Path, id: &str) -> PathBuf {
    dir.join(format!("{id}.cnb"))
}

/// `blob` with its meta JSON changed by `edit` and its checksum made right
/// again: what only a deliberate forger (or another release) writes.
fn with_meta(blob: &[u8], edit: impl FnOnce(&mut Value)) -> Vec<u8> {
    let len = u32::from_le_bytes(blob[48..52].try_into().unwrap()) as usize;
    let mut meta: Value = serde_json::from_slice(&blob[64..64 + len]).unwrap();
    edit(&mut meta);
    let meta = serde_json::to_vec(&meta).unwrap();
    let mut out = blob[..64].to_vec();
    out[48..52].copy_from_slice(&(meta.len() as u32).to_le_bytes());
    out[56..64].copy_from_slice(&blake3::hash(&meta).as_bytes()[..8]);
    out.extend_from_slice(&meta);
    out.extend_from_slice(&blob[64 + len..]);
    out
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_forged_file_is_refused_and_another_releases_file_is_left_in_place() {
    let dir = temp_dir("store", "forged");
    let a = replica(&dir).await;
    let id = post_binding(&a, hand()).await.binding_id;
    let mut other = hand().clone();
    other.curvenets[0].sample_density *= 1.5;
    let other_id = post_binding(&a, &other).await.binding_id;
    assert_ne!(id, other_id);
    // The other binding's file under this id's name, its header key rewritten.
    let mut forged = std::fs::read(blob_of(&dir, &other_id)).unwrap();
    let key: Vec<u8> = (0..32).map(|i| u8::from_str_radix(&id[2 * i..2 * i + 2], 16).unwrap()).collect();
    forged[16..48].copy_from_slice(&key);
    std::fs::write(blob_of(&dir, &id), &forged).unwrap();
    let b = replica(&dir).await;
    let (status, _, body) = send(&b, get(&format!("/v1/bindings/{id}"))).await;
    assert_eq!(status, StatusCode::NOT_FOUND, "a forged file was served: {}", String::from_utf8_lossy(&body));
    assert_eq!(metric_opt(&b, "curvenet_store_rejected_total").await, Some(1.0));
    assert!(!blob_of(&dir, &id).exists(), "the forged file was kept");

    // A file of another release: refused, but left for that release's replicas.
    let foreign =
        with_meta(&std::fs::read(blob_of(&dir, &other_id)).unwrap(), |m| m["service_version"] = "0.0.1-other".into());
    std::fs::write(blob_of(&dir, &other_id), &foreign).unwrap();
    let c = replica(&dir).await;
    let (status, _, _) = send(&c, get(&format!("/v1/bindings/{other_id}"))).await;
    assert_eq!(status, StatusCode::NOT_FOUND);
    assert_eq!(metric_opt(&c, "curvenet_store_rejected_total").await, Some(1.0));
    assert!(std::fs::read(blob_of(&dir, &other_id)).unwrap() == foreign, "another release's file was deleted");
    // This release's build overwrites it, and the next replica reads it.
    assert!(!post_binding(&c, &other).await.cached);
    assert!(std::fs::read(blob_of(&dir, &other_id)).unwrap() != foreign, "not overwritten");
    let d = replica(&dir).await;
    let (status, _, _) = send(&d, get(&format!("/v1/bindings/{other_id}"))).await;
    assert_eq!(status, StatusCode::OK);
    let _ = std::fs::remove_dir_all(&dir);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn garbage_under_an_entry_name_is_refused_after_its_first_bytes() {
    let dir = temp_dir("store", "garbage");
    let id = "ab".repeat(32);
    // 256 MiB of zeros (sparse): never read whole.
    let f = std::fs::File::create(blob_of(&dir, &id)).unwrap();
    f.set_len(256 << 20).unwrap();
    drop(f);
    let a = replica(&dir).await;
    let (status, _, _) = send(&a, get(&format!("/v1/bindings/{id}"))).await;
    assert_eq!(status, StatusCode::NOT_FOUND);
    assert_eq!(metric_opt(&a, "curvenet_store_rejected_total").await, Some(1.0));
    let read = metric_opt(&a, "curvenet_store_read_bytes_total").await.unwrap_or(0.0);
    assert!(read <= 8.0, "{read} bytes of garbage were read");
    assert!(!blob_of(&dir, &id).exists());
    let _ = std::fs::remove_dir_all(&dir);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stored_binding_too_large_for_this_cache_answers_507_without_a_build() {
    let dir = temp_dir("store", "too-large");
    let a = replica(&dir).await;
    let posted = post_binding(&a, hand()).await;
    let small = Config { solve_threads: 2, cache_bytes: posted.size_bytes / 2, ..Config::default() };
    let b = app(AppState::open(small, None, dir.to_str().unwrap(), None).await.unwrap());
    let id = &posted.binding_id;
    let (status, _, body) = send(&b, get(&format!("/v1/bindings/{id}"))).await;
    assert_eq!(status, StatusCode::INSUFFICIENT_STORAGE, "{}", String::from_utf8_lossy(&body));
    assert!(String::from_utf8_lossy(&body).contains("cache_too_small"));
    let (status, _) = frame_points(&b, id).await;
    assert_eq!(status, StatusCode::INSUFFICIENT_STORAGE);
    let (status, _, _) = send(&b, post_json("/v1/bindings", hand())).await;
    assert_eq!(status, StatusCode::INSUFFICIENT_STORAGE);
    assert_eq!(metric_opt(&b, "curvenet_bindings_computed_total").await.unwrap_or(0.0), 0.0, "built it again");
    let _ = std::fs::remove_dir_all(&dir);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stored_file_larger_than_the_cache_is_not_read() {
    let dir = temp_dir("store", "sparse");
    let a = replica(&dir).await;
    let id = post_binding(&a, hand()).await.binding_id;
    // The real blob, extended (sparse) past the default cache's 2 GiB: a
    // file that starts like a blob and is too large to be one.
    let f = std::fs::OpenOptions::new().write(true).open(blob_of(&dir, &id)).unwrap();
    f.set_len(3 << 30).unwrap();
    drop(f);
    let b = replica(&dir).await;
    let (status, _, body) = send(&b, get(&format!("/v1/bindings/{id}"))).await;
    assert_eq!(status, StatusCode::INSUFFICIENT_STORAGE, "{}", String::from_utf8_lossy(&body));
    assert_eq!(metric_opt(&b, "curvenet_store_read_bytes_total").await.unwrap_or(0.0), 0.0, "the file was read");
    let _ = std::fs::remove_dir_all(&dir);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_delete_the_store_cannot_carry_out_is_503_not_204() {
    let dir = temp_dir("store", "delete-fails");
    let a = replica(&dir).await;
    let id = post_binding(&a, hand()).await.binding_id;
    // Something the store cannot delete under the entry's name (a directory).
    std::fs::remove_file(blob_of(&dir, &id)).unwrap();
    std::fs::create_dir(blob_of(&dir, &id)).unwrap();
    let delete = || Request::delete(format!("/v1/bindings/{id}")).body(Body::empty()).unwrap();
    let (status, headers, body) = send(&a, delete()).await;
    assert_eq!(status, StatusCode::SERVICE_UNAVAILABLE, "{}", String::from_utf8_lossy(&body));
    assert!(headers.contains_key("retry-after"));
    assert!(String::from_utf8_lossy(&body).contains("retry the DELETE"));
    // Gone from memory all the same; once the store can delete, the DELETE answers 404 (nothing left).
    std::fs::remove_dir(blob_of(&dir, &id)).unwrap();
    let (status, _, _) = send(&a, delete()).await;
    assert_eq!(status, StatusCode::NOT_FOUND);
    let _ = std::fs::remove_dir_all(&dir);
}
