//! The stages opened in the viewer (`curvenet serve --open-stage STAGE`):
//! what to bind, and how to read each frame. A leaf of the service: the
//! application state holds the stages (`AppState::open_in_viewer`), so
//! this file names nothing of the service above it.

use std::sync::{Arc, Mutex};

use curvenet_core::Adjustment;
use curvenet_schema::wire::{BindingRequest, FrameRequest};

use super::adjust::StageAdjustment;

/// Reads frame `k` of a stage opened in the viewer (the stage's k-th time
/// code): posed pools, the rest pose, blend-shape weights and the stage's
/// Curvenet Adjustments at that time. A reader that fails names the frame
/// and the prim.
pub type FrameSource = Arc<dyn Fn(usize) -> Result<StageFrame, String> + Send + Sync>;

/// A frame of a stage opened in the viewer, as read from the stage.
#[derive(Debug, Clone, Default)]
pub struct StageFrame {
    pub request: FrameRequest,
    /// The stage's Curvenet Adjustments at this frame (core's: a rotate
    /// may be a quaternion), applied after the request's own.
    pub adjustments: Vec<Adjustment>,
}

impl From<FrameRequest> for StageFrame {
    fn from(request: FrameRequest) -> Self {
        Self { request, adjustments: Vec::new() }
    }
}

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
