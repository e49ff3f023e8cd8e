//! The one-way march in single precision, for many sources whose recordings are kept in single
//! precision anyway (the element fields of a basis).
//!
//! The plan's own operators (propagators, screens, interfaces) rounded to single precision, the
//! same steps in the same order as [`HasPlan::propagate`]; the FFTs then run twice the SIMD lanes
//! over half the bytes. Each operation rounds to ~6e-8 and the errors add up over the steps: a
//! few 1e-6 of the peak after about a hundred (tested against the double-precision march), far
//! below any MR image's noise.

use super::interface::Interface;
use super::march::Window;
use super::HasPlan;
use crate::physics::fft::Fft2;
use num_complex::{Complex32 as C32, Complex64 as C64};
use std::collections::HashMap;
use std::sync::Arc;

/// A plan's steps up to one plane, in single precision ([`HasPlan::single_precision`]).
pub struct SinglePlan {
    fft: Fft2<f32>,
    steps: Vec<SingleStep>,
}

struct SingleStep {
    interface: Option<Interface<f32>>,
    propagator: Arc<Vec<C32>>,
    screen: Arc<Vec<C32>>,
}

/// `v` rounded to single precision.
pub(crate) fn single(v: &[C64]) -> Vec<C32> {
    v.iter().map(|c| C32::new(c.re as f32, c.im as f32)).collect()
}

impl HasPlan {
    /// The plan's steps to plane `last` in single precision, or `None` where its march to that
    /// plane is not one-way (a reverberating layer begins at or before it). Operators shared
    /// between steps stay shared.
    pub fn single_precision(&self, last: usize) -> Option<SinglePlan> {
        let steps = self.one_way_steps(last)?;
        let mut copies: HashMap<usize, Arc<Vec<C32>>> = HashMap::new();
        let mut copy = |a: &Arc<Vec<C64>>| copies.entry(Arc::as_ptr(a) as usize).or_insert_with(|| Arc::new(single(a))).clone();
        let steps = steps
            .iter()
            .map(|s| SingleStep {
                interface: s.interface.as_ref().map(|i| i.single(&mut copy)),
                propagator: copy(&s.propagator),
                screen: copy(&s.screen),
            })
            .collect();
        Some(SinglePlan { fft: Fft2::new(self.grid.nx, self.grid.ny), steps })
    }

    /// About the bytes [`HasPlan::single_precision`] holds for plane `last` (each distinct
    /// propagator and screen once, and every interface as a full plane, 8 bytes per sample), or
    /// `None` where it is refused.
    pub fn single_precision_bytes(&self, last: usize) -> Option<u64> {
        let steps = self.one_way_steps(last)?;
        let arrays: std::collections::HashSet<usize> =
            steps.iter().flat_map(|s| [Arc::as_ptr(&s.propagator) as usize, Arc::as_ptr(&s.screen) as usize]).collect();
        let planes = arrays.len() + steps.iter().filter(|s| s.interface.is_some()).count();
        Some((planes * self.grid.lateral_len()) as u64 * 8)
    }

    /// The steps a march to plane `last` takes (plane `last` is recorded on arrival: its
    /// interface is not crossed, nor its slab stepped), where that march is one-way.
    fn one_way_steps(&self, last: usize) -> Option<&[super::Step]> {
        (last < self.grid.nz && !self.zone.is_some_and(|z| z.first <= last)).then(|| &self.steps[..last])
    }
}

impl SinglePlan {
    /// Marches each source (the field on plane 0) and keeps `window` (row-major plane, row,
    /// column), as [`HasPlan::propagate_batch`] does with a [`super::RecordSpec`] asking for that
    /// window alone (and spread over the pool as it does). `window` must end at or before the
    /// plan's last plane.
    pub fn window_batch(&self, sources: &[Vec<C64>], window: &Window) -> Vec<Vec<C32>> {
        use rayon::prelude::*;
        if super::in_sequence(self.fft.nx * self.fft.ny) {
            let mut out = Vec::with_capacity(sources.len());
            super::march::in_pool(|| out = sources.iter().map(|s| self.window(s, window, true)).collect());
            return out;
        }
        sources.par_iter().map(|s| self.window(s, window, false)).collect()
    }

    fn window(&self, source: &[C64], window: &Window, parallel: bool) -> Vec<C32> {
        let nx = self.fft.nx;
        let mut field = single(source);
        let mut ws = self.fft.workspace(parallel);
        let zero = C32::new(0.0, 0.0);
        let (mut reflected, mut work) = (vec![zero; field.len()], vec![zero; field.len()]);
        let mut out = Vec::with_capacity(window.len());
        for n in 0..window.planes.end {
            if n > 0 {
                let st = &self.steps[n - 1];
                self.fft.filter(&mut field, &mut ws, None, &st.propagator, Some(&st.screen));
            }
            if window.planes.contains(&n) {
                for r in window.rows.clone() {
                    out.extend_from_slice(&field[r * nx + window.cols.start..r * nx + window.cols.end]);
                }
            }
            if let Some(interface) = self.steps.get(n).and_then(|s| s.interface.as_ref()) {
                interface.reflect(&self.fft, &field, &mut reflected, &mut work, &mut ws);
                field.iter_mut().zip(&reflected).for_each(|(f, r)| *f += r);
            }
        }
        out
    }
}
