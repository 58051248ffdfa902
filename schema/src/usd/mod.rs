//! The USD encoding of the contract (schema/README.md): reading a composed
//! stage into plain data.
//!
//! ```no_run
//! let stage = curvenet_schema::usd::Stage::open("fixtures/grid/grid.usda")?;
//! for mesh in stage.deformed_meshes()? {
//!     let rest = stage.rest_points(&mesh, Some(2.0))?;
//!     for path in &mesh.curvenets {
//!         let net = stage.curvenet(path)?;
//!         let posed = stage.posed_pool(&net, Some(2.0))?;
//!         # let _ = (&rest, posed);
//!     }
//! }
//! # Ok::<(), curvenet_schema::usd::UsdError>(())
//! ```

mod adjust;
mod adjust_layer;
mod cage;
mod confine;
mod curvenet_layer;
mod error;
mod read;
mod skel;
mod value;
mod write;
pub use write::{
    LayerFormat, PointsOverrides, PrimPoints, ReadOverridesError, WriteError, decode_points_overrides,
    encode_points_overrides, read_points_overrides, write_points_overrides,
};

/// The attribute names of a `CurvenetAdjustment` prim.
pub mod adjustment_attributes {
    pub use super::adjust::{ATTACH, KNOT, OP_ORDER, ORIENT, ROTATE_XYZ, SCALE, TANGENT_TRANSLATES, TRANSLATE};
}
pub use adjust::ADJUSTMENT_TYPE;
pub use adjust_layer::{AdjustmentLayer, AdjustmentOver, AdjustmentRotate, encode_adjustment_layer};
pub use cage::{CAGE_REL, POSED_CAGE_OFFSETS};
pub use curvenet_layer::{CurvenetLayer, encode_curvenet_layer, write_curvenet_layer};
pub use error::UsdError;
pub use read::Stage;
pub use skel::{
    BLEND_SHAPE_ORDER, BlendShapeOrder, CURVENET_JOINT_INDICES, CURVENET_JOINT_WEIGHTS, CURVENET_SKINNING,
    CURVENET_SKINNING_METHOD, CurvenetSkinning, CurvenetSkinningMethod, SkinRig,
};
