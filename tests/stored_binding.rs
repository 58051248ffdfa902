//! A deformer written in the stored format (`Deformer::to_bytes`) and read
//! back (`Deformer::from_bytes`) deforms bit for bit as the one that was
//! built, single frames and groups, on hands of several sizes and the
//! creature corpus's grid; damaged bytes are refused with their reason.

use curvenet_core::{Deformer, Frame, FrameOut};
use curvenet_core::{STORED_HEADER_BYTES as HEADER_BYTES, StoredFormatError as FormatError};
use curvenet_e2e::bind_fixture;

/// Frames of the fixture's animation (its posed pools at times 0..n) solved
/// one by one and as one group, on `d`.
/// Each frame's points.
type Points = Vec<Vec<[f64; 3]>>;

fn frames(b: &curvenet_e2e::Bound, d: &Deformer, times: &[f64]) -> (Points, Points) {
    let pools: Vec<Vec<Option<Vec<[f64; 3]>>>> =
        times.iter().map(|&t| b.nets.iter().map(|n| b.stage.posed_pool(n, Some(t)).unwrap()).collect()).collect();
    let refs: Vec<Vec<Option<&[[f64; 3]]>>> = pools.iter().map(|f| f.iter().map(|p| p.as_deref()).collect()).collect();
    let frames: Vec<Frame<'_>> = refs.iter().map(|r| Frame { posed: r, ..Default::default() }).collect();
    let n = d.n_vertices();
    let single = frames
        .iter()
        .map(|f| {
            let mut out = vec![[0.0; 3]; n];
            d.frame(f, &mut out, None).unwrap();
            out
        })
        .collect();
    let mut grouped = vec![vec![[0.0; 3]; n]; frames.len()];
    let mut outs: Vec<FrameOut<'_>> = grouped.iter_mut().map(|o| FrameOut { points: o, gradients: None }).collect();
    d.frames(&frames, &mut outs).unwrap();
    (single, grouped)
}

fn bits(points: &[Vec<[f64; 3]>]) -> Vec<u64> {
    points.iter().flatten().flatten().map(|x| x.to_bits()).collect()
}

#[test]
fn a_stored_deformer_deforms_bit_for_bit_as_the_built_one() {
    for rel in ["hand/hand_1k4.usda", "hand/hand_22k.usdc", "grid/grid.usda"] {
        let b = bind_fixture(rel);
        let t = std::time::Instant::now();
        let bytes = b.deformer.to_bytes();
        let write_ms = t.elapsed().as_secs_f64() * 1e3;
        let t = std::time::Instant::now();
        let loaded = Deformer::from_bytes(&bytes).unwrap_or_else(|e| panic!("{rel}: {e}"));
        let read_ms = t.elapsed().as_secs_f64() * 1e3;
        eprintln!(
            "{rel}: {} bytes, written in {write_ms:.1} ms, read in {read_ms:.1} ms (built in {:.1} ms)",
            bytes.len(),
            b.deformer.timings().total_ms
        );
        assert_eq!(loaded.n_vertices(), b.deformer.n_vertices(), "{rel}");
        assert_eq!(loaded.binding().stats().factor_nonzeros, b.binding().stats().factor_nonzeros, "{rel}");
        assert_eq!(loaded.binding().warnings().len(), b.binding().warnings().len(), "{rel}");
        // Written again, the loaded deformer gives the same bytes: nothing was lost.
        assert!(loaded.to_bytes() == bytes, "{rel}: the loaded deformer does not write the bytes it was read from");
        let times: Vec<f64> = (0..6).map(f64::from).collect();
        let (built_single, built_grouped) = frames(&b, &b.deformer, &times);
        let (loaded_single, loaded_grouped) = frames(&b, &loaded, &times);
        assert_eq!(bits(&built_single), bits(&loaded_single), "{rel}: single frames differ");
        assert_eq!(bits(&built_grouped), bits(&loaded_grouped), "{rel}: grouped frames differ");
        assert_eq!(bits(&built_single), bits(&built_grouped), "{rel}: groups differ from single frames");
    }
}

#[test]
fn damaged_stored_bytes_are_refused_never_used() {
    let b = bind_fixture("hand/hand_1k4.usda");
    let bytes = b.deformer.to_bytes();
    // Truncated anywhere: refused as truncated (or, before the magic is whole, as not a binding).
    let mut seed = 0x9e37_79b9_7f4a_7c15u64;
    let mut next = || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        seed
    };
    for _ in 0..64 {
        let cut = (next() as usize) % bytes.len();
        match Deformer::from_bytes(&bytes[..cut]) {
            Err(FormatError::Truncated { .. }) => {}
            Err(FormatError::Magic { .. }) if cut < 8 => {}
            other => panic!("truncated at {cut} of {}: {:?}", bytes.len(), other.err()),
        }
    }
    // A flipped byte in the payload fails the checksum; in the header, the field it hits.
    for _ in 0..256 {
        let at = (next() as usize) % bytes.len();
        let mut flipped = bytes.clone();
        flipped[at] ^= 1 << (next() % 8);
        let e = Deformer::from_bytes(&flipped).err().unwrap_or_else(|| panic!("flipped byte {at} was accepted"));
        if at >= HEADER_BYTES {
            assert!(matches!(e, FormatError::Checksum { .. }), "byte {at}: {e:?}");
        }
    }
    // Another format version.
    let mut version = bytes.clone();
    version[8..12].copy_from_slice(&999u32.to_le_bytes());
    assert!(matches!(Deformer::from_bytes(&version), Err(FormatError::Version { found: 999, .. })));
    assert!(matches!(Deformer::from_bytes(b"not a binding at all, really not"), Err(FormatError::Magic { .. })));
}
