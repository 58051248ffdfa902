//! The bench's inputs: a fixture's mesh and curvenets loaded, a deformer
//! built and timed, the finger-curl poses, one frame solved through the
//! deformer, and fixed random right-hand sides for the triangular solves.

use std::hint::black_box;
use std::path::Path;
use std::time::Instant;

use curvenet_core::{Binding, CurvenetInput, Deformer, Frame};
use curvenet_schema::usd::Stage;
use curvenet_schema::{CurvenetData, MeshData};

use super::measure::{Lap, Stopwatch, ms_since, uniform};
use crate::cli::{CliError, CliResult};

/// Largest curl angle of the generated poses, degrees.
pub(super) const MAX_ANGLE_DEG: f64 = 60.0;
/// The articulation plane, as a fraction of the pool's extent along y.
pub(super) const PLANE: f64 = 0.55;
/// Width of the smoothstep blend across the plane, as a fraction of the extent.
pub(super) const BAND: f64 = 0.10;
/// The first curvenet-deformed mesh of `file` and its curvenets, with the load time.
pub(super) fn load(file: &Path) -> CliResult<(MeshData, Vec<CurvenetData>, f64)> {
    let t = Instant::now();
    let stage = Stage::open(file)?;
    let mesh = stage
        .deformed_meshes()?
        .into_iter()
        .next()
        .ok_or_else(|| CliError::Input(format!("{}: no mesh deformed by curvenets", file.display())))?;
    let nets: Vec<CurvenetData> = mesh.curvenets.iter().map(|p| stage.curvenet(p)).collect::<Result<_, _>>()?;
    Ok((mesh, nets, ms_since(t)))
}

/// One `Deformer::new` of `mesh` and `nets`, timed (wall and thread CPU).
pub(super) fn build(mesh: &MeshData, nets: &[CurvenetData], context: &str) -> CliResult<(Deformer, Lap)> {
    let curvenets: Vec<CurvenetInput> = nets.iter().map(CurvenetData::input).collect();
    let input = curvenet_schema::deformer_input(mesh, &curvenets);
    let clock = Stopwatch::start();
    let deformer = Deformer::new(&input).map_err(core_err(context))?;
    Ok((deformer, clock.stop()))
}

pub(super) fn core_err(context: &str) -> impl FnOnce(curvenet_core::Error) -> CliError + '_ {
    move |source| CliError::Core { context: context.to_string(), source }
}

/// The pools of frame `i` of `n`: control points beyond the plane curl
/// about the x axis towards +z (see the module docs). Frame 0 is neutral.
pub(super) fn pose(nets: &[CurvenetData], i: usize, n: usize) -> Vec<Vec<[f64; 3]>> {
    let (lo, hi) = nets
        .iter()
        .flat_map(|c| c.pool.iter())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| (lo.min(p[1]), hi.max(p[1])));
    let count = nets.iter().map(|c| c.pool.len()).sum::<usize>().max(1) as f64;
    let zc = nets.iter().flat_map(|c| c.pool.iter()).map(|p| p[2]).sum::<f64>() / count;
    let extent = (hi - lo).max(f64::MIN_POSITIVE);
    let y0 = lo + PLANE * extent;
    let band = BAND * extent;
    let angle = MAX_ANGLE_DEG.to_radians() * 0.5 * (1.0 - (std::f64::consts::TAU * i as f64 / n as f64).cos());
    nets.iter()
        .map(|c| {
            c.pool
                .iter()
                .map(|p| {
                    let s = ((p[1] - (y0 - 0.5 * band)) / band).clamp(0.0, 1.0);
                    let a = angle * s * s * (3.0 - 2.0 * s);
                    if a == 0.0 {
                        return *p;
                    }
                    let (sin, cos) = a.sin_cos();
                    let (y, z) = (p[1] - y0, p[2] - zc);
                    [p[0], y0 + y * cos - z * sin, zc + y * sin + z * cos]
                })
                .collect()
        })
        .collect()
}

/// Solves one frame through `Deformer::frame` into `out`.
pub(super) fn solve(
    deformer: &Deformer,
    posed: &[Option<&[[f64; 3]]>],
    out: &mut [[f64; 3]],
) -> curvenet_core::Result<()> {
    deformer.frame(&Frame { posed, ..Frame::default() }, out, None)
}

/// `Binding::solve_in_place::<K>` on fixed random right-hand sides.
pub(super) struct TriSolve<const K: usize> {
    pub(super) src: Vec<[f64; K]>,
    pub(super) rhs: Vec<[f64; K]>,
    pub(super) work: Vec<[f64; K]>,
}

impl<const K: usize> TriSolve<K> {
    pub(super) fn new(n: usize, seed: u64) -> Self {
        let mut rng = 0x9E37_79B9_7F4A_7C15u64 ^ seed;
        let src: Vec<[f64; K]> = (0..n).map(|_| std::array::from_fn(|_| uniform(&mut rng))).collect();
        Self { rhs: src.clone(), work: vec![[0.0; K]; n], src }
    }

    /// One solve (the right-hand side is restored outside the clock).
    pub(super) fn time(&mut self, binding: &Binding) -> Lap {
        self.rhs.copy_from_slice(&self.src);
        let clock = Stopwatch::start();
        binding.solve_in_place(black_box(&mut self.rhs), &mut self.work);
        black_box(&self.rhs);
        clock.stop()
    }
}
