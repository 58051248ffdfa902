//! The parts of a frame timed on their own, right after each timed frame:
//! the curvenet part (posed samples, scaled frames, gradients, as
//! `Binding::deform` runs it) and the memory-bandwidth reference (a copy of
//! the factor's size there and back).

use std::hint::black_box;

use curvenet_core::{CurvenetLayout, Mat3};
use curvenet_core::{ScaledFrame, constraint_gradients_into, deformation_gradients_into, scaled_frames_into};

use super::measure::{Lap, Stopwatch};

/// Copying `len` f64 there and back (two passes): the memory-bandwidth reference.
pub(super) struct CopyReference {
    a: Vec<f64>,
    b: Vec<f64>,
}

impl CopyReference {
    pub(super) fn new(len: usize) -> Self {
        let len = len.max(1);
        let a: Vec<f64> = (0..len).map(|i| i as f64 * 0.5 + 1.0).collect();
        let b = a.clone(); // both touched
        Self { a, b }
    }

    pub(super) fn time(&mut self) -> Lap {
        let clock = Stopwatch::start();
        black_box(&mut self.b).copy_from_slice(black_box(&self.a));
        black_box(&mut self.a).copy_from_slice(black_box(&self.b));
        black_box((&self.a, &self.b));
        clock.stop()
    }
}

/// The curvenet part of a frame, as `Binding::deform` runs it: posed
/// samples, scaled frames, per-side deformation gradients, per-slot gradients.
pub(super) struct CurvenetEval {
    samples: Vec<Vec<[f64; 3]>>,
    frames: Vec<Vec<[ScaledFrame; 2]>>,
    gradients: Vec<Vec<[Mat3; 2]>>,
    slots: Vec<Vec<Mat3>>,
}

impl CurvenetEval {
    pub(super) fn new(layouts: &[CurvenetLayout]) -> Self {
        Self {
            samples: layouts.iter().map(|l| vec![[0.0; 3]; l.n_samples()]).collect(),
            frames: layouts.iter().map(|l| vec![[ScaledFrame::default(); 2]; l.n_segments()]).collect(),
            gradients: layouts.iter().map(|l| vec![[[[0.0; 3]; 3]; 2]; l.n_segments()]).collect(),
            slots: layouts.iter().map(|l| vec![[[0.0; 3]; 3]; l.constraints().len()]).collect(),
        }
    }

    pub(super) fn time(&mut self, layouts: &[CurvenetLayout], pools: &[Vec<[f64; 3]>]) -> curvenet_core::Result<Lap> {
        let clock = Stopwatch::start();
        for (k, layout) in layouts.iter().enumerate() {
            layout.sampling().samples_into(&pools[k], &mut self.samples[k])?;
            scaled_frames_into(layout, &self.samples[k], &mut self.frames[k])?;
            deformation_gradients_into(layout, layout.neutral_frames(), &self.frames[k], &mut self.gradients[k])?;
            constraint_gradients_into(layout.constraints(), &self.gradients[k], &mut self.slots[k])?;
        }
        black_box(&self.slots);
        Ok(clock.stop())
    }
}
