//! `curvenet bake --frames` per chunk and `curvenet stitch` as a farm runs
//! them: the stitched chunks are the whole-range bake byte for byte, reruns
//! and concurrent runs of a chunk write the same bytes, and every refusal
//! exits 2 naming the file, prim and frame.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use curvenet_schema::usd::{PrimPoints, write_points_overrides};

mod common;
use common::{SHOT, curvenet, repo, stderr};

/// A fresh, empty directory for one test.
fn temp_dir(tag: &str) -> PathBuf {
    common::temp_dir("stitch", tag)
}

fn dir_names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> =
        std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    v.sort();
    v
}

fn bake(out: &Path, frames: &str) {
    let run = curvenet(&["bake", SHOT, "--out", out.to_str().unwrap(), "--frames", frames, "--quiet"]);
    assert!(run.status.success(), "bake {frames}: {}", stderr(&run));
}

fn stitch(chunks: &[&Path], out: &Path, extra: &[&str]) -> Output {
    let mut args = vec!["stitch"];
    args.extend(chunks.iter().map(|p| p.to_str().unwrap()));
    args.extend(["--out", out.to_str().unwrap()]);
    args.extend_from_slice(extra);
    curvenet(&args)
}

fn read(p: &Path) -> Vec<u8> {
    std::fs::read(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// Asserts a refusal: exit 2, every `needle` in the message, OUTPUT untouched.
fn refused(run: &Output, needles: &[&str]) {
    let err = stderr(run);
    assert_eq!(run.status.code(), Some(2), "{err}");
    for n in needles {
        assert!(err.contains(n), "{n:?} not in: {err}");
    }
}

#[test]
fn stitched_chunks_are_the_whole_bake_byte_for_byte_in_both_formats() {
    let dir = temp_dir("whole");
    for ext in ["usda", "usdc"] {
        let whole = dir.join(format!("whole.{ext}"));
        bake(&whole, "1-24");
        let chunks: Vec<PathBuf> = ["1-8", "9-16", "17-24"]
            .iter()
            .map(|r| {
                let p = dir.join(format!("{r}.{ext}"));
                bake(&p, r);
                p
            })
            .collect();
        // The chunks are real parts: each holds its own frames only.
        let chunk_len = read(&chunks[1]).len();
        assert!(chunk_len < read(&whole).len() / 2, "{ext}: a chunk is not smaller than the whole bake");

        // Any order of the chunks.
        let out = dir.join(format!("stitched.{ext}"));
        let run = stitch(&[&chunks[2], &chunks[0], &chunks[1]], &out, &[]);
        assert!(run.status.success(), "{}", stderr(&run));
        assert!(stderr(&run).contains("stitched 3 chunks (1 mesh, 24 frames, time codes 1..24)"), "{}", stderr(&run));
        assert!(read(&out) == read(&whole), "{ext}: the stitched chunks differ from the whole-range bake");

        // A rerun of a chunk rewrites the same bytes; a chunk given twice, or
        // chunks that overlap and agree, stitch to the same layer.
        let before = read(&chunks[1]);
        bake(&chunks[1], "9-16");
        assert!(read(&chunks[1]) == before, "{ext}: a rerun chunk wrote different bytes");
        let overlap = dir.join(format!("5-12.{ext}"));
        bake(&overlap, "5-12");
        let run = stitch(&[&chunks[0], &overlap, &chunks[1], &chunks[1], &chunks[2]], &out, &["--quiet"]);
        assert!(run.status.success() && run.stderr.is_empty(), "{}", stderr(&run));
        assert!(read(&out) == read(&whole), "{ext}: overlapping chunks stitched differently");

        // --frames keeps a sub-range: the bake of that range, byte for byte.
        let part = dir.join(format!("part.{ext}"));
        bake(&part, "6-19");
        let run = stitch(&[&chunks[0], &chunks[1], &chunks[2]], &out, &["--frames", "6-19"]);
        assert!(run.status.success(), "{}", stderr(&run));
        assert!(read(&out) == read(&part), "{ext}: stitch --frames 6-19 differs from bake --frames 6-19");

        // OUTPUT may be one of the chunks (all are read before it is replaced).
        let run = stitch(&[&chunks[0], &chunks[1], &chunks[2]], &chunks[0], &[]);
        assert!(run.status.success(), "{}", stderr(&run));
        assert!(read(&chunks[0]) == read(&whole), "{ext}: stitching over a chunk");
        bake(&chunks[0], "1-8");
    }
    // Chunks of either format stitch to either format.
    let out = dir.join("mixed.usdc");
    let run = stitch(&[&dir.join("1-8.usda"), &dir.join("9-16.usdc"), &dir.join("17-24.usda")], &out, &[]);
    assert!(run.status.success(), "{}", stderr(&run));
    assert!(read(&out) == read(&dir.join("whole.usdc")), "mixed chunk formats");
    assert!(dir_names(&dir).iter().all(|n| !n.starts_with('.')), "temporary files left: {:?}", dir_names(&dir));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn concurrent_bakes_of_one_chunk_to_one_file_leave_one_whole_file() {
    // Farm retries and duplicate dispatches: several processes write the same
    // chunk at once. Each writes its own temporary file and renames it; the
    // survivor is a whole layer with the same bytes as a lone run.
    let dir = temp_dir("concurrent");
    let alone = dir.join("alone.usdc");
    bake(&alone, "1-6");
    let shared = dir.join("shared.usdc");
    let runs: Vec<_> = (0..4)
        .map(|_| {
            Command::new(env!("CARGO_BIN_EXE_curvenet"))
                .args(["bake", SHOT, "--out", shared.to_str().unwrap(), "--frames", "1-6", "--quiet", "--threads", "1"])
                .current_dir(repo())
                .spawn()
                .unwrap()
        })
        .collect();
    for mut r in runs {
        assert!(r.wait().unwrap().success());
    }
    assert!(read(&shared) == read(&alone), "concurrent bakes left different bytes");
    assert_eq!(dir_names(&dir), ["alone.usdc", "shared.usdc"], "temporary files left behind");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn refusals_exit_2_name_the_file_prim_and_frame_and_leave_the_output() {
    let dir = temp_dir("refuse");
    let (a, b, c) = (dir.join("1-8.usda"), dir.join("9-16.usda"), dir.join("17-24.usda"));
    bake(&a, "1-8");
    bake(&b, "9-16");
    bake(&c, "17-24");
    let out = dir.join("out.usda");
    std::fs::write(&out, "previous").unwrap();
    let untouched = || assert_eq!(std::fs::read_to_string(&out).unwrap(), "previous");

    // A missing chunk: a hole in the range.
    refused(&stitch(&[&a, &c], &out, &[]), &["frames 9-16 are in no chunk", "1-8.usda (1..8)", "17-24.usda (17..24)"]);
    refused(&stitch(&[&a, &b], &out, &["--frames", "1-20"]), &["frames 17-20 are in no chunk"]);
    untouched();

    // Overlapping chunks that disagree (a chunk of the shot before a change).
    let text = std::fs::read_to_string(&b).unwrap();
    let at = text.find("9.0: [(").expect("frame 9") + "9.0: [(".len();
    let comma = at + text[at..].find(',').unwrap();
    let stale = dir.join("stale-9-16.usda");
    std::fs::write(&stale, format!("{}12.5{}", &text[..at], &text[comma..])).unwrap();
    let overlap = dir.join("5-12.usda");
    bake(&overlap, "5-12");
    refused(
        &stitch(&[&a, &overlap, &stale, &c], &out, &[]),
        &["5-12.usda and ", "stale-9-16.usda disagree on /Hand/Mesh at frame 9: point 0 is"],
    );
    // Frames outside --frames are not read into the result, so a stale chunk
    // disagreeing only there is harmless.
    let run = stitch(&[&a, &overlap, &stale], &out, &["--frames", "1-8"]);
    assert!(run.status.success(), "{}", stderr(&run));
    std::fs::write(&out, "previous").unwrap();

    // Different prims, or the same prim with another vertex count.
    let renamed = dir.join("renamed.usda");
    std::fs::write(&renamed, text.replace("over \"Mesh\"", "over \"Body\"")).unwrap();
    refused(
        &stitch(&[&a, &renamed], &out, &[]),
        &["1-8.usda and ", "renamed.usda bake different prims: /Hand/Mesh is in ", "1-8.usda only"],
    );
    let doc = {
        let t = std::fs::read_to_string(&a).unwrap();
        let start = t.find("documentation = \"").unwrap() + "documentation = \"".len();
        let end = start + t[start..].find('"').unwrap();
        t[start..end].replace("\\`", "`")
    };
    let small = dir.join("small.usdc");
    let points = PrimPoints { prim: "/Hand/Mesh".into(), samples: vec![(9.0, vec![[0.0; 3]; 10])] };
    write_points_overrides(&small, vec![points], (9.0, 9.0), &doc).unwrap();
    refused(
        &stitch(&[&a, &small], &out, &[]),
        &["small.usdc: /Hand/Mesh has 10 points at time code 9, but 1400 in ", "1-8.usda"],
    );

    // Chunks of different bakes (another shot: another doc string).
    let other = dir.join("skinned.usda");
    let run = curvenet(&[
        "bake",
        "fixtures/shots/hand_skinned/shot.usda",
        "--out",
        other.to_str().unwrap(),
        "--frames",
        "9-12",
        "--quiet",
    ]);
    assert!(run.status.success(), "{}", stderr(&run));
    refused(&stitch(&[&a, &other], &out, &[]), &["skinned.usda come from different bakes", "hand_skinned/shot.usda"]);

    // Not a bake layer: the shot itself, a layer with a def, not USD at all, no file.
    refused(
        &stitch(&[&repo().join(SHOT)], &out, &[]),
        &["hand_wave/shot.usda: not a curvenet bake layer: /: authors defaultPrim"],
    );
    let def = dir.join("def.usda");
    std::fs::write(&def, text.replacen("over \"Hand\"", "def Xform \"Hand\"", 1)).unwrap();
    refused(&stitch(&[&a, &def], &out, &[]), &["def.usda: not a curvenet bake layer: /Hand:"]);
    let junk = dir.join("junk.usdc");
    std::fs::write(&junk, "not a layer").unwrap();
    refused(&stitch(&[&a, &junk], &out, &[]), &["junk.usdc: cannot decode the layer"]);
    refused(&stitch(&[&a, &dir.join("nope.usdc")], &out, &[]), &["cannot read chunk ", "nope.usdc"]);
    untouched();

    // Bad commands: 2; an output directory that does not exist: 75, before any read.
    refused(&stitch(&[&a], &dir.join("out.obj"), &[]), &[".usda or .usdc"]);
    refused(&stitch(&[&a], &out, &["--frames", "8-1"]), &["8-1"]);
    let run = stitch(&[&dir.join("nope.usdc")], &dir.join("no/such/dir/out.usda"), &[]);
    assert_eq!(run.status.code(), Some(75), "{}", stderr(&run));
    assert!(stderr(&run).contains("no/such/dir"), "{}", stderr(&run));
    let run = curvenet(&["stitch", "--out", out.to_str().unwrap()]);
    assert_eq!(run.status.code(), Some(2), "no chunks: {}", stderr(&run));
    untouched();
    assert!(dir_names(&dir).iter().all(|n| !n.starts_with('.')), "temporary files left: {:?}", dir_names(&dir));
    let help = String::from_utf8(curvenet(&["stitch", "--help"]).stdout).unwrap();
    assert!(help.contains("byte for byte") && help.contains("75"), "{help}");
    std::fs::remove_dir_all(&dir).unwrap();
}
