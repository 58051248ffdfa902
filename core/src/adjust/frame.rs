//! The adjuster inside a binding's frame (the orientation plans are built
//! with the binding, `binding/knots.rs`): the per-frame step [`crate::Binding::deform`] runs between
//! posing the curvenet and sampling it.

use super::apply::{Adjustment, apply_adjustment, check_adjustment};
use super::orientations::OrientationPlan;
use crate::binding::Binding;
use crate::binding::knots::triangle_normal;
use crate::curvenet::{CurvenetLayout, Mat3};
use crate::error::{Error, Result};

/// A curvenet's control-point pool and its samples.
type PoolAndSamples = (Vec<[f64; 3]>, Vec<[f64; 3]>);

/// No adjustment claims this knot (see [`Binding::check_adjustments_with`]).
pub(crate) const UNCLAIMED: u32 = u32::MAX;

impl Binding {
    /// The knot-orientation plan of curvenet `k`.
    pub fn orientation_plan(&self, k: usize) -> &OrientationPlan {
        &self.orientation_plans[k]
    }

    /// The surface normal at control point `p` of curvenet `k`: the normal
    /// of the triangle it is bound to, in the rest pose `rest` (else the
    /// projection pose).
    pub(crate) fn knot_normal(&self, k: usize, p: u32, rest: Option<&[[f64; 3]]>) -> [f64; 3] {
        let tri = self.knots[k][p as usize].tri;
        match rest {
            Some(rest) => triangle_normal(&self.surface, tri, rest),
            None => triangle_normal(&self.surface, tri, &self.surface.points),
        }
    }

    /// Every knot's orientation of curvenet `k` in a frame (the issue's
    /// `orientations`): `(pool index, row-major rotation)` per knot, in
    /// increasing pool order, for the posed pool `posed`, else the pool
    /// tracked to `rest`, else the neutral pool — the pose the frame's
    /// adjustments are expressed in. Allocates; errors name the element.
    pub fn knot_orientations(
        &self,
        k: usize,
        posed: Option<&[[f64; 3]]>,
        rest: Option<&[[f64; 3]]>,
    ) -> Result<Vec<(u32, Mat3)>> {
        let layout = self.layout_checked(k)?;
        let (pool, samples) = self.pose_so_far(k, posed, rest)?;
        let mut out = vec![[[0.0; 3]; 3]; layout.sampling().n_knots()];
        self.orientation_plans[k].orientations_into(
            layout,
            &pool,
            &samples,
            |p| self.knot_normal(k, p, rest),
            &mut out,
        )?;
        Ok(out.into_iter().enumerate().map(|(i, m)| (layout.sampling().knot_point(i), m)).collect())
    }

    /// The control-point pool of curvenet `k` after `adjustments` (those
    /// naming curvenet `k`; all are checked), on top of the posed pool
    /// `posed`, else the pool tracked to `rest`, else the neutral pool: the
    /// pool [`Binding::deform`] samples. Allocates.
    pub fn adjusted_pool(
        &self,
        k: usize,
        posed: Option<&[[f64; 3]]>,
        rest: Option<&[[f64; 3]]>,
        adjustments: &[Adjustment],
    ) -> Result<Vec<[f64; 3]>> {
        let layout = self.layout_checked(k)?;
        self.check_adjustments(adjustments)?;
        let (pool, samples) = self.pose_so_far(k, posed, rest)?;
        let mut orientations = vec![[[0.0; 3]; 3]; layout.sampling().n_knots()];
        let mut out = pool.clone();
        self.adjust_pool_into(k, &pool, &samples, rest, adjustments, &mut orientations, &mut out)?;
        Ok(out)
    }

    /// Checks `adjustments` against the bound curvenets (see
    /// [`check_adjustment`]) and refuses two adjustments of one knot
    /// ([`Error::DuplicateAdjustment`]).
    pub fn check_adjustments(&self, adjustments: &[Adjustment]) -> Result<()> {
        let mut claimed: Vec<Vec<u32>> = self.layouts.iter().map(|l| vec![UNCLAIMED; l.sampling().n_knots()]).collect();
        self.check_adjustments_with(adjustments, &mut claimed)
    }

    /// [`Self::check_adjustments`] with a scratch table (`claimed[k][knot]`,
    /// all [`UNCLAIMED`]; left so). Allocation-free.
    pub(crate) fn check_adjustments_with(&self, adjustments: &[Adjustment], claimed: &mut [Vec<u32>]) -> Result<()> {
        let mut result = Ok(());
        let mut marked = 0;
        for (i, a) in adjustments.iter().enumerate() {
            match check_adjustment(i, a, &self.layouts, &self.orientation_plans) {
                Ok(knot) => {
                    let slot = &mut claimed[a.curvenet][knot];
                    if *slot != UNCLAIMED {
                        result = Err(Error::DuplicateAdjustment {
                            curvenet: a.curvenet,
                            point: a.knot,
                            adjustments: [*slot as usize, i],
                        });
                        break;
                    }
                    *slot = i as u32;
                    marked = i + 1;
                }
                Err(e) => {
                    result = Err(e);
                    break;
                }
            }
        }
        for a in &adjustments[..marked] {
            if let Some(knot) = self.layouts[a.curvenet].sampling().knot_sample(a.knot as usize) {
                claimed[a.curvenet][knot as usize] = UNCLAIMED;
            }
        }
        result
    }

    /// The frame step: the orientations of curvenet `k` posed at `pool`
    /// (with samples `samples`) into `orientations`, then `pool` with the
    /// adjustments of curvenet `k` into `out`. The adjustments must have
    /// been checked. Allocation-free.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn adjust_pool_into(
        &self,
        k: usize,
        pool: &[[f64; 3]],
        samples: &[[f64; 3]],
        rest: Option<&[[f64; 3]]>,
        adjustments: &[Adjustment],
        orientations: &mut [Mat3],
        out: &mut [[f64; 3]],
    ) -> Result<()> {
        let layout = &self.layouts[k];
        let plan = &self.orientation_plans[k];
        let sampling = layout.sampling();
        let adjusted = |q: usize| {
            adjustments.iter().any(|a| a.curvenet == k && sampling.knot_sample(a.knot as usize) == Some(q as u32))
        };
        plan.some_orientations_into(layout, pool, samples, |p| self.knot_normal(k, p, rest), adjusted, orientations)?;
        if out.len() != pool.len() {
            return Err(Error::CountMismatch { what: "adjusted pool buffer", expected: pool.len(), got: out.len() });
        }
        out.copy_from_slice(pool);
        for a in adjustments.iter().filter(|a| a.curvenet == k) {
            let knot = layout.sampling().knot_sample(a.knot as usize).ok_or_else(|| Error::Internal {
                what: format!("adjustment of control point {} applied unchecked", a.knot),
            })? as usize;
            apply_adjustment(a, &orientations[knot], plan.knot_tangents(knot), out);
        }
        Ok(())
    }

    fn layout_checked(&self, k: usize) -> Result<&CurvenetLayout> {
        self.layouts.get(k).ok_or(Error::IndexOutOfRange {
            what: "knot orientation request",
            index: 0,
            target: "curvenet",
            value: u32::try_from(k).unwrap_or(u32::MAX),
            len: self.layouts.len(),
        })
    }

    /// The pool of curvenet `k` posed so far and its samples (allocating).
    fn pose_so_far(&self, k: usize, posed: Option<&[[f64; 3]]>, rest: Option<&[[f64; 3]]>) -> Result<PoolAndSamples> {
        let layout = &self.layouts[k];
        let pool = match (posed, rest) {
            (Some(pool), _) => pool.to_vec(),
            (None, Some(rest)) => {
                if rest.len() != self.n_vertices() {
                    return Err(Error::CountMismatch {
                        what: "rest-pose points",
                        expected: self.n_vertices(),
                        got: rest.len(),
                    });
                }
                crate::mesh::check_finite(rest, "rest-pose point")?;
                let mut tracked = vec![[0.0; 3]; layout.sampling().n_points()];
                self.tracked_pool_into(k, rest, &mut tracked)?;
                tracked
            }
            (None, None) => layout.neutral_pool().to_vec(),
        };
        if let Some(rest) = rest
            && rest.len() != self.n_vertices()
        {
            return Err(Error::CountMismatch {
                what: "rest-pose points",
                expected: self.n_vertices(),
                got: rest.len(),
            });
        }
        let samples = layout.sampling().samples(&pool)?;
        Ok((pool, samples))
    }
}
