//! Fuzz-style property test of the USD reader: a small valid curvenet stage,
//! mutated (numbers made hostile, lines dropped or repeated, junk inserted,
//! the text cut short), read as the bake and the service read a stage. The
//! reader must never panic, and the peak bytes it allocates must stay within
//! a bound derived from the file's size (counted by this test binary's
//! allocator on the reading thread). Seeded; a thousand cases per run.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use curvenet_schema::usd::Stage;
use proptest::prelude::*;
use proptest::test_runner::{Config, RngSeed};

struct Counting;

thread_local! {
    static LIVE: Cell<isize> = const { Cell::new(0) };
    static PEAK: Cell<isize> = const { Cell::new(0) };
}

fn track(delta: isize) {
    let _ = LIVE.try_with(|live| {
        let now = live.get() + delta;
        live.set(now);
        let _ = PEAK.try_with(|peak| peak.set(peak.get().max(now)));
    });
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        track(layout.size() as isize);
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        track(-(layout.size() as isize));
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        track(new_size as isize - layout.size() as isize);
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn peak_of<T>(f: impl FnOnce() -> T) -> (T, usize) {
    let start = LIVE.with(Cell::get);
    PEAK.with(|p| p.set(start));
    let r = f();
    ((r), (PEAK.with(Cell::get) - start).max(0) as usize)
}

/// A 3 × 3 quad grid with a two-spline curvenet animated over two frames,
/// a blend shape and its skeleton animation left out (optional in the contract).
const STAGE: &str = r#"#usda 1.0
(
    defaultPrim = "Grid"
    endTimeCode = 2
    startTimeCode = 1
)

def Xform "Grid"
{
    def Mesh "Mesh"
    {
        rel curvenet:curvenets = </Grid/Curvenet>
        int[] faceVertexCounts = [4, 4, 4, 4, 4, 4, 4, 4, 4]
        int[] faceVertexIndices = [0, 1, 5, 4, 1, 2, 6, 5, 2, 3, 7, 6, 4, 5, 9, 8, 5, 6, 10, 9, 6, 7, 11, 10, 8, 9, 13, 12, 9, 10, 14, 13, 10, 11, 15, 14]
        point3f[] points = [(0, 0, 0), (1, 0, 0), (2, 0, 0), (3, 0, 0), (0, 1, 0), (1, 1, 0), (2, 1, 0), (3, 1, 0), (0, 2, 0), (1, 2, 0), (2, 2, 0), (3, 2, 0), (0, 3, 0), (1, 3, 0), (2, 3, 0), (3, 3, 0)]
        point3f[] points.timeSamples = {
            1: [(0, 0, 0), (1, 0, 0), (2, 0, 0), (3, 0, 0), (0, 1, 0), (1, 1, 0), (2, 1, 0), (3, 1, 0), (0, 2, 0), (1, 2, 0), (2, 2, 0), (3, 2, 0), (0, 3, 0), (1, 3, 0), (2, 3, 0), (3, 3, 0)],
        }
    }

    def BasisCurves "Curvenet"
    {
        uniform token basis = "bezier"
        uniform token type = "cubic"
        uniform token wrap = "nonperiodic"
        uniform float curvenet:sampleDensity = 5
        int[] curveVertexCounts = [4, 4]
        point3f[] primvars:curvenet:cv = [(0.5, 1.5, 0), (1, 1.5, 0), (1.5, 1.5, 0), (2, 1.5, 0), (2.2, 1.5, 0), (2.4, 1.5, 0), (2.6, 1.5, 0)] (
            interpolation = "vertex"
        )
        point3f[] primvars:curvenet:cv.timeSamples = {
            1: [(0.5, 1.5, 0), (1, 1.5, 0), (1.5, 1.5, 0), (2, 1.5, 0), (2.2, 1.5, 0), (2.4, 1.5, 0), (2.6, 1.5, 0)],
            2: [(0.5, 1.5, 0.1), (1, 1.5, 0.1), (1.5, 1.5, 0.1), (2, 1.5, 0.1), (2.2, 1.5, 0.1), (2.4, 1.5, 0.1), (2.6, 1.5, 0.1)],
        }
        int[] primvars:curvenet:cv:indices = [0, 1, 2, 3, 3, 4, 5, 6]
        point3f[] points = [(0.5, 1.5, 0), (1, 1.5, 0), (1.5, 1.5, 0), (2, 1.5, 0), (2, 1.5, 0), (2.2, 1.5, 0), (2.4, 1.5, 0), (2.6, 1.5, 0)]
    }
}
"#;

/// Reads `text` as the bake does; returns whether it was read whole.
fn read(path: &std::path::Path) -> bool {
    let Ok(stage) = Stage::open(path) else { return false };
    let _ = stage.time_code_range();
    let Ok(meshes) = stage.deformed_meshes() else { return false };
    let mut whole = true;
    for mesh in &meshes {
        whole &= stage.rest_points(mesh, Some(1.0)).is_ok();
        whole &= stage.blend_shape_weights(mesh, Some(1.0)).is_ok() || mesh.blend_shapes.is_empty();
        for net in &mesh.curvenets {
            match stage.curvenet(net) {
                Ok(c) => whole &= stage.posed_pool(&c, Some(2.0)).is_ok(),
                Err(_) => whole = false,
            }
        }
    }
    whole
}

/// One edit of the text: (kind, where, a hostile token).
fn edit() -> impl Strategy<Value = (u8, usize, &'static str)> {
    let token = prop_oneof![
        Just("1e308"),
        Just("-1e308"),
        Just("nan"),
        Just("inf"),
        Just("4294967295"),
        Just("-1"),
        Just("99999999999999999999"),
        Just("0"),
        Just("[]"),
        Just("("),
        Just("]"),
        Just("@/etc/passwd@"),
        Just("\""),
        Just("float3[]"),
    ];
    (0u8..5, any::<usize>(), token)
}

fn apply(text: &str, (kind, at, token): (u8, usize, &str)) -> String {
    if text.is_empty() {
        return token.to_string();
    }
    let lines: Vec<&str> = text.lines().collect();
    match kind {
        // Replace the number (or word) at a position with the token.
        0 => {
            let chars: Vec<char> = text.chars().collect();
            let mut i = at % chars.len();
            while i < chars.len() && !chars[i].is_ascii_alphanumeric() {
                i += 1;
            }
            let mut j = i;
            while j < chars.len() && (chars[j].is_ascii_alphanumeric() || chars[j] == '.' || chars[j] == '-') {
                j += 1;
            }
            let mut out: String = chars[..i].iter().collect();
            out.push_str(token);
            out.extend(&chars[j..]);
            out
        }
        // Drop a line.
        1 | 2 if lines.is_empty() => text.to_string(),
        1 => {
            let k = at % lines.len();
            lines.iter().enumerate().filter(|(i, _)| *i != k).map(|(_, l)| *l).collect::<Vec<_>>().join("\n")
        }
        // Repeat a line.
        2 => {
            let k = at % lines.len();
            let mut out = lines.clone();
            out.insert(k, lines[k]);
            out.join("\n")
        }
        // Insert the token anywhere.
        3 => {
            let mut i = at % text.len();
            while !text.is_char_boundary(i) {
                i -= 1;
            }
            format!("{}{token}{}", &text[..i], &text[i..])
        }
        // Cut the text short.
        _ => {
            let mut i = at % text.len();
            while !text.is_char_boundary(i) {
                i -= 1;
            }
            text[..i].to_string()
        }
    }
}

#[test]
fn the_unmutated_stage_is_read_whole() {
    let dir = std::env::temp_dir().join(format!("curvenet-fuzz-usd-base-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("stage.usda");
    std::fs::write(&path, STAGE).unwrap();
    let (whole, peak) = peak_of(|| read(&path));
    assert!(whole, "the base stage must be read whole");
    println!("the base stage ({} bytes) peaks at {peak} bytes", STAGE.len());
    std::fs::remove_dir_all(&dir).unwrap();
}

proptest! {
    #![proptest_config(Config { cases: 1000, rng_seed: RngSeed::Fixed(15), failure_persistence: None, ..Config::default() })]

    #[test]
    fn mutated_stages_never_panic_the_reader_nor_overallocate(edits in prop::collection::vec(edit(), 1..5)) {
        let mut text = STAGE.to_string();
        for e in edits {
            text = apply(&text, e);
        }
        let dir = std::env::temp_dir().join(format!("curvenet-fuzz-usd-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("stage.usda");
        std::fs::write(&path, &text).unwrap();
        let (_, peak) = peak_of(|| read(&path));
        // openusd's parser and composition hold a fixed amount besides the
        // file; the rest must grow with the file, not with what it claims.
        let bound = 256 * text.len() + (1 << 20);
        prop_assert!(peak <= bound, "{peak} bytes for a {}-byte stage", text.len());
    }
}
