//! curvenet-schema: the data contract, documented once in `schema/README.md`
//! and declared in `schema/curvenet.usda`.
//!
//! - [`usd`]: reading a composed USD stage that follows the contract into
//!   plain data ([`MeshData`], [`CurvenetData`], [`BlendShapeData`], [`CageData`]) that the
//!   core consumes, and (later) writing bake output.
//!
//! USD stages are not `Send` (the openusd crate holds `Rc`s): open a stage in
//! the thread that reads it, and hand the plain data across threads.

pub mod data;
pub mod frame;
pub mod usd;
pub mod wire;

pub use data::{
    AdjustmentData, BlendShapeData, CageData, CageFrame, CageSample, CurvenetData, InbetweenData, MeshData,
    deformer_input,
};
