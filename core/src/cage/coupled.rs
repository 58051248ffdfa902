//! The coupled cage-and-skeleton rig (Corda et al. 2020 §4, Fig. 4) that
//! evaluates one frame: rest-cage edits `C`, joint transforms, posed-cage
//! offsets `∂C′` → the mesh's posed points.
//!
//! # Decisions (where the paper leaves a choice)
//!
//! - **The mesh off the cage.** Mean value coordinates have linear
//!   precision, so `Φ C₀` reproduces the mesh's bind points up to rounding
//!   whatever mesh the cage encloses (it need not be made from the cage).
//!   The rig keeps the frame's pre-cage points (`base`: the bind points, or
//!   a frame's rest pose / sculpt) and applies the cage as a displacement:
//!   `M = base + Φ (C − C₀)`, i.e. `M = Φ C + D` with the residual
//!   `D = base − Φ C₀` carried unrotated (it is rounding-level for the bind
//!   points, [`CoupledRig::max_bind_residual`]; a sculpt of the frame's
//!   rest pose rides on it). CageUp fits `Φ̃ C′ = M̃′ − G·D̃` (`G`'s linear
//!   part), so that with identity transforms `C′ = C` exactly.
//! - **SkelUp** moves the joints by the cage's displacement, `A = A₀ +
//!   Ψ (C − C₀)` (Eq. 13, exact at bind whatever the accuracy of Eq. 11's
//!   solve), and re-chains the skinning translations keeping the linear
//!   parts (Eq. 16): a root's posed pivot moves by its rest displacement,
//!   `∂t_r = (I − L_r) ∂a_r`; a child stays attached to its parent,
//!   `∂t_j = ∂t_f + (L_f − L_j) ∂a_j`. With no cage edit the transforms are
//!   the frame's exactly.
//! - **Ψ (Eq. 9–12).** Localisation `L_ji = −1 + ω_ij^s + (Σ_{k≠j} ω_ik)^s`
//!   with `s = 0.1` ([`LOCALIZATION_EXPONENT`]), times the absolute mean
//!   value coordinates of the joint with respect to the mesh's triangles
//!   (the mesh need not be closed for them to localise), gives masses
//!   `m = Σ_i L_ji |mvc_ji| Φ_i`; entries below 10⁻¹² of the largest are
//!   raised to it (the maximum-entropy projection needs positive priors).
//!   A joint with no localised weight takes the cage's own coordinates of
//!   its position as masses. Eq. 11 is solved by Newton's method on the
//!   dual (`b_k ∝ m_k exp(λ·(c_k − a))`) to 10⁻¹² of the cage diagonal.
//! - **CoRs** follow the cage by `p = p₀ + Λ (C − C₀)` (Eq. 14) for the
//!   points with a centre of their own; the others are their own centre.
//! - **CageRev** (Eq. 19) is linearised through LBS for every method. With
//!   DQS or CoR the default is the paper's small-increment approximation
//!   ([`CageRevApproximation::SmallIncrement`]): CageUp fits the mesh as
//!   skinned, so the loop `C′ → C → S → S′ → C′` is exact under LBS only.
//!   [`CageRevApproximation::LbsGhost`] fits CageUp to an LBS "ghost" of the
//!   MaxVol rows instead (the loop is then exact for every method, the fit
//!   slightly off the displayed mesh). The 3c × 3c system is assembled and
//!   factored (LU, partial pivoting) per frame that has offsets, since it
//!   depends on the pose.
//! - **Spaces.** The cage and the rest edits are in the mesh's space; the
//!   joints, CoRs, `C′` and `∂C′` in skeleton space (the skinned points'
//!   space), see the module docs of [`super`]. Without a skeleton the
//!   output is `M` (the mesh's space) and `C′ = C`.

use std::time::{Duration, Instant};

use glam::{DMat3, DVec3};

use super::CageError;
use super::cor::CentersOfRotation;
use super::maxvol::MaxVol;
use super::mvc::{Cage, Mvc};
use crate::error::{Error, Result};
use crate::skinning::{Influences, Mat4, Skeleton, Skin, SkinningMethod, inverse, transform_point, transform_vector};

/// `s` of the joint localisation function (Corda et al. Eq. 9).
pub const LOCALIZATION_EXPONENT: f64 = 0.1;

/// How CageRev treats skinning methods other than LBS (Corda et al. §4.3, last paragraph).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub enum CageRevApproximation {
    /// CageUp fits the mesh as skinned; CageRev's LBS linearisation is an
    /// approximation for DQS and CoR (exact for LBS).
    #[default]
    SmallIncrement,
    /// CageUp fits an LBS skinning of the MaxVol rows: the loop is exact
    /// for every method.
    LbsGhost,
}

/// One frame of a [`CoupledRig`].
#[derive(Debug, Clone, Copy, Default)]
pub struct CageFrame<'a> {
    /// The mesh's points before the cage (bind points, or the frame's rest
    /// pose / sculpt); `None`: the bind points.
    pub base: Option<&'a [[f64; 3]]>,
    /// The rest cage `C` this frame (mesh space); `None`: `C₀`.
    pub rest_cage: Option<&'a [[f64; 3]]>,
    /// Skinning transforms, one per joint; `None`: identities (for a rig
    /// with a skeleton), refused for a rig without.
    pub joint_transforms: Option<&'a [Mat4]>,
    /// Posed-cage offsets `∂C′` (skeleton space), through CageRev.
    pub posed_cage_offsets: Option<&'a [[f64; 3]]>,
}

/// Times of the last frame's stages (per-frame costs).
#[derive(Debug, Clone, Copy, Default)]
pub struct CageTimings {
    pub cage_rev: Duration,
    pub skel_up: Duration,
    /// `M = base + Φ(C − C₀)` and the CoRs.
    pub cage_to_mesh: Duration,
    pub skinning: Duration,
    pub cage_up: Duration,
}

/// The skeleton side of the coupling.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
struct Skel {
    parents: Vec<Option<u32>>,
    /// `A₀`: the joints at bind, skeleton space.
    #[serde(with = "crate::persist::pod")]
    joints: Vec<DVec3>,
    /// `Ψ`, `#J × #C` row-major.
    #[serde(with = "crate::persist::pod")]
    psi: Vec<f64>,
    skin: Skin,
    /// CoR: bind centres (mesh space), the blended vertices and `Λ` rows.
    cor: Option<Cor>,
}

#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
struct Cor {
    #[serde(with = "crate::persist::pod")]
    centers: Vec<[f64; 3]>,
    #[serde(with = "crate::persist::pod")]
    blended: Vec<u32>,
    #[serde(with = "crate::persist::pod")]
    lambda: Vec<f64>,
}

/// A mesh coupled with a cage (and, optionally, a skeleton and skin).
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct CoupledRig {
    mvc: Mvc,
    maxvol: MaxVol,
    #[serde(with = "crate::persist::pod")]
    bind_points: Vec<[f64; 3]>,
    /// `max |base − Φ C₀|` at bind.
    bind_residual: f64,
    geom_bind: Mat4,
    geom_linear: DMat3,
    geom_linear_inv: DMat3,
    skel: Option<Skel>,
    approximation: CageRevApproximation,
}

/// Reused buffers of [`CoupledRig::evaluate`]: after the first frame, a
/// frame allocates nothing.
#[derive(Debug, Clone, Default)]
pub struct CoupledWorkspace {
    cage: Vec<[f64; 3]>,
    delta: Vec<[f64; 3]>,
    posed_cage: Vec<[f64; 3]>,
    rows_in: Vec<[f64; 3]>,
    transforms: Vec<Mat4>,
    joints: Vec<DVec3>,
    rest: Vec<[f64; 3]>,
    centers: Vec<[f64; 3]>,
    /// CageRev: the 3c × 3c matrix, its right side, pivots, and the
    /// per-joint `∂t/∂C` (3 × 3c each).
    k: Vec<f64>,
    rhs: Vec<f64>,
    piv: Vec<usize>,
    dt: Vec<f64>,
    timings: CageTimings,
}

impl CoupledWorkspace {
    /// The rest cage `C` of the last frame (after CageRev), mesh space.
    pub fn rest_cage(&self) -> &[[f64; 3]] {
        &self.cage
    }
    /// The posed cage `C′` of the last frame (CageUp), skeleton space.
    pub fn posed_cage(&self) -> &[[f64; 3]] {
        &self.posed_cage
    }
    /// The joints `A` of the last frame (SkelUp), skeleton space.
    pub fn joints(&self) -> &[DVec3] {
        &self.joints
    }
    /// The skinning transforms after SkelUp.
    pub fn transforms(&self) -> &[Mat4] {
        &self.transforms
    }
    /// The mesh's rest pose `M` of the last frame (mesh space).
    pub fn rest_mesh(&self) -> &[[f64; 3]] {
        &self.rest
    }
    pub fn timings(&self) -> CageTimings {
        self.timings
    }
}

fn linear(m: &Mat4) -> DMat3 {
    // Column-vector L with L x = transform_vector(m, x): columns are the images of the axes.
    DMat3::from_cols(
        DVec3::from_array(transform_vector(m, [1.0, 0.0, 0.0])),
        DVec3::from_array(transform_vector(m, [0.0, 1.0, 0.0])),
        DVec3::from_array(transform_vector(m, [0.0, 0.0, 1.0])),
    )
}

impl CoupledRig {
    /// Builds the rig: `Φ` of the mesh's bind points (`mesh_points`, with
    /// `mesh_triangles`, a triangulation of its faces) with respect to the
    /// cage (validated, [`Cage::new`]), the MaxVol rows and `Φ̃⁻¹`, and with
    /// a skeleton and skin: `Ψ` (Eq. 9–12) and, for centres-of-rotation
    /// skinning, the centres (the skin's own, else Eq. 5) and `Λ`.
    pub fn new(
        cage_points: &[[f64; 3]],
        cage_triangles: &[[u32; 3]],
        mesh_points: &[[f64; 3]],
        mesh_triangles: &[[u32; 3]],
        skinning: Option<(&Skeleton, &Skin)>,
        approximation: CageRevApproximation,
    ) -> Result<Self> {
        let cage = Cage::new(cage_points, cage_triangles)?;
        let mvc = Mvc::with_cage(cage, mesh_points)?;
        let maxvol = MaxVol::new(&mvc)?;
        let n = mesh_points.len();
        let mut m = vec![[0.0; 3]; n];
        mvc.apply(cage_points, &mut m)?;
        let bind_residual = m
            .iter()
            .zip(mesh_points)
            .map(|(a, b)| DVec3::from_array(*a).distance(DVec3::from_array(*b)))
            .fold(0.0, f64::max);
        let (geom_bind, skel) = match skinning {
            None => (crate::skinning::IDENTITY, None),
            Some((skeleton, skin)) => {
                let skel = build_skel(&mvc, mesh_points, mesh_triangles, skeleton, skin)?;
                (*skin.geom_bind_transform(), Some(skel))
            }
        };
        let geom_linear = linear(&geom_bind);
        let geom_linear_inv = geom_linear.inverse();
        Ok(Self {
            mvc,
            maxvol,
            bind_points: mesh_points.to_vec(),
            bind_residual,
            geom_bind,
            geom_linear,
            geom_linear_inv,
            skel,
            approximation,
        })
    }

    /// The mean value coordinates `Φ` (and the cage).
    pub fn mvc(&self) -> &Mvc {
        &self.mvc
    }
    pub fn maxvol(&self) -> &MaxVol {
        &self.maxvol
    }
    pub fn n_cage_vertices(&self) -> usize {
        self.mvc.n_cage_vertices()
    }
    pub fn n_cage_triangles(&self) -> usize {
        self.mvc.cage().triangles().len()
    }
    /// The MaxVol rows (mesh vertices).
    pub fn maxvol_rows(&self) -> &[usize] {
        self.maxvol.rows()
    }
    /// The condition number of the MaxVol square system `Φ̃`.
    pub fn condition(&self) -> f64 {
        self.maxvol.condition()
    }
    /// Heap bytes of `Φ`.
    pub fn phi_bytes(&self) -> usize {
        self.mvc.heap_bytes()
    }
    /// `max_i |M₀_i − (Φ C₀)_i|`: how far the bind points are from the
    /// cage's reproduction of them (rounding, by linear precision).
    pub fn max_bind_residual(&self) -> f64 {
        self.bind_residual
    }
    /// The joints at bind `A₀` (skeleton space), with a skeleton.
    pub fn bind_joints(&self) -> Option<&[DVec3]> {
        self.skel.as_ref().map(|s| &s.joints[..])
    }
    /// `Ψ` (`#J × #C`, row-major), with a skeleton.
    pub fn psi(&self) -> Option<&[f64]> {
        self.skel.as_ref().map(|s| &s.psi[..])
    }
    /// The skin, with a skeleton.
    pub fn skin(&self) -> Option<&Skin> {
        self.skel.as_ref().map(|s| &s.skin)
    }
    /// The bind-time centres of rotation (mesh space), for CoR skinning.
    pub fn centers_of_rotation(&self) -> Option<&[[f64; 3]]> {
        self.skel.as_ref().and_then(|s| s.cor.as_ref()).map(|c| &c.centers[..])
    }
    pub fn n_points(&self) -> usize {
        self.bind_points.len()
    }
    pub fn n_joints(&self) -> usize {
        self.skel.as_ref().map_or(0, |s| s.parents.len())
    }

    /// Evaluates one frame into `out` (one point per mesh vertex): CageRev
    /// (with offsets), SkelUp, `M`, skinning, CageUp (see the module docs).
    /// Errors name the frame field and index (counts, non-finite values),
    /// or the singular CageRev pivot.
    pub fn evaluate(&self, frame: &CageFrame<'_>, ws: &mut CoupledWorkspace, out: &mut [[f64; 3]]) -> Result<()> {
        let n = self.n_points();
        let c = self.n_cage_vertices();
        let cage0 = self.mvc.cage().points();
        check_points(frame.base, n, "frame base points")?;
        check_points(frame.rest_cage, c, "Frame::rest_cage")?;
        check_points(frame.posed_cage_offsets, c, "Frame::posed_cage_offsets")?;
        if out.len() != n {
            return Err(Error::CountMismatch { what: "cage rig output", expected: n, got: out.len() });
        }
        let s = self.n_joints();
        match (&self.skel, frame.joint_transforms) {
            (None, Some(_)) => {
                return Err(CageError::Missing { what: "joint transforms for a cage rig without a skeleton" }.into());
            }
            (Some(_), Some(t)) if t.len() != s => {
                return Err(Error::CountMismatch { what: "joint transforms", expected: s, got: t.len() });
            }
            _ => {}
        }
        if let Some(t) = frame.joint_transforms
            && let Some(j) = t.iter().position(|m| !m.iter().all(|x| x.is_finite()))
        {
            return Err(crate::skinning::SkinningError::NonFiniteTransform { what: "joint transform", index: j }.into());
        }
        ws.cage.clear();
        ws.cage.extend_from_slice(frame.rest_cage.unwrap_or(cage0));
        ws.transforms.clear();
        match frame.joint_transforms {
            Some(t) => ws.transforms.extend_from_slice(t),
            None => ws.transforms.resize(s, crate::skinning::IDENTITY),
        }
        ws.timings = CageTimings::default();
        // CageRev.
        if let Some(offsets) = frame.posed_cage_offsets {
            let t0 = Instant::now();
            match &self.skel {
                None => {
                    // No skeleton: C′ = C, so ∂C = ∂C′ (in the mesh's space).
                    for (q, d) in ws.cage.iter_mut().zip(offsets) {
                        for k in 0..3 {
                            q[k] += d[k];
                        }
                    }
                }
                Some(skel) => self.cage_rev(skel, offsets, ws)?,
            }
            ws.timings.cage_rev = t0.elapsed();
        }
        ws.delta.clear();
        ws.delta.extend(ws.cage.iter().zip(cage0).map(|(a, b)| [a[0] - b[0], a[1] - b[1], a[2] - b[2]]));
        // SkelUp.
        let t0 = Instant::now();
        if let Some(skel) = &self.skel {
            self.skel_up(skel, ws);
        }
        ws.timings.skel_up = t0.elapsed();
        // C → M.
        let t0 = Instant::now();
        let base = frame.base.unwrap_or(&self.bind_points);
        ws.rest.resize(n, [0.0; 3]);
        self.mvc.apply_add(&ws.delta, Some(base), &mut ws.rest);
        ws.timings.cage_to_mesh = t0.elapsed();
        let Some(skel) = &self.skel else {
            out.copy_from_slice(&ws.rest);
            ws.posed_cage.clear();
            ws.posed_cage.extend_from_slice(&ws.cage);
            return Ok(());
        };
        // Skinning (CoRs moved by Λ).
        let t0 = Instant::now();
        match &skel.cor {
            Some(cor) => {
                ws.centers.clear();
                ws.centers.extend_from_slice(&ws.rest);
                for (r, &i) in cor.blended.iter().enumerate() {
                    let row = &cor.lambda[r * c..(r + 1) * c];
                    let mut p = cor.centers[i as usize];
                    for (w, d) in row.iter().zip(&ws.delta) {
                        for k in 0..3 {
                            p[k] += w * d[k];
                        }
                    }
                    ws.centers[i as usize] = p;
                }
                crate::cage::skin_points_cor(
                    &ws.rest,
                    &ws.centers,
                    skel.skin.influences(),
                    &self.geom_bind,
                    &ws.transforms,
                    out,
                )?;
            }
            None => skel.skin.skin_points(&ws.rest, &ws.transforms, out)?,
        }
        ws.timings.skinning = t0.elapsed();
        // CageUp: Φ̃ C′ = M̃′ − G·D̃, D̃ = M̃ − Φ̃ C.
        let t0 = Instant::now();
        let ghost =
            self.approximation == CageRevApproximation::LbsGhost && skel.skin.method() != SkinningMethod::ClassicLinear;
        ws.rows_in.resize(c, [0.0; 3]);
        for (r, &i) in self.maxvol.rows().iter().enumerate() {
            let phi = self.mvc.row(i);
            let mut pc = [0.0; 3];
            for (w, q) in phi.iter().zip(&ws.cage) {
                for k in 0..3 {
                    pc[k] += w * q[k];
                }
            }
            let m = ws.rest[i];
            let d = self.geom_linear * DVec3::new(m[0] - pc[0], m[1] - pc[1], m[2] - pc[2]);
            let posed =
                if ghost { lbs_point(skel.skin.influences(), i, &self.geom_bind, &ws.transforms, m) } else { out[i] };
            ws.rows_in[r] = [posed[0] - d.x, posed[1] - d.y, posed[2] - d.z];
        }
        ws.posed_cage.resize(c, [0.0; 3]);
        self.maxvol.solve(&ws.rows_in, &mut ws.posed_cage);
        ws.timings.cage_up = t0.elapsed();
        Ok(())
    }

    /// SkelUp: `A = A₀ + G·Ψ(C − C₀)`, translations re-chained (Eq. 16).
    fn skel_up(&self, skel: &Skel, ws: &mut CoupledWorkspace) {
        let c = self.n_cage_vertices();
        ws.joints.clear();
        for (j, a0) in skel.joints.iter().enumerate() {
            let row = &skel.psi[j * c..(j + 1) * c];
            let mut d = DVec3::ZERO;
            for (w, q) in row.iter().zip(&ws.delta) {
                d += DVec3::from_array(*q) * *w;
            }
            ws.joints.push(*a0 + self.geom_linear * d);
        }
        self.rechain(skel, ws);
    }

    /// `∂t_root = (I − L)∂a`, `∂t_j = ∂t_f + (L_f − L_j)∂a_j`, added to the translations.
    fn rechain(&self, skel: &Skel, ws: &mut CoupledWorkspace) {
        // ws.dt holds ∂t_j (3 per joint) as scratch.
        let s = skel.parents.len();
        ws.dt.clear();
        ws.dt.resize(3 * s, 0.0);
        for j in 0..s {
            let da = ws.joints[j] - skel.joints[j];
            let lj = linear(&ws.transforms[j]);
            let dt = match skel.parents[j] {
                None => (DMat3::IDENTITY - lj) * da,
                Some(f) => {
                    let f = f as usize;
                    let lf = linear(&ws.transforms[f]);
                    DVec3::new(ws.dt[3 * f], ws.dt[3 * f + 1], ws.dt[3 * f + 2]) + (lf - lj) * da
                }
            };
            ws.dt[3 * j..3 * j + 3].copy_from_slice(&dt.to_array());
        }
        for j in 0..s {
            for k in 0..3 {
                ws.transforms[j][12 + k] += ws.dt[3 * j + k];
            }
        }
    }

    /// CageRev (Eq. 19): solves `(R̃Φ̃ + Ω̃ ∂T/∂C) ∂C_s = Φ̃ ∂C′` at the
    /// frame's pose and adds `∂C = G⁻¹ ∂C_s` to the rest cage in `ws`.
    fn cage_rev(&self, skel: &Skel, offsets: &[[f64; 3]], ws: &mut CoupledWorkspace) -> Result<()> {
        let c = self.n_cage_vertices();
        let s = skel.parents.len();
        let dim = 3 * c;
        // ∂t_j/∂C_s: 3 × 3c per joint, chained: D_j = D_f + E_j ⊗ ψ_j,
        // E_root = I − L_root, E_j = L_f − L_j.
        ws.dt.clear();
        ws.dt.resize(s * 3 * dim, 0.0);
        for j in 0..s {
            let lj = linear(&ws.transforms[j]);
            let e = match skel.parents[j] {
                None => DMat3::IDENTITY - lj,
                Some(f) => {
                    let f = f as usize;
                    let (head, tail) = ws.dt.split_at_mut(j * 3 * dim);
                    tail[..3 * dim].copy_from_slice(&head[f * 3 * dim..(f + 1) * 3 * dim]);
                    linear(&ws.transforms[f]) - lj
                }
            };
            let block = &mut ws.dt[j * 3 * dim..(j + 1) * 3 * dim];
            let psi = &skel.psi[j * c..(j + 1) * c];
            for (k, w) in psi.iter().enumerate() {
                if *w == 0.0 {
                    continue;
                }
                for r in 0..3 {
                    for q in 0..3 {
                        block[r * dim + 3 * k + q] += e.col(q)[r] * w;
                    }
                }
            }
        }
        // K = R̃Φ̃ + Ω̃ D, and rhs = Φ̃ ∂C′.
        ws.k.clear();
        ws.k.resize(dim * dim, 0.0);
        ws.rhs.clear();
        ws.rhs.resize(dim, 0.0);
        let influences = skel.skin.influences();
        for (r, &i) in self.maxvol.rows().iter().enumerate() {
            let phi = self.mvc.row(i);
            let mut rm = DMat3::ZERO;
            for (j, w) in influences.point(i) {
                if w != 0.0 {
                    rm += linear(&ws.transforms[j as usize]) * w;
                }
            }
            for (k, p) in phi.iter().enumerate() {
                for a in 0..3 {
                    for b in 0..3 {
                        ws.k[(3 * r + a) * dim + 3 * k + b] += rm.col(b)[a] * p;
                    }
                }
                for a in 0..3 {
                    ws.rhs[3 * r + a] += p * offsets[k][a];
                }
            }
            for (j, w) in influences.point(i) {
                if w == 0.0 {
                    continue;
                }
                let block = &ws.dt[j as usize * 3 * dim..(j as usize + 1) * 3 * dim];
                for a in 0..3 {
                    let krow = &mut ws.k[(3 * r + a) * dim..(3 * r + a + 1) * dim];
                    for (x, y) in krow.iter_mut().zip(&block[a * dim..(a + 1) * dim]) {
                        *x += w * y;
                    }
                }
            }
        }
        lu_solve(&mut ws.k, &mut ws.rhs, &mut ws.piv, dim)?;
        for (k, q) in ws.cage.iter_mut().enumerate() {
            let d = self.geom_linear_inv * DVec3::new(ws.rhs[3 * k], ws.rhs[3 * k + 1], ws.rhs[3 * k + 2]);
            q[0] += d.x;
            q[1] += d.y;
            q[2] += d.z;
        }
        Ok(())
    }
}

/// LBS of one mesh-space point (the ghost mesh's MaxVol rows).
fn lbs_point(influences: &Influences, i: usize, geom_bind: &Mat4, transforms: &[Mat4], p: [f64; 3]) -> [f64; 3] {
    let q = transform_point(geom_bind, p);
    let mut acc = [0.0; 3];
    for (j, w) in influences.point(i) {
        if w == 0.0 {
            continue;
        }
        let x = transform_point(&transforms[j as usize], q);
        for k in 0..3 {
            acc[k] += w * x[k];
        }
    }
    acc
}

/// Dense LU with partial pivoting, in place: solves `k x = rhs` into `rhs`.
fn lu_solve(k: &mut [f64], rhs: &mut [f64], piv: &mut Vec<usize>, n: usize) -> Result<()> {
    piv.clear();
    piv.extend(0..n);
    let scale = k.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    for col in 0..n {
        let (p, v) =
            (col..n).map(|r| (r, k[r * n + col].abs())).fold((col, -1.0), |m, x| if x.1 > m.1 { x } else { m });
        if !(v > 1e-14 * scale) {
            return Err(CageError::SingularCageRev { pivot: col }.into());
        }
        if p != col {
            for q in 0..n {
                k.swap(col * n + q, p * n + q);
            }
            rhs.swap(col, p);
            piv.swap(col, p);
        }
        let d = k[col * n + col];
        let (top, bottom) = k.split_at_mut((col + 1) * n);
        let pivot_row = &top[col * n..];
        for r in 0..n - col - 1 {
            let row = &mut bottom[r * n..(r + 1) * n];
            let f = row[col] / d;
            if f == 0.0 {
                continue;
            }
            for q in col..n {
                row[q] -= f * pivot_row[q];
            }
            rhs[col + 1 + r] -= f * rhs[col];
        }
    }
    for col in (0..n).rev() {
        let mut x = rhs[col];
        for q in col + 1..n {
            x -= k[col * n + q] * rhs[q];
        }
        rhs[col] = x / k[col * n + col];
    }
    Ok(())
}

fn check_points(p: Option<&[[f64; 3]]>, expected: usize, what: &'static str) -> Result<()> {
    let Some(p) = p else { return Ok(()) };
    if p.len() != expected {
        return Err(Error::CountMismatch { what, expected, got: p.len() });
    }
    if let Some(index) = p.iter().position(|q| !q.iter().all(|x| x.is_finite())) {
        return Err(CageError::NonFinite { what, index, value: p[index] }.into());
    }
    Ok(())
}

/// The joints (translations of the bind transforms) of a skeleton.
fn bind_joints(skeleton: &Skeleton) -> Vec<DVec3> {
    skeleton
        .inverse_bind_transforms()
        .iter()
        .map(|ib| {
            let b = inverse(ib).unwrap_or(crate::skinning::IDENTITY);
            DVec3::new(b[12], b[13], b[14])
        })
        .collect()
}

fn build_skel(
    mvc: &Mvc,
    mesh_points: &[[f64; 3]],
    mesh_triangles: &[[u32; 3]],
    skeleton: &Skeleton,
    skin: &Skin,
) -> Result<Skel> {
    let n = mesh_points.len();
    let influences = skin.influences();
    if influences.n_points() != n {
        return Err(Error::CountMismatch {
            what: "skinned points (the rig's influences)",
            expected: n,
            got: influences.n_points(),
        });
    }
    if influences.n_joints() != skeleton.n_joints() {
        return Err(Error::CountMismatch {
            what: "joints of the skin's influences",
            expected: skeleton.n_joints(),
            got: influences.n_joints(),
        });
    }
    for (face, t) in mesh_triangles.iter().enumerate() {
        for (corner, &v) in t.iter().enumerate() {
            if v as usize >= n {
                return Err(CageError::IndexOutOfRange { face, corner, vertex: v, n_vertices: n }.into());
            }
        }
    }
    let g = *skin.geom_bind_transform();
    let joints = bind_joints(skeleton);
    let c = mvc.n_cage_vertices();
    let cage_s: Vec<DVec3> = mvc.cage().points().iter().map(|p| DVec3::from_array(transform_point(&g, *p))).collect();
    let mesh_s: Vec<[f64; 3]> = mesh_points.iter().map(|p| transform_point(&g, *p)).collect();
    let cage_diag = {
        let (lo, hi) =
            cage_s.iter().fold((DVec3::splat(f64::MAX), DVec3::splat(f64::MIN)), |(l, h), p| (l.min(*p), h.max(*p)));
        (hi - lo).length()
    };
    let mesh_diag = crate::mesh::bounding_box_diagonal(&mesh_s);
    let cage_obj = Cage::new(&cage_s.iter().map(|p| p.to_array()).collect::<Vec<_>>(), mvc.cage().triangles())?;
    let mut psi = vec![0.0; joints.len() * c];
    let mut mvc_row = vec![0.0; n];
    let mut masses = vec![0.0; c];
    for (j, a) in joints.iter().enumerate() {
        // Eq. 9 × the joint's mean value coordinates w.r.t. the mesh.
        super::mvc::raw_coordinates(&mesh_s, mesh_triangles, mesh_diag, *a, &mut mvc_row);
        masses.iter_mut().for_each(|m| *m = 0.0);
        let mut total = 0.0;
        for i in 0..n {
            let (mut wj, mut rest) = (0.0, 0.0);
            for (k, w) in influences.point(i) {
                if k as usize == j {
                    wj += w;
                } else {
                    rest += w;
                }
            }
            let l = -1.0 + wj.max(0.0).powf(LOCALIZATION_EXPONENT) + rest.max(0.0).powf(LOCALIZATION_EXPONENT);
            let f = l.max(0.0) * mvc_row[i].abs();
            if f > 0.0 && f.is_finite() {
                total += f;
                for (m, p) in masses.iter_mut().zip(mvc.row(i)) {
                    *m += f * p;
                }
            }
        }
        let top = masses.iter().fold(0.0f64, |m, x| m.max(*x));
        if !(total > 0.0) || !(top > 0.0) {
            cage_obj.coordinates(a.to_array(), &mut masses);
        }
        let top = masses.iter().fold(0.0f64, |m, x| m.max(*x));
        masses.iter_mut().for_each(|m| *m = m.max(1e-12 * top));
        let b = max_entropy(&cage_s, &masses, *a, cage_diag)
            .map_err(|residual| CageError::JointCoordinates { joint: j, residual })?;
        psi[j * c..(j + 1) * c].copy_from_slice(&b);
    }
    let cor = if skin.method() == SkinningMethod::CentersOfRotation {
        let cors = CentersOfRotation::new(mesh_points, mesh_triangles, influences)?;
        let lambda = cors.cage_coordinates(mesh_points, mesh_triangles, influences, mvc)?;
        let blended: Vec<u32> = (0..n).filter(|&i| cors.is_blended(i)).map(|i| i as u32).collect();
        let centers = match skin.centers_of_rotation() {
            Some(given) => given.to_vec(),
            None => cors.centers().to_vec(),
        };
        Some(Cor { centers, blended, lambda })
    } else {
        None
    };
    let mut skin = skin.clone();
    if let Some(cor) = &cor
        && skin.centers_of_rotation().is_none()
    {
        skin = skin.with_centers_of_rotation(cor.centers.clone())?;
    }
    Ok(Skel { parents: skeleton.parents().to_vec(), joints, psi, skin, cor })
}

/// Eq. 11: `argmax −Σ b ln(b/m)` with `Σ b c = a`, `Σ b = 1`, by Newton's
/// method on the dual: `b_k ∝ m_k exp(λ·(c_k − a)/diag)`. The residual
/// `|Σ b c − a|` when Newton does not reach 1e-8·diag (a joint outside
/// the cage's hull); otherwise polished to rounding ([`polish`]).
fn max_entropy(cage: &[DVec3], masses: &[f64], a: DVec3, diag: f64) -> std::result::Result<Vec<f64>, f64> {
    let x: Vec<DVec3> = cage.iter().map(|c| (*c - a) / diag).collect();
    let mut lambda = DVec3::ZERO;
    let eval = |l: DVec3| -> (f64, DVec3, DMat3, Vec<f64>) {
        let e: Vec<f64> = x.iter().map(|xk| l.dot(*xk)).collect();
        let top = e.iter().fold(f64::MIN, |m, v| m.max(*v));
        let w: Vec<f64> = masses.iter().zip(&e).map(|(m, v)| m * (v - top).exp()).collect();
        let z: f64 = w.iter().sum();
        let b: Vec<f64> = w.iter().map(|v| v / z).collect();
        let g: DVec3 = b.iter().zip(&x).map(|(bk, xk)| *xk * *bk).sum();
        let mut h = DMat3::ZERO;
        for (bk, xk) in b.iter().zip(&x) {
            h += DMat3::from_cols(*xk * xk.x, *xk * xk.y, *xk * xk.z) * *bk;
        }
        h -= DMat3::from_cols(g * g.x, g * g.y, g * g.z);
        (z.ln() + top, g, h, b)
    };
    for _ in 0..500 {
        let (f, g, h, b) = eval(lambda);
        if g.length() < 1e-13 {
            return Ok(b);
        }
        // Newton on the convex dual, damped (Levenberg) when the
        // covariance of the coordinates is nearly singular.
        let mu = 1e-12 * (h.x_axis.x + h.y_axis.y + h.z_axis.z).max(1e-300);
        let step = (h + DMat3::IDENTITY * mu).inverse() * g;
        let step = if step.is_finite() && step.dot(g) > 0.0 { step } else { g };
        let mut t = 1.0;
        loop {
            let next = lambda - step * t;
            let (f2, ..) = eval(next);
            if f2 <= f - 1e-4 * t * g.dot(step) || t < 1e-14 {
                lambda = next;
                break;
            }
            t *= 0.5;
        }
    }
    let (_, g, _, b) = eval(lambda);
    if !(g.length() < 1e-8) {
        return Err(g.length() * diag);
    }
    Ok(polish(&x, b))
}

/// The last step of Eq. 11 in closed form: `b_k ← b_k (1 + μ₀ + μ·x_k)`
/// with `(μ₀, μ)` solving the linearised constraints `Σ b = 1`, `Σ b x = 0`
/// exactly (a 4 × 4 system), so linear precision holds to rounding.
fn polish(x: &[DVec3], mut b: Vec<f64>) -> Vec<f64> {
    use glam::{DMat4, DVec4};
    let mut m = DMat4::ZERO;
    let mut s0 = 0.0;
    let mut s1 = DVec3::ZERO;
    for (bk, xk) in b.iter().zip(x) {
        let v = DVec4::new(1.0, xk.x, xk.y, xk.z);
        m += DMat4::from_cols(v * v.x, v * v.y, v * v.z, v * v.w) * *bk;
        s0 += bk;
        s1 += *xk * *bk;
    }
    let mu = m.inverse() * DVec4::new(1.0 - s0, -s1.x, -s1.y, -s1.z);
    if mu.is_finite() {
        for (bk, xk) in b.iter_mut().zip(x) {
            *bk *= 1.0 + mu.x + mu.y * xk.x + mu.z * xk.y + mu.w * xk.z;
        }
    }
    b
}
