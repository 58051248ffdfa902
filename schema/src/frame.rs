//! A frame's parts between the wire and core: [`AdjustmentSpec`] and
//! core's `Adjustment` both ways (exactly: a stage's quaternion rotate
//! travels as `orient`), the blend-shape mode. The frame itself is
//! declared once, as `wire::FrameRequest`; the service makes it core's
//! `curvenet_core::Frame` in one place (`server/src/service/frame.rs`,
//! `CoreFrame`).

use curvenet_core::{Adjustment, Rotate};

use crate::wire::{AdjustmentSpec, BlendShapeMode};

impl From<&AdjustmentSpec> for Adjustment {
    /// Absent fields are no change; `orient` (a quaternion) wins over
    /// `rotate` (Euler angles) when a caller that did not validate gives
    /// both (the service refuses that: `both_rotations`).
    fn from(a: &AdjustmentSpec) -> Self {
        let rotate = match a.orient {
            Some(q) => Rotate::Quaternion(q),
            None => Rotate::EulerXyz(a.rotate.unwrap_or([0.0; 3])),
        };
        let out = Adjustment::new(a.curvenet as usize, a.knot)
            .with_translate(a.translate.unwrap_or([0.0; 3]))
            .with_rotate(rotate)
            .with_scale(a.scale.unwrap_or([1.0; 3]))
            .with_tangent_translates(a.tangent_translates.clone());
        match a.attach_tangents {
            Some(attach) => out.with_attach_tangents(attach),
            None => out,
        }
    }
}

impl From<&Adjustment> for AdjustmentSpec {
    /// Every field given, the rotate in the form core holds it (Euler
    /// angles as `rotate`, a quaternion as `orient`): converted back with
    /// `Adjustment::from`, the same adjustment bit for bit.
    fn from(a: &Adjustment) -> Self {
        let (rotate, orient) = match a.rotate {
            Rotate::EulerXyz(e) => (Some(e), None),
            Rotate::Quaternion(q) => (None, Some(q)),
        };
        AdjustmentSpec {
            curvenet: a.curvenet as u32,
            knot: a.knot,
            translate: Some(a.translate),
            rotate,
            orient,
            scale: Some(a.scale),
            attach_tangents: Some(a.attach_tangents),
            tangent_translates: a.tangent_translates.clone(),
        }
    }
}

impl From<BlendShapeMode> for curvenet_core::BlendShapeMode {
    fn from(mode: BlendShapeMode) -> Self {
        match mode {
            BlendShapeMode::After => curvenet_core::BlendShapeMode::After,
            BlendShapeMode::Before => curvenet_core::BlendShapeMode::Before,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Core's adjustment on the wire and back is the same adjustment, for
    /// both forms of rotate; a sparse spec's absent fields are no change.
    #[test]
    fn adjustments_go_to_the_wire_and_back_unchanged() {
        let euler = Adjustment::new(1, 7)
            .with_translate([0.1, -2.0, 3.5])
            .with_rotate(Rotate::EulerXyz([10.0, -35.0, 70.0]))
            .with_scale([1.0, 0.5, 2.0])
            .with_attach_tangents(false)
            .with_tangent_translates(vec![[0.25, 0.0, -1.0]]);
        let quat = Adjustment::new(0, 3).with_rotate(Rotate::Quaternion([0.9, 0.1, -0.3, 0.2]));
        for a in [euler, quat] {
            let spec = AdjustmentSpec::from(&a);
            let back = Adjustment::from(&spec);
            assert_eq!(back, a);
        }
        let sparse: AdjustmentSpec = serde_json::from_str(r#"{"curvenet": 2, "knot": 5}"#).unwrap();
        assert!(Adjustment::from(&sparse).is_identity());
        assert!(Adjustment::from(&sparse).attach_tangents);
    }
}
