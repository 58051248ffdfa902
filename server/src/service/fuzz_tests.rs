//! Fuzz-style property tests (seeded proptest, thousands of cases per run)
//! over what a client controls before any binding work: the binary frame
//! parser and the JSON binding validator (parse, `validate`, the options,
//! the work prediction). Properties: never a panic, and never an
//! allocation beyond a bound derived from the body size (peak bytes live on
//! the parsing thread, counted by this test binary's allocator).

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use proptest::prelude::*;
use proptest::test_runner::{Config, RngSeed};
use serde_json::{Value, json};

use crate::binary::{Expected, parse};
use crate::error::Code;

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

/// Runs `f` and returns its result and the peak bytes it had allocated at once on this thread.
fn peak_of<T>(f: impl FnOnce() -> T) -> (T, usize) {
    let start = LIVE.with(Cell::get);
    PEAK.with(|p| p.set(start));
    let r = f();
    let peak = PEAK.with(Cell::get) - start;
    (r, peak.max(0) as usize)
}

/// The allowed peak for a body of `n` bytes.
fn bound(n: usize) -> usize {
    64 * n + (64 << 10)
}

fn config(cases: u32) -> Config {
    Config { cases, rng_seed: RngSeed::Fixed(15), failure_persistence: None, ..Config::default() }
}

const POOLS: [usize; 2] = [5, 3];
const EXPECTED: Expected<'static> =
    Expected { pools: &POOLS, vertices: 10, blend_shapes: 2, joints: Some(3), cage: Some(4), max_frames: 50 };

/// An array entry of a binary header, hostile or not.
fn array() -> impl Strategy<Value = Value> {
    let name = prop_oneof![
        Just("posed"),
        Just("rest"),
        Just("blend_shape_weights"),
        Just("joint_transforms"),
        Just("points"),
        Just("")
    ];
    let index = prop_oneof![Just(None), (0u64..4).prop_map(Some), Just(Some(u32::MAX as u64)), Just(Some(1 << 40))];
    let dtype = prop_oneof![Just("f32"), Just("<f4"), Just("f64"), Just("")];
    let dim = prop_oneof![0u64..12, Just(u32::MAX as u64), Just(1 << 32), Just(u64::MAX)];
    let shape = prop::collection::vec(dim, 0..4);
    (name, index, dtype, shape).prop_map(|(name, index, dtype, shape)| {
        let mut a = json!({"name": name, "dtype": dtype, "shape": shape});
        if let Some(i) = index {
            a["index"] = json!(i);
        }
        a
    })
}

fn frame_header() -> impl Strategy<Value = Value> {
    (prop::collection::vec(array(), 0..5), any::<bool>())
        .prop_map(|(arrays, g)| json!({"arrays": arrays, "gradients": g}))
}

fn body_of(header: &Value, data_floats: usize, garbage_len: Option<u32>) -> Vec<u8> {
    let h = serde_json::to_vec(header).unwrap();
    let mut out = garbage_len.unwrap_or(h.len() as u32).to_le_bytes().to_vec();
    out.extend_from_slice(&h);
    out.extend(std::iter::repeat_n(0x3f, data_floats * 4));
    out
}

fn check_parse(body: &[u8]) -> Result<(), TestCaseError> {
    let (r, peak) = peak_of(|| parse(body, &EXPECTED));
    prop_assert!(peak <= bound(body.len()), "{peak} bytes for a body of {}", body.len());
    match r {
        Ok((frames, _)) => {
            prop_assert!(frames.len() <= EXPECTED.max_frames);
            for f in &frames {
                prop_assert!(f.posed.as_ref().is_none_or(|p| p.len() == POOLS.len()));
                for (k, p) in f.posed.iter().flatten().enumerate() {
                    prop_assert!(p.as_ref().is_none_or(|p| p.len() == POOLS[k]));
                }
                prop_assert!(f.rest.as_ref().is_none_or(|r| r.len() == EXPECTED.vertices));
                prop_assert!(f.blend_shape_weights.as_ref().is_none_or(|w| w.len() == EXPECTED.blend_shapes));
                prop_assert!(f.joint_transforms.as_ref().is_none_or(|t| Some(t.len()) == EXPECTED.joints));
            }
        }
        Err(e) => prop_assert!(matches!(
            e.code,
            Code::MalformedBinary | Code::CountMismatch | Code::IndexOutOfRange | Code::LimitExceeded
        )),
    }
    Ok(())
}

proptest! {
    #![proptest_config(config(3000))]

    #[test]
    fn binary_frames_of_any_bytes_never_panic_nor_overallocate(body in prop::collection::vec(any::<u8>(), 0..2048)) {
        check_parse(&body)?;
    }

    #[test]
    fn binary_frames_with_hostile_headers_never_panic_nor_overallocate(
        frames in prop::collection::vec(frame_header(), 1..4),
        batch in any::<bool>(),
        many in prop_oneof![Just(0usize), Just(60), Just(2000)],
        data in 0usize..200,
        garbage in prop_oneof![Just(None), any::<u32>().prop_map(Some)],
    ) {
        let header = if batch {
            let mut all = frames.clone();
            all.extend(std::iter::repeat_n(json!({}), many));
            json!({"frames": all})
        } else {
            frames[0].clone()
        };
        check_parse(&body_of(&header, data, garbage))?;
    }
}

/// A small valid binding request: a 3 × 3 quad grid with one curvenet.
fn base_request() -> Value {
    let mut points = Vec::new();
    for j in 0..4 {
        for i in 0..4 {
            points.push(json!([i as f64, j as f64, 0.0]));
        }
    }
    let mut counts = Vec::new();
    let mut indices = Vec::new();
    for j in 0..3u32 {
        for i in 0..3u32 {
            let v = j * 4 + i;
            counts.push(4);
            indices.extend([v, v + 1, v + 5, v + 4]);
        }
    }
    json!({
        "face_vertex_counts": counts,
        "face_vertex_indices": indices,
        "projection_points": points,
        "curvenets": [{"pool": [[0.5, 1.5, 0.0], [1.2, 1.5, 0.0], [1.8, 1.5, 0.0], [2.5, 1.5, 0.0]], "splines": [[0, 1, 2, 3]], "sample_density": 5.0}],
        "blend_shapes": [{"name": "s", "offsets": [[0.0, 0.0, 0.1]], "point_indices": [5]}],
    })
}

/// Hostile numbers and indices.
fn number() -> impl Strategy<Value = Value> {
    prop_oneof![
        (-10.0f64..10.0).prop_map(|x| json!(x)),
        Just(json!(1e300)),
        Just(json!(-1e300)),
        Just(json!(1e-300)),
        Just(json!(0.0)),
        Just(json!(1e16)),
        any::<u32>().prop_map(|x| json!(x)),
        Just(json!(u32::MAX)),
        Just(json!(-1)),
        Just(json!("x")),
        Just(json!(null)),
    ]
}

/// A mutation of the base request: (path of keys and indices, new value).
fn mutation() -> impl Strategy<Value = (usize, usize, Value)> {
    (0usize..9, 0usize..64, number())
}

fn mutate(req: &mut Value, (what, at, v): &(usize, usize, Value)) {
    // Sets element `at` (modulo the length) of the array at `pointer`, if there is one.
    let set = |req: &mut Value, pointer: &str, v: &Value| {
        if let Some(a) = req.pointer_mut(pointer).and_then(Value::as_array_mut)
            && !a.is_empty()
        {
            let n = a.len();
            a[at % n] = v.clone();
        }
    };
    match what {
        0 => set(req, "/face_vertex_counts", v),
        1 => set(req, "/face_vertex_indices", v),
        2 => set(req, &format!("/projection_points/{}", at % 16), v),
        3 => set(req, &format!("/curvenets/0/pool/{}", at % 4), v),
        4 => set(req, "/curvenets/0/splines/0", v),
        5 => {
            if let Some(d) = req.pointer_mut("/curvenets/0/sample_density") {
                *d = v.clone();
            }
        }
        6 => set(req, "/blend_shapes/0/point_indices", v),
        7 => {
            // Repeat the spline (many segments).
            let n = (at * at) % 4000;
            if let Some(s) = req.pointer("/curvenets/0/splines/0").cloned()
                && let Some(splines) = req.pointer_mut("/curvenets/0/splines")
            {
                *splines = json!(vec![s; n]);
            }
        }
        _ => {
            // Empty a required array.
            let keys = ["projection_points", "curvenets", "face_vertex_counts", "blend_shapes"];
            req[keys[at % 4]] = json!([]);
        }
    }
}

proptest! {
    #![proptest_config(config(2000))]

    #[test]
    fn the_binding_validator_never_panics_nor_overallocates(
        mutations in prop::collection::vec(mutation(), 0..6),
        scale in prop_oneof![Just(1.0f64), Just(1e6), Just(1e-9)],
    ) {
        let mut req = base_request();
        for m in &mutations {
            mutate(&mut req, m);
        }
        if scale != 1.0
            && let Some(p) = req.pointer_mut("/curvenets/0/pool").and_then(Value::as_array_mut)
        {
            for q in p {
                if let Some(q) = q.as_array_mut() {
                    for x in q {
                        if let Some(f) = x.as_f64() {
                            *x = json!(f * scale);
                        }
                    }
                }
            }
        }
        let body = serde_json::to_vec(&req).unwrap();
        let limits = crate::limits::WorkLimits::default();
        let (r, peak) = peak_of(|| -> Result<(), crate::error::ServiceError> {
            let parsed: curvenet_schema::wire::BindingRequest = crate::extract::parse_json(&body)?;
            crate::request::validate(&parsed)?;
            crate::request::EffectiveOptions::of(&parsed)?;
            crate::request::predict(&parsed, &limits)?;
            Ok(())
        });
        prop_assert!(peak <= bound(body.len()), "{peak} bytes for a body of {}", body.len());
        if let Err(e) = r {
            prop_assert!(e.code.status().is_client_error(), "{e}");
        }
    }
}

#[test]
fn the_unmutated_request_passes_and_the_allocator_counts() {
    let body = serde_json::to_vec(&base_request()).unwrap();
    let (r, peak) = peak_of(|| {
        let parsed: curvenet_schema::wire::BindingRequest = crate::extract::parse_json(&body).unwrap();
        crate::request::validate(&parsed).and_then(|()| crate::request::predict(&parsed, &Default::default()))
    });
    assert!(r.is_ok(), "{:?}", r.err());
    assert!(peak > 0 && peak <= bound(body.len()), "{peak}");
}
