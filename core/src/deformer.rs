//! The deformer: the one way in and the one way through.
//!
//! Every caller — the bake, the service (frames, batches, one-shot deforms,
//! the viewer), the bench, `inspect --bind` and the tests — turns its data
//! into a [`DeformerInput`] (plain slices: the mesh in its projection pose,
//! the curvenets, the blend shapes, the options) and builds a [`Deformer`]
//! with [`Deformer::new`], the only place a binding is made from plain
//! data. A frame is then one call to [`Deformer::frame`], the only place a
//! frame is solved: posed curvenets (or knot tracking), the frame's rest
//! pose, blend-shape weights in either mode, gradients on request, and —
//! for a mesh with a rig underneath ([`Rig`]) — the frame's skinning: the
//! rest pose is the mesh's points skinned by the frame's joint transforms
//! and spline-skinned curvenets take their posed pools from them.
//!
//! ```text
//! DeformerInput ──Deformer::new──▶ Deformer { Binding, BlendShapes, workspaces }
//!   Surface::new                      (validation, face planes, closest-point tree)
//!   CurvenetLayout per curvenet       (§3: topology, sampling, fans, slots)
//!   Binding::with_surface             (§4.1–4.2: cut-mesh, Laplacian, factor)
//! Frame ──Deformer::frame──▶ points (+ gradients)
//!   blend shapes before (sculpt the rest pose)
//!   skinning of the rest pose (Rig::skin)        joint transforms given
//!   spline skinning of curvenets (Rig::curvenets)
//!   Binding::deform (§4.3, §5; Curvenet Adjustments)
//!   blend shapes after (mapped by F_v)
//! [Frame] ──Deformer::frames──▶ the same, per frame, for a group of frames:
//!   each frame's work before the solves, then ONE sweep of each triangular
//!   solve over all the group's columns (9 per frame, then 3), then each
//!   frame's work after them: the factor is read once per group
//! Frame ──Deformer::pose──▶ FramePose: a frame's steps before the solve
//!   alone (rest pose, posed pools, cage), for tools that draw them (the viewer)
//! ```
//!
//! A `Deformer` is immutable and `Send + Sync`: frames of one deformer may
//! be solved from many threads at once; each takes a workspace from the
//! deformer's pool and gives it back, so after the first frames on a thread
//! a frame allocates nothing but what its mode needs (see [`Deformer::frame`]).

use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

use crate::binding::{BindOptions, Binding, Surface};
use crate::blend_shapes::{BlendShape, BlendShapes};
use crate::cage::{CageFrame, CageRevApproximation, CentersOfRotation, CoupledRig, CoupledWorkspace};
use crate::curvenet::{Curvenet, CurvenetLayout, SamplingOptions};
use crate::error::{Error, Result};
use crate::mesh::PolyMesh;
use crate::rig::Rig;
use crate::skinning::SkinningMethod;
use crate::solve::{HasWorkspace, Lanes, Workspace};

pub use crate::frame::{BlendShapeMode, Frame};

/// A mesh in its projection pose (the pose the curvenets were drawn on):
/// USD / OBJ face layout, counter-clockwise faces seen from outside.
#[derive(Debug, Clone, Copy)]
pub struct MeshInput<'a> {
    pub face_vertex_counts: &'a [u32],
    pub face_vertex_indices: &'a [u32],
    pub projection_points: &'a [[f64; 3]],
}

/// A curvenet: cubic Bézier splines over a pool of control points in the
/// neutral pose, and its sampling density (the paper's samples per mean edge, 5).
#[derive(Debug, Clone, Copy)]
pub struct CurvenetInput<'a> {
    pub splines: &'a [[u32; 4]],
    pub pool: &'a [[f64; 3]],
    pub sample_density: f64,
}

/// A closed triangle cage around the mesh (Corda et al. 2020,
/// [`crate::cage`]): its rest points at bind — the cage the mesh's
/// projection points are bound to, `M₀ = Φ C₀` — and its outward
/// counter-clockwise triangles.
#[derive(Debug, Clone, Copy)]
pub struct CageInput<'a> {
    pub points: &'a [[f64; 3]],
    pub triangles: &'a [[u32; 3]],
}

/// Everything a deformer is built from.
#[derive(Debug, Clone)]
pub struct DeformerInput<'a> {
    pub mesh: MeshInput<'a>,
    /// The curvenets, in the order frames give their posed pools.
    pub curvenets: &'a [CurvenetInput<'a>],
    /// The mesh's blend shapes (UsdSkel semantics), in the order frames give their weights.
    pub blend_shapes: Vec<BlendShape>,
    /// The rig underneath, when the mesh is skinned in process: frames then
    /// give joint transforms ([`Frame::joint_transforms`]).
    pub skinning: Option<Rig>,
    /// A cage coupled with the rig (Corda et al. 2020, [`crate::cage`]):
    /// with a [`Rig`] (which then needs its [`Rig::skeleton`]) the cage and
    /// the skeleton are synchronised (SkelUp, CageUp, CageRev) and the
    /// frame's rest pose is the coupled result; without one the cage alone
    /// deforms the mesh, `M = Φ C` (+ the frame's sculpt). Frames edit it
    /// with [`Frame::rest_cage`] and [`Frame::posed_cage_offsets`].
    pub cage: Option<CageInput<'a>>,
    pub options: DeformerOptions,
}

impl DeformerInput<'_> {
    /// A fixed encoding of everything [`Deformer::new`] builds from (the
    /// mesh, the curvenets, the blend shapes, the rig, the cage and the
    /// options, f64 values by their bits), prefixed by the stored format's
    /// version ([`crate::persist::FORMAT_VERSION`]): equal bytes, equal
    /// deformers. Hashed, it names a stored binding (`curvenet bake
    /// --store`). The cancellation flag is not part of it.
    pub fn content_bytes(&self) -> Vec<u8> {
        let mut out = Vec::new();
        self.write_content(|b| out.extend_from_slice(b));
        out
    }

    /// [`Self::content_bytes`] handed to `sink` in pieces of at most 64 KiB,
    /// in order: how to hash the content without holding it all.
    pub fn write_content(&self, sink: impl FnMut(&[u8])) {
        /// A curvenet's splines, pool and density; a cage's points and triangles.
        type Net<'a> = (&'a [[u32; 4]], &'a [[f64; 3]], f64);
        type Cage<'a> = (&'a [[f64; 3]], &'a [[u32; 3]]);
        #[derive(serde::Serialize)]
        struct Content<'a> {
            format: u32,
            face_vertex_counts: &'a [u32],
            face_vertex_indices: &'a [u32],
            projection_points: &'a [[f64; 3]],
            curvenets: Vec<Net<'a>>,
            blend_shapes: &'a [BlendShape],
            skinning: &'a Option<Rig>,
            cage: Option<Cage<'a>>,
            snap_tolerance: f64,
            max_projection_distance: f64,
            lambda: f64,
            strict: bool,
            max_segments_per_spline: Option<u32>,
        }
        let bind = &self.options.bind;
        let content = Content {
            format: crate::persist::FORMAT_VERSION,
            face_vertex_counts: self.mesh.face_vertex_counts,
            face_vertex_indices: self.mesh.face_vertex_indices,
            projection_points: self.mesh.projection_points,
            curvenets: self.curvenets.iter().map(|c| (c.splines, c.pool, c.sample_density)).collect(),
            blend_shapes: &self.blend_shapes,
            skinning: &self.skinning,
            cage: self.cage.map(|c| (c.points, c.triangles)),
            snap_tolerance: bind.cut.snap_tolerance,
            max_projection_distance: bind.cut.max_projection_distance,
            lambda: bind.lambda,
            strict: bind.strict,
            max_segments_per_spline: self.options.max_segments_per_spline,
        };
        postcard::to_extend(&content, Chunks::new(sink))
            .expect("postcard serialises slices and numbers into any Extend")
            .flush();
    }
}

/// An `Extend<u8>` that hands its bytes on in chunks (postcard pushes them
/// one at a time).
struct Chunks<F: FnMut(&[u8])> {
    buf: Vec<u8>,
    sink: F,
}

impl<F: FnMut(&[u8])> Chunks<F> {
    const CAPACITY: usize = 1 << 16;

    fn new(sink: F) -> Self {
        Self { buf: Vec::with_capacity(Self::CAPACITY), sink }
    }

    fn flush(mut self) {
        (self.sink)(&self.buf);
    }
}

impl<F: FnMut(&[u8])> Extend<u8> for Chunks<F> {
    fn extend<I: IntoIterator<Item = u8>>(&mut self, bytes: I) {
        for b in bytes {
            if self.buf.len() == Self::CAPACITY {
                (self.sink)(&self.buf);
                self.buf.clear();
            }
            self.buf.push(b);
        }
    }
}

/// G¹-flexible spline skinning done over a deformer's frames so far.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FlexibleStats {
    /// Alternating iterations done, all poses together.
    pub iterations: u64,
    /// Curvenet poses computed with [`SplineSkinning::pose_flexible`].
    pub poses: u64,
}

/// Options of [`Deformer::new`].
#[derive(Debug, Clone, Default)]
#[non_exhaustive]
pub struct DeformerOptions {
    pub bind: BindOptions,
    /// The sampling's cap on segments per spline (`None`: the default).
    pub max_segments_per_spline: Option<u32>,
}

impl DeformerOptions {
    pub fn with_bind(mut self, bind: BindOptions) -> Self {
        self.bind = bind;
        self
    }
    pub fn with_max_segments_per_spline(mut self, max: u32) -> Self {
        self.max_segments_per_spline = Some(max);
        self
    }
}

/// Times of a deformer's construction, milliseconds.
#[derive(Debug, Clone, Copy, Default, serde::Serialize, serde::Deserialize)]
pub struct DeformerTimings {
    /// Curvenet analysis and sampling (paper §3), all curvenets.
    pub analysis_ms: f64,
    /// Surface, cutting, assembly and factor: see [`Binding::timings`].
    pub binding: crate::binding::BindTimings,
    /// The whole construction, wall time.
    pub total_ms: f64,
}

/// What one frame solve needs besides the binding's own workspace.
#[derive(Debug)]
struct Scratch {
    ws: Workspace,
    /// Gradients for the `after` blend-shape mode when the caller wants none.
    gradients: Vec<[f64; 9]>,
    /// `None` per curvenet, for frames that articulate none.
    unposed: Vec<Option<&'static [[f64; 3]]>>,
    /// The buffers of the frame's pose before the solve ([`Deformer::pose_rig`]).
    rig: RigScratch,
}

/// The buffers [`Deformer::pose_rig`] poses a frame's rest pose and
/// curvenets in (blend shapes before, skinning, the coupled cage).
#[derive(Debug, Default)]
struct RigScratch {
    /// The sculpted rest pose of the `before` mode.
    sculpted: Vec<[f64; 3]>,
    /// The skinned rest pose of a frame with joint transforms.
    skinned: Vec<[f64; 3]>,
    /// The spline-skinned pool of each curvenet (empty for the others).
    pools: Vec<Vec<[f64; 3]>>,
    /// The coupled cage's buffers.
    cage: CoupledWorkspace,
}

/// A frame's pose as the solve takes it ([`Deformer::pose_rig`]): the rest
/// pose and the posed pool of each curvenet, borrowed from the frame and
/// from the workspace.
struct Posed<'p> {
    /// The rest pose the binding deforms from (`None`: the projection pose).
    rest: Option<&'p [[f64; 3]]>,
    /// Every curvenet's posed pool when the rig spline-skinned some, else empty.
    skinned: Vec<Option<&'p [[f64; 3]]>>,
    /// The frame's own posed pools, or one `None` per curvenet when it gave none.
    given: &'p [Option<&'p [[f64; 3]]>],
}

impl<'p> Posed<'p> {
    /// The posed pool of each curvenet (`None`: it tracks the rest pose).
    fn posed(&self) -> &[Option<&'p [[f64; 3]]>] {
        if self.skinned.is_empty() { self.given } else { &self.skinned }
    }
}

/// A frame's pose before its solve, as [`Deformer::frame`] gives it to the
/// binding ([`Deformer::pose`]): for tools that draw what the solve sees
/// (the service's viewer) without evaluating blend shapes, skinning or
/// cages themselves.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FramePose {
    /// The rest pose the curvenets' tracking and the solve use: the frame's
    /// rest pose with blend shapes in the `before` mode added, skinned by the
    /// rig, through the coupled cage. `None`: the projection pose (the frame
    /// gave none and nothing changed it).
    pub rest: Option<Vec<[f64; 3]>>,
    /// The posed pool of each curvenet (absolute positions), in binding
    /// order: the spline skinning of a spline-skinned curvenet, else the
    /// frame's own; `None` for a curvenet that tracks the rest pose.
    pub posed: Vec<Option<Vec<[f64; 3]>>>,
    /// The coupled cage this frame, for a deformer with a cage.
    pub cage: Option<CagePose>,
}

/// A coupled cage as one frame poses it ([`FramePose::cage`]).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct CagePose {
    /// The rest cage `C` (the frame's rest-cage edits, then CageRev of its
    /// posed-cage offsets), the mesh's space.
    pub rest: Vec<[f64; 3]>,
    /// The posed cage `C′`: CageUp of the skinned mesh for a cage coupled
    /// with a skeleton (the skeleton's space), else the rest cage.
    pub posed: Vec<[f64; 3]>,
}

/// The workspaces of a group of frames solved together ([`Deformer::frames`]).
#[derive(Debug, Default)]
struct Batch {
    /// One per frame of the largest group solved so far.
    scratches: Vec<Scratch>,
    /// The group's right-hand sides and solutions, lane-interleaved.
    lanes: Lanes,
}

impl HasWorkspace for Scratch {
    fn workspace(&mut self) -> &mut Workspace {
        &mut self.ws
    }
}

/// Where [`Deformer::frames`] writes one frame: its points and, when
/// given, its per-vertex deformation gradients.
#[derive(Debug)]
pub struct FrameOut<'a> {
    pub points: &'a mut [[f64; 3]],
    pub gradients: Option<&'a mut [[f64; 9]]>,
}

/// A frame of [`Deformer::frames`] failed: its index in the frames given, and why.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("frame {frame} of the group: {error}")]
pub struct BatchError {
    pub frame: usize,
    #[source]
    pub error: Error,
}

/// The most frames [`Deformer::frames`] solves in one sweep; more are
/// solved in consecutive groups of this many (the widest group
/// `curvenet bench` measures). A group's block holds 12 values per frame
/// per unknown and per constraint row (9 gradient columns, 3 position
/// columns): 3.1 KB per unknown and per constraint row at 32, about 290 MB
/// on the 94k hand, kept for reuse by each thread solving groups.
pub const MAX_BATCH_FRAMES: usize = 32;
// A group's frames are lanes of `Lanes`, masked by `u32` bits.
const _: () = assert!(MAX_BATCH_FRAMES <= crate::sparse::MAX_LANES && crate::sparse::MAX_LANES <= 32);

/// The group size callers use when they have no reason to choose another
/// (`curvenet bake --batch-frames`, the service's batches): the K with the
/// best throughput on both threads at 94k in `curvenet bench` (one run on a
/// loaded machine, README, Performance; at 22k the K values were within
/// the noise of each other).
pub const DEFAULT_BATCH_FRAMES: usize = 8;

/// A bound mesh: the binding, the blend shapes and a pool of workspaces.
#[derive(Debug)]
pub struct Deformer {
    binding: Binding,
    shapes: BlendShapes,
    projection_points: Vec<[f64; 3]>,
    timings: DeformerTimings,
    pool: Mutex<Vec<Scratch>>,
    /// Workspaces of groups of frames ([`Deformer::frames`]).
    batches: Mutex<Vec<Batch>>,
    rig: Option<Rig>,
    cage: Option<CoupledRig>,
    flexible_iterations: AtomicU64,
    flexible_poses: AtomicU64,
}

/// What a stored deformer holds ([`Deformer::to_bytes`]): everything but
/// its workspaces and counters, which a loaded deformer starts afresh.
#[derive(serde::Serialize)]
struct StoredRef<'a> {
    binding: &'a Binding,
    shapes: &'a BlendShapes,
    projection_points: &'a [[f64; 3]],
    timings: &'a DeformerTimings,
    rig: &'a Option<Rig>,
    cage: &'a Option<CoupledRig>,
}

/// [`StoredRef`] read back (the same fields in the same order).
#[derive(serde::Deserialize)]
struct Stored {
    binding: Binding,
    shapes: BlendShapes,
    projection_points: Vec<[f64; 3]>,
    timings: DeformerTimings,
    rig: Option<Rig>,
    cage: Option<CoupledRig>,
}

/// At most this many workspaces are kept for reuse (one per solving thread is enough).
const KEEP_WORKSPACES: usize = 32;

impl Deformer {
    /// Binds the curvenets to the mesh: validates the mesh, analyses and
    /// samples every curvenet against it, cuts and factors. Errors about a
    /// curvenet's own shape are wrapped in [`Error::Curvenet`] naming it;
    /// binding errors name segments as (curvenet, spline, segment). A rig
    /// whose sizes do not match the mesh or its curvenets is refused, naming
    /// the count (and the curvenet).
    pub fn new(input: &DeformerInput<'_>) -> Result<Self> {
        let t0 = Instant::now();
        if input.curvenets.is_empty() {
            return Err(Error::Empty { what: "the list of curvenets to bind" });
        }
        let m = input.mesh;
        let n = m.projection_points.len();
        if let Some(rig) = &input.skinning {
            check_rig(rig, n, input.curvenets)?;
        }
        let mesh = PolyMesh::new(m.face_vertex_counts, m.face_vertex_indices, n)?;
        let mut rig = input.skinning.clone();
        let cage = rig_layers(&mesh, m.projection_points, &mut rig, input.cage.as_ref())?;
        let surface = Surface::new(&mesh, m.projection_points)?;
        let surface_ms = ms(t0);
        input.options.bind.cancel.check("the curvenet analysis")?;
        let t1 = Instant::now();
        let layouts = input
            .curvenets
            .iter()
            .enumerate()
            .map(|(k, c)| {
                let mut options = SamplingOptions::default().with_density(c.sample_density);
                if let Some(max) = input.options.max_segments_per_spline {
                    options = options.with_max_segments_per_spline(max);
                }
                Curvenet::new(c.splines, c.pool)
                    .and_then(|net| {
                        CurvenetLayout::with_closest_point(
                            &net,
                            surface.closest_points(),
                            surface.mean_edge_length(),
                            &options,
                        )
                    })
                    .map_err(|e| Error::Curvenet { curvenet: k as u32, source: Box::new(e) })
            })
            .collect::<Result<Vec<_>>>()?;
        let analysis_ms = ms(t1);
        let refs: Vec<&CurvenetLayout> = layouts.iter().collect();
        let binding = Binding::with_surface(surface, &refs, &input.options.bind, surface_ms)?;
        let shapes = BlendShapes::new(n, input.blend_shapes.clone());
        let timings = DeformerTimings { analysis_ms, binding: binding.timings(), total_ms: ms(t0) };
        Ok(Self {
            binding,
            shapes,
            projection_points: m.projection_points.to_vec(),
            timings,
            pool: Mutex::new(Vec::new()),
            batches: Mutex::new(Vec::new()),
            rig,
            cage,
            flexible_iterations: AtomicU64::new(0),
            flexible_poses: AtomicU64::new(0),
        })
    }

    /// The deformer in the stored format ([`crate::persist`]: versioned,
    /// checksummed, little-endian): the binding, the blend shapes, the
    /// projection pose and the rig and cage, everything a frame needs.
    /// [`Self::from_bytes`] reads it back into a deformer whose frames are
    /// bit for bit this one's.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(self.stored_bytes_hint());
        self.append_bytes(&mut out);
        out
    }

    /// [`Self::to_bytes`] appended to `out`: how an envelope (the
    /// service's stored entry) holds the deformer without a second copy.
    pub fn append_bytes(&self, out: &mut Vec<u8>) {
        let stored = StoredRef {
            binding: &self.binding,
            shapes: &self.shapes,
            projection_points: &self.projection_points,
            timings: &self.timings,
            rig: &self.rig,
            cage: &self.cage,
        };
        crate::persist::encode_into(&stored, crate::persist::KIND_DEFORMER, out)
    }

    /// About how many bytes [`Self::to_bytes`] writes (a capacity to reserve).
    pub fn stored_bytes_hint(&self) -> usize {
        crate::persist::HEADER_BYTES + self.binding.heap_bytes() + self.projection_points.len() * 24
    }

    /// A deformer read back from [`Self::to_bytes`]'s bytes. Refuses, with
    /// the reason, bytes that are truncated, corrupted (checksum), of
    /// another format version or not a deformer; never panics on any bytes.
    /// Its timings are those of the original build.
    pub fn from_bytes(bytes: &[u8]) -> std::result::Result<Self, crate::persist::FormatError> {
        let s: Stored = crate::persist::decode(bytes, crate::persist::KIND_DEFORMER)?;
        Ok(Self {
            binding: s.binding,
            shapes: s.shapes,
            projection_points: s.projection_points,
            timings: s.timings,
            pool: Mutex::new(Vec::new()),
            batches: Mutex::new(Vec::new()),
            rig: s.rig,
            cage: s.cage,
            flexible_iterations: AtomicU64::new(0),
            flexible_poses: AtomicU64::new(0),
        })
    }

    /// Deforms the mesh for one frame into `out` (one point per vertex) and,
    /// when given, each vertex's deformation gradient (row-major 3×3) into
    /// `gradients`.
    ///
    /// A frame is, in order: blend shapes in the `before` mode added to the
    /// rest pose (or the projection pose); with joint transforms, that pose
    /// skinned by the [`Rig`]'s skin (the frame's rest pose) and the
    /// spline-skinned curvenets posed; the solve (posed pools or knot
    /// tracking, then Curvenet Adjustments); blend shapes in the `after`
    /// mode mapped by each vertex's deformation gradient.
    ///
    /// Allocates nothing once this thread's workspace exists, except a
    /// frame in the `before` blend-shape mode with no rest pose of its own
    /// (it copies the projection pose to sculpt it, into a reused buffer),
    /// a frame spline-skinning a curvenet (the list of posed pools, and
    /// whatever [`SplineSkinning::pose`] needs) and the
    /// first skinned frames on a thread (reused buffers).
    /// Errors name the array and element (counts, non-finite values, a
    /// degenerate pose of a named curvenet, a joint transform).
    pub fn frame(&self, frame: &Frame<'_>, out: &mut [[f64; 3]], gradients: Option<&mut [[f64; 9]]>) -> Result<()> {
        let mut s = self.take();
        let result = (|| {
            self.stage(frame, &mut s, out.len())?;
            self.binding.deform_rows(&mut s.ws)?;
            self.solve_staged(frame, &mut s, out, gradients)
        })();
        self.give(s);
        result
    }

    /// Deforms the mesh for several frames at once: frame `i` of `frames`
    /// into `outs[i]` (points and, when given, gradients), exactly as
    /// [`Self::frame`] would, in one sweep of each triangular solve for up
    /// to [`MAX_BATCH_FRAMES`] frames (more are solved in consecutive
    /// groups of that many). Each frame's samples are made in its own
    /// workspace; its curvenet and constraint rows are made in the group's
    /// block ([`crate::solve`]'s `Lanes`: rows in the factor's order, every
    /// frame's columns side by side), all frames at once, one per vector
    /// lane, for groups of 2, 4, 8 or 16 frames in the projection pose
    /// (`curvenet/lanes.rs`); otherwise frame by frame in the
    /// workspaces and copied in. The harmonic right-hand
    /// sides (9 columns per frame) are built there by one pass over `B`,
    /// solved in one sweep, the Poisson ones (3 per frame) built by one
    /// pass over `B` and the gradient operator and solved in one sweep, so
    /// every entry of the factor and of those operators is read once per
    /// group rather than once per frame; a frame with its own rest pose
    /// builds its Poisson right-hand side in its workspace (its operator is
    /// its own). The solutions go back to the workspaces for the output.
    /// The results are bit for bit those of [`Self::frame`] (every frame
    /// sees the same operations in the same order), whatever the group
    /// size (`tests/multi_frame.rs`).
    ///
    /// Runs on the calling thread: parallelise across groups of frames.
    /// Allocates nothing once a group of at least as many frames has been
    /// solved (the workspaces of a group and its stacked columns are kept
    /// for reuse, one set per thread solving groups at once), except as
    /// [`Self::frame`] does per frame: a workspace sizes the buffers a
    /// frame's mode needs the first time a frame in that mode uses it.
    /// The first group of two or more frames on a binding also makes the
    /// factor's row copy its forward sweeps read
    /// ([`crate::binding::Binding::factor_row_copy_bytes`]), once.
    /// An error names the frame (its index in `frames`); the outputs of the
    /// other frames are then unspecified.
    pub fn frames(&self, frames: &[Frame<'_>], outs: &mut [FrameOut<'_>]) -> std::result::Result<(), BatchError> {
        if outs.len() != frames.len() {
            let error = Error::CountMismatch { what: "frame outputs", expected: frames.len(), got: outs.len() };
            return Err(BatchError { frame: frames.len().min(outs.len()), error });
        }
        let mut batch = self.take_batch();
        let mut result = Ok(());
        for (g, (group, outs)) in frames.chunks(MAX_BATCH_FRAMES).zip(outs.chunks_mut(MAX_BATCH_FRAMES)).enumerate() {
            result = self
                .solve_group(group, outs, &mut batch)
                .map_err(|(i, error)| BatchError { frame: g * MAX_BATCH_FRAMES + i, error });
            if result.is_err() {
                break;
            }
        }
        self.give_batch(batch);
        result
    }

    /// One sweep of each solve for `frames` (at most [`MAX_BATCH_FRAMES`]).
    fn solve_group(
        &self,
        frames: &[Frame<'_>],
        outs: &mut [FrameOut<'_>],
        batch: &mut Batch,
    ) -> std::result::Result<(), (usize, Error)> {
        let k = frames.len();
        while batch.scratches.len() < k {
            batch.scratches.push(self.take());
        }
        let scratches = &mut batch.scratches[..k];
        for (i, ((frame, out), s)) in frames.iter().zip(outs.iter()).zip(scratches.iter_mut()).enumerate() {
            self.stage(frame, s, out.points.len()).map_err(|e| (i, e))?;
        }
        if k == 1 {
            // A group of one solves in its own workspace, as `frame` does:
            // the interleaved block would only be a copy of it.
            let out = &mut outs[0];
            let s = &mut scratches[0];
            return self
                .binding
                .deform_rows(&mut s.ws)
                .and_then(|()| self.solve_staged(&frames[0], s, out.points, out.gradients.as_deref_mut()))
                .map_err(|e| (0, e));
        }
        // Every frame's constraint rows into its lane (made there, all
        // frames at once, when the group allows it; else frame by frame and
        // copied in); the harmonic right-hand sides and solve, 9 columns
        // per frame; then the Poisson ones, 3 per frame. f_v (and f_c) come
        // back to the workspaces of the frames whose output needs it
        // (gradients, or blend shapes after the solve; the lanes add the
        // frames with their own rest pose), x_v to every one.
        let mut wants_fv = 0u32;
        for (i, (frame, out)) in frames.iter().zip(outs.iter()).enumerate() {
            if out.gradients.is_some() || self.after_weights(frame).is_some() {
                wants_fv |= 1 << i;
            }
        }
        let lanes = &mut batch.lanes;
        self.binding.lanes_start(lanes, k);
        if !self.binding.lanes_rows(lanes, scratches, wants_fv) {
            for (i, s) in scratches.iter_mut().enumerate() {
                self.binding.deform_rows(&mut s.ws).map_err(|e| (i, e))?;
            }
            self.binding.lanes_load(lanes, scratches);
        }
        self.binding.lanes_solve_harmonic(lanes, scratches, wants_fv);
        self.binding.lanes_solve_poisson(lanes, scratches);
        for (i, ((frame, out), s)) in frames.iter().zip(outs.iter_mut()).zip(scratches.iter_mut()).enumerate() {
            self.finish(frame, s, out.points, out.gradients.as_deref_mut()).map_err(|e| (i, e))?;
        }
        Ok(())
    }

    /// A staged frame ([`Self::stage`]) solved in its own workspace: both
    /// solves, the Poisson right-hand side between them, and the output.
    fn solve_staged(
        &self,
        frame: &Frame<'_>,
        s: &mut Scratch,
        out: &mut [[f64; 3]],
        gradients: Option<&mut [[f64; 9]]>,
    ) -> Result<()> {
        self.binding.harmonic_rhs(&mut s.ws);
        self.binding.solve_harmonic(&mut s.ws);
        self.binding.deform_poisson_rhs(&mut s.ws);
        self.binding.solve_poisson(&mut s.ws);
        self.finish(frame, s, out, gradients)
    }

    /// A frame's work before its solves, into `s`: the frame posed
    /// ([`Self::pose_rig`]), then the binding's checks and curvenet samples
    /// (`Binding::deform_samples`). The constraint rows come next:
    /// `Binding::deform_rows` for one frame, or a group's
    /// `Binding::lanes_rows` (the harmonic right-hand side is built by
    /// [`Self::solve_staged`], or in a group's block). `n_out`: the length
    /// of the caller's output points.
    fn stage(&self, frame: &Frame<'_>, s: &mut Scratch, n_out: usize) -> Result<()> {
        let Scratch { ws, unposed, rig, .. } = s;
        let posed = self.pose_rig(frame, rig, unposed, true)?;
        let input =
            Frame { posed: posed.posed(), rest: posed.rest, adjustments: frame.adjustments, ..Frame::default() };
        self.binding.deform_samples(&input, ws, n_out)
    }

    /// A frame's pose as [`Self::frame`] gives it to the solve, without
    /// solving: the rest pose (blend shapes in the `before` mode, the rig's
    /// skinning, the coupled cage), every curvenet's posed pool (spline
    /// skinning) and the cage, by the very code [`Self::frame`] runs (so
    /// bit for bit what it solves from). For tools that draw a frame's
    /// pose, like the service's viewer. Refuses what [`Self::frame`] refuses
    /// before its solve (blend-shape weights, joint transforms, cage edits,
    /// posed pools of a skinned frame; the binding's own checks of the pools
    /// and the rest pose come with the solve). Counts no G¹-flexible
    /// iterations ([`Self::flexible_stats`] counts frames).
    pub fn pose(&self, frame: &Frame<'_>) -> Result<FramePose> {
        let mut s = self.take();
        let result = (|| {
            let Scratch { unposed, rig, .. } = &mut s;
            let posed = self.pose_rig(frame, rig, unposed, false)?;
            let rest = posed.rest.map(<[_]>::to_vec);
            let pools = posed.posed().iter().map(|p| p.map(<[_]>::to_vec)).collect();
            let cage = self
                .cage
                .as_ref()
                .map(|_| CagePose { rest: rig.cage.rest_cage().to_vec(), posed: rig.cage.posed_cage().to_vec() });
            Ok(FramePose { rest, posed: pools, cage })
        })();
        self.give(s);
        result
    }

    /// A frame posed before its solve, into `buffers` ([`Self::stage`] and
    /// [`Self::pose`] both pose through here): checks, blend shapes in the
    /// `before` mode, the rig's skinning (through the coupled cage when
    /// there is one), the spline-skinned curvenets' pools. `unposed`: one
    /// `None` per curvenet, for a frame that articulates none.
    /// `count_flexible`: add the G¹-flexible iterations to the deformer's
    /// [`FlexibleStats`].
    fn pose_rig<'p>(
        &'p self,
        frame: &Frame<'p>,
        buffers: &'p mut RigScratch,
        unposed: &'p [Option<&'static [[f64; 3]]>],
        count_flexible: bool,
    ) -> Result<Posed<'p>> {
        let n = self.binding.n_vertices();
        if let Some(w) = frame.blend_shape_weights
            && w.len() != self.shapes.len()
        {
            return Err(Error::CountMismatch {
                what: "blend-shape weights",
                expected: self.shapes.len(),
                got: w.len(),
            });
        }
        if let Some(i) = frame.blend_shape_weights.and_then(|w| w.iter().position(|x| !x.is_finite())) {
            let value = frame.blend_shape_weights.map_or(f64::NAN, |w| w[i]);
            return Err(Error::NonFiniteScalar { what: "blend-shape weight", index: i, value });
        }
        let skinning = match (&self.rig, frame.joint_transforms) {
            (Some(rig), Some(t)) => Some((rig, t)),
            (None, Some(_)) => {
                return Err(Error::Unsupported {
                    what: "joint transforms for a deformer without a rig (DeformerInput::skinning)",
                });
            }
            (_, None) => None,
        };
        if self.cage.is_none() && (frame.rest_cage.is_some() || frame.posed_cage_offsets.is_some()) {
            return Err(Error::Unsupported {
                what: "rest-cage points or posed-cage offsets for a deformer without a cage (DeformerInput::cage)",
            });
        }
        let n_nets = self.binding.n_curvenets();
        if skinning.is_some() && !frame.posed.is_empty() && frame.posed.len() != n_nets {
            return Err(Error::CountMismatch { what: "posed curvenets", expected: n_nets, got: frame.posed.len() });
        }
        let RigScratch { sculpted, skinned, pools, cage: cage_ws } = buffers;
        let weights = self.active_weights(frame);
        let rest = match (weights, frame.blend_shape_mode) {
            (Some(w), BlendShapeMode::Before) => {
                sculpted.clear();
                sculpted.extend_from_slice(frame.rest.unwrap_or(&self.projection_points));
                if sculpted.len() != n {
                    return Err(Error::CountMismatch { what: "rest-pose points", expected: n, got: sculpted.len() });
                }
                self.shapes.add_to(w, sculpted)?;
                Some(&sculpted[..])
            }
            _ => frame.rest,
        };
        // The rig: the rest pose skinned (through the coupled cage when
        // there is one), spline-skinned curvenets posed.
        let mut skinned_posed: Vec<Option<&[[f64; 3]]>> = Vec::new();
        let rest = match (skinning, &self.cage) {
            (None, None) => rest,
            (None, Some(cage)) => {
                // The cage alone (or a rig posed at bind this frame).
                let base = rest.unwrap_or(&self.projection_points);
                skinned.resize(base.len(), [0.0; 3]);
                let f = CageFrame {
                    base: Some(base),
                    rest_cage: frame.rest_cage,
                    joint_transforms: None,
                    posed_cage_offsets: frame.posed_cage_offsets,
                };
                cage.evaluate(&f, cage_ws, skinned)?;
                Some(&skinned[..])
            }
            (Some((rig, frame_transforms)), cage) => {
                let bind = rest.unwrap_or(&self.projection_points);
                skinned.resize(bind.len(), [0.0; 3]);
                let transforms = match cage {
                    None => {
                        rig.skin.skin_points(bind, frame_transforms, skinned)?;
                        frame_transforms
                    }
                    Some(cage) => {
                        let f = CageFrame {
                            base: Some(bind),
                            rest_cage: frame.rest_cage,
                            joint_transforms: Some(frame_transforms),
                            posed_cage_offsets: frame.posed_cage_offsets,
                        };
                        cage.evaluate(&f, cage_ws, skinned)?;
                        // The curvenets follow the joints SkelUp moved.
                        cage_ws.transforms()
                    }
                };
                pools.resize_with(n_nets, Vec::new);
                for (k, spline) in rig.curvenets.iter().enumerate() {
                    let Some(spline) = spline else { continue };
                    let pool = &mut pools[k];
                    pool.resize(spline.n_points(), [0.0; 3]);
                    let posed = if rig.flexible_iterations == 0 {
                        spline.pose(transforms, pool)
                    } else {
                        spline.pose_flexible(transforms, rig.flexible_iterations, pool).map(|report| {
                            if count_flexible {
                                self.flexible_iterations.fetch_add(report.iterations as u64, Ordering::Relaxed);
                                self.flexible_poses.fetch_add(1, Ordering::Relaxed);
                            }
                        })
                    };
                    posed.map_err(|e| Error::Curvenet { curvenet: k as u32, source: Box::new(e) })?;
                }
                let pools: &'p [Vec<[f64; 3]>] = pools;
                skinned_posed.extend(rig.curvenets.iter().enumerate().map(move |(k, spline)| match spline {
                    Some(_) => Some(&pools[k][..]),
                    None => frame.posed.get(k).copied().flatten(),
                }));
                Some(&skinned[..])
            }
        };
        let given: &'p [Option<&'p [[f64; 3]]>] = if frame.posed.is_empty() { unposed } else { frame.posed };
        Ok(Posed { rest, skinned: skinned_posed, given })
    }

    /// A frame's work after its solves: the output points (and gradients),
    /// then blend shapes in the `after` mode mapped by each vertex's
    /// deformation gradient.
    fn finish(
        &self,
        frame: &Frame<'_>,
        s: &mut Scratch,
        out: &mut [[f64; 3]],
        gradients: Option<&mut [[f64; 9]]>,
    ) -> Result<()> {
        let n = self.binding.n_vertices();
        let Scratch { ws, gradients: own, rig: RigScratch { sculpted, skinned, .. }, .. } = s;
        // The rest pose `stage` gave the binding.
        let rest = if self.cage.is_some() || (self.rig.is_some() && frame.joint_transforms.is_some()) {
            Some(&skinned[..])
        } else if self.active_weights(frame).is_some() && frame.blend_shape_mode == BlendShapeMode::Before {
            Some(&sculpted[..])
        } else {
            frame.rest
        };
        match (self.after_weights(frame), gradients) {
            (Some(w), Some(g)) => {
                self.binding.deform_output(rest, ws, out, Some(&mut *g))?;
                self.shapes.add_deformed(w, g, out)
            }
            (Some(w), None) => {
                own.resize(n, [0.0; 9]);
                self.binding.deform_output(rest, ws, out, Some(own))?;
                self.shapes.add_deformed(w, own, out)
            }
            (None, g) => self.binding.deform_output(rest, ws, out, g),
        }
    }

    /// The frame's blend-shape weights when they do anything and apply after
    /// the solve (mapped by the deformation gradients).
    fn after_weights<'f>(&self, frame: &Frame<'f>) -> Option<&'f [f64]> {
        self.active_weights(frame).filter(|_| frame.blend_shape_mode == BlendShapeMode::After)
    }

    /// The frame's blend-shape weights when they do anything (some shape, a nonzero weight).
    fn active_weights<'f>(&self, frame: &Frame<'f>) -> Option<&'f [f64]> {
        frame.blend_shape_weights.filter(|w| !self.shapes.is_empty() && w.iter().any(|&x| x != 0.0))
    }

    /// The workspaces of a group of frames, reused when one is free.
    fn take_batch(&self) -> Batch {
        let reused = self.batches.lock().unwrap_or_else(|e| e.into_inner()).pop();
        reused.unwrap_or_default()
    }

    fn give_batch(&self, b: Batch) {
        let mut pool = self.batches.lock().unwrap_or_else(|e| e.into_inner());
        if pool.len() < KEEP_WORKSPACES {
            pool.push(b);
        }
    }

    /// A workspace for one frame, reused from earlier frames when one is free.
    fn take(&self) -> Scratch {
        let reused = self.pool.lock().unwrap_or_else(|e| e.into_inner()).pop();
        reused.unwrap_or_else(|| Scratch {
            ws: self.binding.workspace(),
            gradients: Vec::new(),
            unposed: vec![None; self.binding.n_curvenets()],
            rig: RigScratch::default(),
        })
    }

    fn give(&self, s: Scratch) {
        let mut pool = self.pool.lock().unwrap_or_else(|e| e.into_inner());
        if pool.len() < KEEP_WORKSPACES {
            pool.push(s);
        }
    }

    /// Heap bytes a group workspace of `k` frames holds once it has solved
    /// a group: [`Self::frames`] keeps it for reuse, one per thread solving
    /// groups at once. That is `k` frame workspaces of `workspace_bytes`
    /// each (as [`Self::prepare_workspace`] measures one) and the group's
    /// interleaved block, 96·k bytes per unknown and per constraint row.
    pub fn group_bytes(&self, k: usize, workspace_bytes: usize) -> usize {
        k * workspace_bytes + self.binding.lanes_bytes(k)
    }

    /// Makes one frame workspace now, so the first frame finds it in the
    /// pool, and returns its heap bytes (for callers that budget memory per
    /// workspace: one is kept per thread that solves frames at once).
    pub fn prepare_workspace(&self) -> usize {
        let s = self.take();
        let bytes = s.ws.heap_bytes();
        self.give(s);
        bytes
    }

    /// The binding (cut-mesh, factor, analysed curvenets, warnings, stats).
    pub fn binding(&self) -> &Binding {
        &self.binding
    }
    /// The blend shapes, in the order of a frame's weights.
    pub fn blend_shapes(&self) -> &BlendShapes {
        &self.shapes
    }
    /// The mesh in its projection pose.
    pub fn projection_points(&self) -> &[[f64; 3]] {
        &self.projection_points
    }
    /// Number of mesh vertices: the length of a frame's output.
    pub fn n_vertices(&self) -> usize {
        self.binding.n_vertices()
    }
    pub fn timings(&self) -> DeformerTimings {
        self.timings
    }
    /// The rig underneath, when the mesh is skinned in process.
    pub fn rig(&self) -> Option<&Rig> {
        self.rig.as_ref()
    }
    /// The coupled cage, when the deformer has one: its vertex and
    /// triangle counts ([`CoupledRig::n_cage_vertices`],
    /// [`CoupledRig::n_cage_triangles`]), MaxVol rows
    /// ([`CoupledRig::maxvol_rows`]), the condition number of the square
    /// system ([`CoupledRig::condition`]) and `Φ`'s bytes ([`CoupledRig::phi_bytes`]).
    pub fn cage(&self) -> Option<&CoupledRig> {
        self.cage.as_ref()
    }
    /// G¹-flexible spline skinning done by this deformer's frames so far
    /// (zero unless [`Rig::flexible_iterations`] is positive).
    pub fn flexible_stats(&self) -> FlexibleStats {
        FlexibleStats {
            iterations: self.flexible_iterations.load(Ordering::Relaxed),
            poses: self.flexible_poses.load(Ordering::Relaxed),
        }
    }
}

/// The rig's layers that need the mesh: a centres-of-rotation skin gets its
/// centres (Eq. 5 on the projection pose, fan-triangulated) unless it has
/// them, and a cage becomes the coupled rig (with the rig's skeleton and
/// skin, else alone).
fn rig_layers(
    mesh: &PolyMesh,
    points: &[[f64; 3]],
    rig: &mut Option<Rig>,
    cage: Option<&CageInput<'_>>,
) -> Result<Option<CoupledRig>> {
    let needs_triangles =
        cage.is_some() || rig.as_ref().is_some_and(|r| r.skin.method() == SkinningMethod::CentersOfRotation);
    if !needs_triangles {
        return Ok(None);
    }
    let triangles = crate::cage::fan_triangles(mesh);
    if let Some(r) = rig.as_mut()
        && r.skin.method() == SkinningMethod::CentersOfRotation
        && r.skin.centers_of_rotation().is_none()
    {
        let centers = CentersOfRotation::new(points, &triangles, r.skin.influences())?;
        r.skin = r.skin.clone().with_centers_of_rotation(centers.centers().to_vec())?;
    }
    let Some(cage) = cage else { return Ok(None) };
    let skinning = match rig.as_ref() {
        None => None,
        Some(r) => match &r.skeleton {
            Some(skeleton) => Some((skeleton, &r.skin)),
            None => {
                return Err(crate::cage::CageError::Missing {
                    what: "a cage coupled with a rig needs the rig's skeleton (Rig::skeleton)",
                }
                .into());
            }
        },
    };
    CoupledRig::new(cage.points, cage.triangles, points, &triangles, skinning, CageRevApproximation::default())
        .map(Some)
}

/// Refuses a rig whose sizes do not match the mesh (`n` points) or the curvenets.
fn check_rig(rig: &Rig, n: usize, curvenets: &[CurvenetInput<'_>]) -> Result<()> {
    let points = rig.skin.influences().n_points();
    if points != n {
        return Err(Error::CountMismatch { what: "skinned points (the rig's influences)", expected: n, got: points });
    }
    if rig.curvenets.len() != curvenets.len() {
        return Err(Error::CountMismatch {
            what: "curvenets of the rig",
            expected: curvenets.len(),
            got: rig.curvenets.len(),
        });
    }
    for (k, (spline, net)) in rig.curvenets.iter().zip(curvenets).enumerate() {
        if let Some(spline) = spline
            && spline.n_points() != net.pool.len()
        {
            let e = Error::CountMismatch {
                what: "spline-skinned control points",
                expected: net.pool.len(),
                got: spline.n_points(),
            };
            return Err(Error::Curvenet { curvenet: k as u32, source: Box::new(e) });
        }
    }
    Ok(())
}

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}
