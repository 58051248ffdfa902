//! One frame's input, declared once for every layer of core: the
//! [`crate::Deformer`] takes all of it (blend shapes, the rig's joint
//! transforms, the cage's edits); [`crate::Binding::deform`], the bare
//! curvenet layer underneath, takes the posed pools, the rest pose and the
//! adjustments, and refuses a frame that needs the layers above it. The
//! wire's frame (`curvenet_schema::wire::FrameRequest`) becomes this in
//! one place (`curvenet_schema::CoreFrame`).

use crate::adjust::Adjustment;
use crate::error::{Error, Result};
use crate::skinning::Mat4;

/// How blend shapes combine with the curvenet deformation.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum BlendShapeMode {
    /// Offsets mapped by each vertex's deformation gradient after the
    /// deformation (paper §5, the default): sculpts move with the surface.
    #[default]
    After,
    /// Offsets added to the rest pose before the deformation (UsdSkel's order).
    Before,
}

/// One frame's input.
#[derive(Debug, Clone, Copy, Default)]
pub struct Frame<'a> {
    /// The posed pool of each curvenet (absolute positions), `None` for a
    /// curvenet not articulated this frame (its knots track the rest pose);
    /// an empty slice: no curvenet is articulated.
    pub posed: &'a [Option<&'a [[f64; 3]]>],
    /// The mesh's rest pose this frame (skinning or cloth output); `None`:
    /// the projection pose.
    pub rest: Option<&'a [[f64; 3]]>,
    /// One weight per blend shape; `None` (or all zero): no blend shapes.
    pub blend_shape_weights: Option<&'a [f64]>,
    pub blend_shape_mode: BlendShapeMode,
    /// Curvenet Adjustments on top of whatever poses the curvenets
    /// ([`crate::adjust`]); empty: none.
    pub adjustments: &'a [Adjustment],
    /// The frame's skinning transforms (one per joint of the deformer's
    /// [`crate::Rig`], in the mesh's space), for a deformer with a rig; `None`: no
    /// skinning this frame. With them, `rest` (or the projection pose) is
    /// the mesh's points before skinning: blend shapes in the `before` mode
    /// are added to it, the skin then gives the frame's rest pose; and every
    /// spline-skinned curvenet's posed pool is its spline skinning (in place
    /// of its entry of `posed`).
    pub joint_transforms: Option<&'a [Mat4]>,
    /// Rest-cage edits `C` this frame (one point per cage vertex, the
    /// mesh's space), for a deformer with a cage ([`crate::DeformerInput::cage`]);
    /// `None`: the cage at bind. The mesh's rest pose follows as `M =
    /// base + Φ(C − C₀)` (`base`: the points above, sculpted), the joints by
    /// SkelUp.
    pub rest_cage: Option<&'a [[f64; 3]]>,
    /// Posed-cage edits `∂C′` this frame (one offset per cage vertex, the
    /// skinned points' space), taken back to the rest cage by CageRev.
    pub posed_cage_offsets: Option<&'a [[f64; 3]]>,
}

impl Frame<'_> {
    /// Refuses a frame that needs the deformer's layers above the binding
    /// (blend shapes with a weight other than zero, skinning, a cage): a
    /// bare [`crate::Binding`] has none of them, and would ignore them.
    pub(crate) fn check_binding_only(&self) -> Result<()> {
        let unsupported = |what| Err(Error::Unsupported { what });
        if self.blend_shape_weights.is_some_and(|w| w.iter().any(|&x| x != 0.0)) {
            return unsupported("blend_shape_weights on a Binding (it has no blend shapes; deform through a Deformer)");
        }
        if self.joint_transforms.is_some() {
            return unsupported("joint_transforms on a Binding (it has no rig; deform through a Deformer)");
        }
        if self.rest_cage.is_some() || self.posed_cage_offsets.is_some() {
            return unsupported("cage edits on a Binding (it has no cage; deform through a Deformer)");
        }
        Ok(())
    }
}
