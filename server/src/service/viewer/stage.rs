//! The stages opened in the viewer (`curvenet serve --open-stage STAGE`):
//! what to bind, and how to read each frame. A leaf of the service: the
//! application state holds the stages (`AppState::open_in_viewer`), so
//! this file names nothing of the service above it.

use std::sync::{Arc, Mutex};

use curvenet_schema::wire::{BindingRequest, FrameRequest};

use super::adjust::StageAdjustment;

/// Reads frame `k` of a stage opened in the viewer (the stage's k-th time
/// code) as the one frame type: posed pools, the rest pose, blend-shape
/// weights, the rig's and cage's edits and the stage's Curvenet
/// Adjustments at that time (a prim's `xformOp:orient` as `orient`, so the
/// adjustment is the bake's bit for bit). A reader that fails names the
/// frame and the prim.
pub type FrameSource = Arc<dyn Fn(usize) -> Result<FrameRequest, String> + Send + Sync>;

/// A deformed mesh of a stage opened in the viewer (`curvenet serve
/// --open-stage STAGE`): what to bind, and how to read each frame.
pub struct ViewerStage {
    /// The stage's path, as given.
    pub stage: String,
    /// The mesh prim.
    pub mesh: String,
    /// The curvenet prims deforming it, in binding order.
    pub curvenets: Vec<String>,
    /// The frames' time codes, in order.
    pub times: Vec<f64>,
    /// The binding of the mesh to its curvenets.
    pub binding: BindingRequest,
    /// Frame `k` (an index into `times`).
    pub frame: FrameSource,
    /// The stage's `CurvenetAdjustment` prims (what an export keys among).
    pub adjustments: Vec<StageAdjustment>,
    /// The binding id once bound (to skip re-hashing the request per frame).
    bound: Mutex<Option<String>>,
}

impl ViewerStage {
    pub fn new(
        stage: String,
        mesh: String,
        curvenets: Vec<String>,
        times: Vec<f64>,
        binding: BindingRequest,
        frame: FrameSource,
    ) -> Self {
        Self { stage, mesh, curvenets, times, binding, frame, adjustments: Vec::new(), bound: Mutex::new(None) }
    }

    /// The stage's `CurvenetAdjustment` prims (their values per frame come
    /// with the frames).
    pub fn with_adjustments(mut self, adjustments: Vec<StageAdjustment>) -> Self {
        self.adjustments = adjustments;
        self
    }

    /// The id of the stage's binding, once it was bound.
    pub(crate) fn bound(&self) -> Option<String> {
        self.bound.lock().unwrap_or_else(|e| e.into_inner()).clone()
    }

    /// Remembers the id of the stage's binding.
    pub(crate) fn set_bound(&self, id: String) {
        *self.bound.lock().unwrap_or_else(|e| e.into_inner()) = Some(id);
    }
}
