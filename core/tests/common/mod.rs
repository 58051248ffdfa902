//! Shared helpers for the curvenet integration tests: a tiny OBJ loader,
//! hand-built curvenets and surfaces, and matrix checks.
#![allow(dead_code)]

use std::collections::HashMap;

use curvenet_core::closest_point::ClosestPointBvh;
use curvenet_core::{Mat3, PolyMesh};

/// The vendored source meshes (gzip-compressed OBJ, see fixtures/meshes/README.md).
pub const MESH_DIR: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../fixtures/meshes");

/// A polygon mesh read from a gzip-compressed OBJ file (`MESH_DIR/<name>.gz`
/// for a name like `hand_1k4.obj`): `v` and `f` lines only (1-based or
/// negative indices, `v/vt/vn` corners).
pub fn load_obj(path: &str) -> (PolyMesh, Vec<[f64; 3]>) {
    use std::io::Read;
    let gz = format!("{path}.gz");
    let file = std::fs::File::open(&gz).unwrap_or_else(|e| panic!("reading {gz}: {e}"));
    let mut text = String::new();
    flate2::read::GzDecoder::new(file).read_to_string(&mut text).unwrap_or_else(|e| panic!("decompressing {gz}: {e}"));
    let mut points = Vec::new();
    let mut counts = Vec::new();
    let mut indices = Vec::new();
    for line in text.lines() {
        let mut it = line.split_whitespace();
        match it.next() {
            Some("v") => {
                let c: Vec<f64> = it.take(3).map(|x| x.parse().unwrap()).collect();
                points.push([c[0], c[1], c[2]]);
            }
            Some("f") => {
                let mut n = 0;
                for corner in it {
                    let i: i64 = corner.split('/').next().unwrap().parse().unwrap();
                    let i = if i < 0 { points.len() as i64 + i } else { i - 1 };
                    indices.push(i as u32);
                    n += 1;
                }
                counts.push(n);
            }
            _ => {}
        }
    }
    (PolyMesh::new(&counts, &indices, points.len()).unwrap(), points)
}

/// Builds a curvenet: knots are deduplicated by exact position, handles are
/// always new points.
#[derive(Default, Clone)]
pub struct NetBuilder {
    pub points: Vec<[f64; 3]>,
    pub splines: Vec<[u32; 4]>,
    knots: HashMap<[u64; 3], u32>,
}

impl NetBuilder {
    pub fn knot(&mut self, p: [f64; 3]) -> u32 {
        let key = p.map(f64::to_bits);
        if let Some(&k) = self.knots.get(&key) {
            return k;
        }
        self.points.push(p);
        let k = self.points.len() as u32 - 1;
        self.knots.insert(key, k);
        k
    }

    pub fn handle(&mut self, p: [f64; 3]) -> u32 {
        self.points.push(p);
        self.points.len() as u32 - 1
    }

    /// A spline from knot `a` to knot `b` with handles `h1`, `h2`.
    pub fn spline(&mut self, a: [f64; 3], h1: [f64; 3], h2: [f64; 3], b: [f64; 3]) -> usize {
        let s = [self.knot(a), self.handle(h1), self.handle(h2), self.knot(b)];
        self.splines.push(s);
        self.splines.len() - 1
    }

    /// A spline from `a` to `b` whose handles sit at 1/3 and 2/3 of the chord,
    /// offset by `bulge` and `-bulge/2`.
    pub fn segment(&mut self, a: [f64; 3], b: [f64; 3], bulge: [f64; 3]) -> usize {
        let h1 = std::array::from_fn(|k| a[k] + (b[k] - a[k]) / 3.0 + bulge[k]);
        let h2 = std::array::from_fn(|k| a[k] + 2.0 * (b[k] - a[k]) / 3.0 - 0.5 * bulge[k]);
        self.spline(a, h1, h2, b)
    }
}

/// A planar quad mesh of `[-half, half]²` at z = 0 with `n × n` quads
/// (normal +z).
pub fn plane(half: f64, n: usize) -> (PolyMesh, Vec<[f64; 3]>) {
    let mut pts = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            pts.push([-half + 2.0 * half * i as f64 / n as f64, -half + 2.0 * half * j as f64 / n as f64, 0.0]);
        }
    }
    let mut idx = Vec::new();
    for j in 0..n {
        for i in 0..n {
            let v = (j * (n + 1) + i) as u32;
            idx.extend([v, v + 1, v + n as u32 + 2, v + n as u32 + 1]);
        }
    }
    (PolyMesh::new(&vec![4; n * n], &idx, pts.len()).unwrap(), pts)
}

/// A cylinder of radius `r` around the z axis, `z ∈ [z0, z1]`, quads with
/// outward normals, open at both ends.
pub fn cylinder(r: f64, z0: f64, z1: f64, around: usize, up: usize) -> (PolyMesh, Vec<[f64; 3]>) {
    let mut pts = Vec::new();
    for j in 0..=up {
        let z = z0 + (z1 - z0) * j as f64 / up as f64;
        for i in 0..around {
            let a = std::f64::consts::TAU * i as f64 / around as f64;
            pts.push([r * a.cos(), r * a.sin(), z]);
        }
    }
    let mut idx = Vec::new();
    for j in 0..up {
        for i in 0..around {
            let v = |ii: usize, jj: usize| (jj * around + ii % around) as u32;
            // Counter-clockwise seen from outside: around (+φ), then up (+z).
            idx.extend([v(i, j), v(i + 1, j), v(i + 1, j + 1), v(i, j + 1)]);
        }
    }
    (PolyMesh::new(&vec![4; around * up], &idx, pts.len()).unwrap(), pts)
}

/// A 3 × 3 grid in the plane z = 0: vertical lines x ∈ {-1, 0, 1} for
/// y ∈ [-2, 2] and horizontal lines y ∈ {-1, 0, 1} for x ∈ [-2, 2]. Between
/// two intersections a line is split into two splines at a valence-2 joint.
/// `bulge` bends the splines in the plane. Vertical lines run in +y,
/// horizontal ones in +x.
pub fn grid(bulge: f64) -> NetBuilder {
    let mut b = NetBuilder::default();
    let stops = [-2.0, -1.0, -0.5, 0.0, 0.5, 1.0, 2.0];
    for x in [-1.0, 0.0, 1.0] {
        for w in stops.windows(2) {
            b.segment([x, w[0], 0.0], [x, w[1], 0.0], [bulge, 0.0, 0.0]);
        }
    }
    for y in [-1.0, 0.0, 1.0] {
        for w in stops.windows(2) {
            b.segment([w[0], y, 0.0], [w[1], y, 0.0], [0.0, bulge, 0.0]);
        }
    }
    b
}

/// A star with a valence-5 intersection at the origin (plane z = 0). Arm `k`
/// points at angle `ANGLES[k]`; arms are authored in scrambled order and
/// some from the tip inwards.
pub const STAR_ANGLES: [f64; 5] = [200.0, 10.0, 290.0, 80.0, 145.0];
pub fn star() -> NetBuilder {
    let mut b = NetBuilder::default();
    for (k, deg) in STAR_ANGLES.iter().enumerate() {
        let a = deg.to_radians();
        let len = 1.0 + 0.3 * k as f64;
        let tip = [len * a.cos(), len * a.sin(), 0.0];
        let side = [-0.1 * a.sin(), 0.1 * a.cos(), 0.0];
        if k % 2 == 0 {
            b.segment([0.0; 3], tip, side);
        } else {
            b.segment(tip, [0.0; 3], side);
        }
    }
    b
}

/// Rings of radius 1 around the z axis at z = 0, 1, 2 crossed by four
/// vertical lines at φ = 0°, 90°, 180°, 270° for z ∈ [-0.5, 2.5], plus an
/// isolated ring at z = 3 and a two-anchor arc at z = 3.4.
pub fn cylinder_net() -> NetBuilder {
    let mut b = NetBuilder::default();
    let kappa = 4.0 / 3.0 * (std::f64::consts::PI / 8.0).tan();
    let at = |phi: f64, z: f64| [phi.cos(), phi.sin(), z];
    let arc = |b: &mut NetBuilder, p0: f64, p1: f64, z: f64| {
        let (a0, a1) = (at(p0, z), at(p1, z));
        let t0 = [-p0.sin(), p0.cos(), 0.0];
        let t1 = [-p1.sin(), p1.cos(), 0.0];
        let k = kappa * (p1 - p0) / std::f64::consts::FRAC_PI_2;
        let h1 = std::array::from_fn(|i| a0[i] + k * t0[i]);
        let h2 = std::array::from_fn(|i| a1[i] - k * t1[i]);
        b.spline(a0, h1, h2, a1)
    };
    let q = std::f64::consts::FRAC_PI_2;
    for z in [0.0, 1.0, 2.0, 3.0] {
        for k in 0..4 {
            arc(&mut b, k as f64 * q, (k + 1) as f64 * q, z);
        }
    }
    arc(&mut b, 0.3, 1.2, 3.4);
    for k in 0..4 {
        let phi = k as f64 * q;
        let zs = [-0.5, 0.0, 1.0, 2.0, 2.5];
        for w in zs.windows(2) {
            b.segment(at(phi, w[0]), at(phi, w[1]), [0.0; 3]);
        }
    }
    // Ring knots at 2π are the same as at 0 only up to round-off: weld them.
    weld(&mut b, 1e-12);
    b
}

/// Merges knots closer than `tol`.
pub fn weld(b: &mut NetBuilder, tol: f64) {
    let n = b.points.len();
    let mut target: Vec<u32> = (0..n as u32).collect();
    for i in 0..n {
        for j in 0..i {
            if target[j] == j as u32 && (0..3).all(|k| (b.points[i][k] - b.points[j][k]).abs() <= tol) {
                target[i] = j as u32;
                break;
            }
        }
    }
    for s in &mut b.splines {
        s[0] = target[s[0] as usize];
        s[3] = target[s[3] as usize];
    }
}

/// A 3 × 3 grid of curves lying on `mesh` around `center`: knots on a planar
/// grid of spacing `d` in the tangent plane, projected to the surface; handles
/// at 1/3 and 2/3 of each chord, projected too.
pub fn surface_grid(bvh: &ClosestPointBvh, center: [f64; 3], d: f64) -> NetBuilder {
    let hit = bvh.closest_point(center).unwrap();
    let n = bvh.face_normal(hit.face as usize);
    let e1 = normalize(cross(n, if n[0].abs() < 0.9 { [1.0, 0.0, 0.0] } else { [0.0, 1.0, 0.0] }));
    let e2 = cross(n, e1);
    let proj = |p: [f64; 3]| bvh.closest_point(p).unwrap().point;
    let at = |i: f64, j: f64| proj(std::array::from_fn(|k| hit.point[k] + d * (i * e1[k] + j * e2[k])));
    let mut b = NetBuilder::default();
    for j in [-1.0, 0.0, 1.0] {
        for i in [-2.0, -1.0, 0.0, 1.0] {
            let (a, c) = (at(i, j), at(i + 1.0, j));
            b.spline(a, at(i + 1.0 / 3.0, j), at(i + 2.0 / 3.0, j), c);
            let (a, c) = (at(j, i), at(j, i + 1.0));
            b.spline(a, at(j, i + 1.0 / 3.0), at(j, i + 2.0 / 3.0), c);
        }
    }
    b
}

pub fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

pub fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

pub fn normalize(a: [f64; 3]) -> [f64; 3] {
    let l = dot(a, a).sqrt();
    a.map(|x| x / l)
}

pub fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

pub fn norm(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}

/// Rotation by `angle` about the unit `axis` (row-major).
pub fn rotation(axis: [f64; 3], angle: f64) -> Mat3 {
    let [x, y, z] = normalize(axis);
    let (s, c) = angle.sin_cos();
    let t = 1.0 - c;
    [
        [t * x * x + c, t * x * y - s * z, t * x * z + s * y],
        [t * x * y + s * z, t * y * y + c, t * y * z - s * x],
        [t * x * z - s * y, t * y * z + s * x, t * z * z + c],
    ]
}

pub fn apply(m: &Mat3, p: [f64; 3]) -> [f64; 3] {
    [dot(m[0], p), dot(m[1], p), dot(m[2], p)]
}

pub fn scaled(m: &Mat3, s: f64) -> Mat3 {
    m.map(|r| r.map(|x| x * s))
}

pub fn mat_mul(a: &Mat3, b: &Mat3) -> Mat3 {
    std::array::from_fn(|r| std::array::from_fn(|c| (0..3).map(|k| a[r][k] * b[k][c]).sum()))
}

pub fn transpose(a: &Mat3) -> Mat3 {
    std::array::from_fn(|r| std::array::from_fn(|c| a[c][r]))
}

/// Largest entry of `a - b` in absolute value.
pub fn max_diff(a: &Mat3, b: &Mat3) -> f64 {
    (0..3).flat_map(|r| (0..3).map(move |c| (a[r][c] - b[r][c]).abs())).fold(0.0, f64::max)
}

pub const I3: Mat3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// A small deterministic random generator (SplitMix64) for seeded tests.
pub struct Rng(pub u64);

impl Rng {
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    /// Uniform in 0..n.
    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
    }
}

/// The seed of a randomized test: `CURVENET_TEST_SEED` when set (to replay
/// a failure), else `default`. Printed either way.
pub fn test_seed(default: u64) -> u64 {
    let seed = std::env::var("CURVENET_TEST_SEED").ok().and_then(|s| s.parse().ok()).unwrap_or(default);
    println!("seed {seed} (replay with CURVENET_TEST_SEED={seed})");
    seed
}
