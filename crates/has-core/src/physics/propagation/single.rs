//! Marches in single precision, for many sources whose recordings are kept in single precision
//! anyway (the element fields of a basis).
//!
//! The plan's own operators (propagators, screens, interfaces) rounded to single precision, the
//! same steps in the same order as [`HasPlan::propagate`], the reverberation's round trips
//! included; the FFTs then run twice the SIMD lanes over half the bytes. Each operation rounds to
//! ~6e-8 and the errors add up over the steps: a few 1e-6 of the peak after a few hundred
//! (tested against the double-precision march), far below any MR image's noise.

use super::interface::Interface;
use super::march::{march, Operators, RoundTrips, StepOperators, Window};
use super::{HasPlan, RecordSpec, Zone};
use crate::physics::fft::Fft2;
use crate::physics::grid::Grid;
use crate::physics::medium::SliceProperties;
use num_complex::{Complex32 as C32, Complex64 as C64};
use std::collections::HashMap;
use std::sync::Arc;

/// A plan's steps up to one plane, in single precision ([`HasPlan::single_precision`]).
pub struct SinglePlan {
    plan: HasPlan,
    fft: Fft2<f32>,
    steps: Vec<SingleStep>,
}

struct SingleStep {
    interface: Option<Arc<Interface<f32>>>,
    propagator: Arc<Vec<C32>>,
    screen: Arc<Vec<C32>>,
    /// The second reference medium's propagator and screen (`references.rs`).
    split: Option<[Arc<Vec<C32>>; 2]>,
    /// The SV field's propagator and screen (`elastic.rs`).
    shear: Option<[Arc<Vec<C32>>; 2]>,
}

/// `v` rounded to single precision.
pub(crate) fn single(v: &[C64]) -> Vec<C32> {
    v.iter().map(|c| C32::new(c.re as f32, c.im as f32)).collect()
}

impl HasPlan {
    /// The plan's steps that a march recording up to plane `last` takes, in single precision
    /// (through the reverberation zone and its far interface where the march reaches it), or
    /// `None` where `last` is beyond the grid. Operators shared between steps stay shared.
    pub fn single_precision(&self, last: usize) -> Option<SinglePlan> {
        let steps = self.steps_to(last)?;
        let mut copies: HashMap<usize, Arc<Vec<C32>>> = HashMap::new();
        let mut copy = |a: &Arc<Vec<C64>>| copies.entry(Arc::as_ptr(a) as usize).or_insert_with(|| Arc::new(single(a))).clone();
        let mut interfaces: HashMap<usize, Arc<Interface<f32>>> = HashMap::new();
        let steps = steps
            .iter()
            .map(|s| SingleStep {
                interface: s
                    .interface
                    .as_ref()
                    .map(|i| interfaces.entry(Arc::as_ptr(i) as usize).or_insert_with(|| Arc::new(i.single(&mut copy))).clone()),
                propagator: copy(&s.propagator),
                screen: copy(&s.screen),
                split: s.split.as_ref().map(|p| [copy(&p.propagator), copy(&p.screen)]),
                shear: s.shear.as_ref().map(|(p, q)| [copy(p), copy(q)]),
            })
            .collect();
        Some(SinglePlan { plan: self.clone(), fft: Fft2::new(self.grid.nx, self.grid.ny), steps })
    }

    /// About the bytes [`HasPlan::single_precision`] holds for plane `last` (each distinct
    /// propagator, screen and interface array once, each as a full plane of 8 bytes per sample:
    /// a pointwise interface's map, each spectral pair's coefficient, the pairs' pixel lists), or
    /// `None` where it is refused.
    pub fn single_precision_bytes(&self, last: usize) -> Option<u64> {
        let steps = self.steps_to(last)?;
        let arrays: std::collections::HashSet<usize> = steps
            .iter()
            .flat_map(|s| {
                let split = s.split.as_ref().map(|p| [Arc::as_ptr(&p.propagator) as usize, Arc::as_ptr(&p.screen) as usize]);
                let shear = s.shear.as_ref().map(|(p, q)| [Arc::as_ptr(p) as usize, Arc::as_ptr(q) as usize]);
                [Arc::as_ptr(&s.propagator) as usize, Arc::as_ptr(&s.screen) as usize]
                    .into_iter()
                    .chain(split.into_iter().flatten())
                    .chain(shear.into_iter().flatten())
            })
            .chain(steps.iter().filter_map(|s| s.interface.as_deref()).flat_map(Interface::planes))
            .collect();
        Some((arrays.len() * self.grid.lateral_len()) as u64 * 8)
    }

    /// The steps a march recording up to plane `last` takes: to `last` (recorded on arrival: its
    /// interface is not crossed, nor its slab stepped), and where the reverberation zone begins at
    /// or before it, through the zone's last interface.
    fn steps_to(&self, last: usize) -> Option<&[super::Step]> {
        let zone_end = self.zone.filter(|z| z.first <= last).map_or(0, |z| z.last + 1);
        (last < self.grid.nz).then(|| &self.steps[..last.max(zone_end).min(self.steps.len())])
    }
}

impl Operators<f32> for SinglePlan {
    fn grid(&self) -> &Grid {
        &self.plan.grid
    }
    fn zone(&self) -> Option<Zone> {
        self.plan.zone
    }
    fn fft(&self) -> &Fft2<f32> {
        &self.fft
    }
    fn interface(&self, n: usize) -> Option<&Interface<f32>> {
        self.steps.get(n)?.interface.as_deref()
    }
    fn step(&self, s: usize) -> StepOperators<'_, f32> {
        let st = &self.steps[s];
        fn pair(f: &[Arc<Vec<C32>>; 2]) -> (&[C32], &[C32]) {
            (&f[0], &f[1])
        }
        ((&st.propagator, &st.screen), st.split.as_ref().map(pair), st.shear.as_ref().map(pair))
    }
    fn slab(&self, n: usize) -> &SliceProperties {
        self.plan.slab_properties(n)
    }
    fn source_medium(&self) -> &SliceProperties {
        &self.plan.source_medium
    }
    fn field_len(&self) -> usize {
        self.plan.field_len()
    }
}

impl SinglePlan {
    /// Marches each source (the field on plane 0) and keeps `window` (row-major plane, row,
    /// column), as [`HasPlan::propagate_batch`] does with a [`super::RecordSpec`] asking for that
    /// window alone (and spread over the pool as it does). `window` must end at or before the
    /// plan's last plane.
    pub fn window_batch(&self, sources: &[Vec<C64>], window: &Window) -> Vec<Vec<C32>> {
        use rayon::prelude::*;
        let spec = RecordSpec { window: Some(window.clone()), ..RecordSpec::default() };
        let one = |s: &Vec<C64>, parallel: bool| single(&march(self, single(s), &spec, parallel, RoundTrips::Fixed).0.window);
        if sources.len() == 1 || super::in_sequence(self.fft.nx * self.fft.ny) {
            let mut out = Vec::with_capacity(sources.len());
            super::march::in_pool(|| out = sources.iter().map(|s| one(s, true)).collect());
            return out;
        }
        sources.par_iter().map(|s| one(s, false)).collect()
    }
}
