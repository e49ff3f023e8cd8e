//! The transpose of a march: one sweep that gives, for weights on one plane, the source-plane
//! vector whose dot product with any source is the weighted sum of that source's recorded field.
//!
//! A march is a linear map `s ↦ M·s` from the source plane to the recorded planes, a product of
//! steps `P = screen · IFFT · propagator · FFT`, crossings `S·(I ± R)` (`S` the diagonal flux
//! normalisation of [`Interface::normalise_transmitted`]), recordings `C` (the diagonal
//! `sqrt(Z/Z_s)` that turns the marched field into pressure) and additions. Its transpose
//! `Mᵀ` is the product of the transposed factors in reverse order: `Pᵀ = IFFT · propagator · FFT
//! · screen` (the propagator depends on `kx² + ky²` only, which makes `IFFT · propagator · FFT`
//! symmetric), `Rᵀ` masks each material pair's pixels before its filter
//! ([`Interface::reflect_transposed`]), a face that converts shear takes the transpose of its
//! scattering of both fields (`elastic::cross_transposed`), and every wave the march adds,
//! reflects or keeps becomes
//! an adjoint wave that the transposed sweep collects. The control flow of a march with a fixed
//! number of round trips does not depend on the source, so the transposed sweeps follow the same
//! plane lists backwards. This is discrete reciprocity: `Mᵀ·δ` at a pixel is the field a point
//! source there sends back to the source plane in this model, and with it each element's
//! pressure at that pixel is one dot product (see [`crate::Simulation::element_responses`]).

use super::interface::Interface;
use super::march::{pressure_scale, Operators, RecordSpec, Wave};
use super::HasPlan;
use crate::error::{HasError, Result};
use crate::physics::fft::FftWorkspace;
use num_complex::Complex64 as C64;
use std::collections::BTreeMap;
use std::ops::Range;

/// Adjoint waves by plane: each kept for the reflection at its plane, which reads a pointwise
/// interface's pixels only (so only those are kept; through a head a few percent of the plane).
type Adjoints = BTreeMap<usize, Wave<f64>>;

/// Buffers and the weighted plane of one transposed march.
struct Transposer<'a> {
    plan: &'a HasPlan,
    ws: FftWorkspace,
    work: Vec<C64>,
    reflected: Vec<C64>,
    incident: Vec<C64>,
    /// A kept adjoint written out on the whole plane.
    unpacked: Vec<C64>,
    plane: usize,
    weights: &'a [C64],
}

impl<'a> Transposer<'a> {
    /// A zero adjoint of a marched field (`[ψ | s]` where the plan carries shear).
    fn zero(&self) -> Vec<C64> {
        vec![C64::new(0.0, 0.0); self.plan.field_len()]
    }

    fn interface(&self, n: usize) -> Option<&'a Interface> {
        let plan: &'a HasPlan = self.plan;
        plan.steps.get(n).and_then(|s| s.interface.as_deref())
    }

    /// The adjoint on plane `n` as the reflection there reads it: on a pointwise interface's
    /// pixels, or the whole plane.
    fn keep(&self, n: usize, adjoint: &[C64]) -> Wave<f64> {
        let interface = self.interface(n);
        // Walls that convert keep the SV field's reflected wave at their treads too.
        let kept = interface.and_then(Interface::walls).and_then(|w| w.kept.clone());
        match interface.and_then(Interface::pointwise) {
            Some((pixels, ..)) => {
                let pixels = kept.unwrap_or_else(|| pixels.clone());
                let values = pixels.iter().map(|&i| adjoint[i as usize]).collect();
                Wave::Sparse { pixels, values }
            }
            None => Wave::Dense(adjoint.to_vec()),
        }
    }

    /// The transpose of recording plane `n` (`p = C·ψ`): the weights, scaled by `C`, join the
    /// adjoint there.
    fn record(&self, n: usize, adjoint: &mut [C64]) {
        if n == self.plane {
            let (before, source) = (self.plan.before(n), self.plan.source_medium());
            let same = std::ptr::eq(before, source);
            adjoint.iter_mut().zip(self.weights).enumerate().for_each(|(i, (a, w))| {
                *a += if same { *w } else { w * pressure_scale(before, source, i) };
            });
        }
    }

    /// The transpose of stepping through slab `s`: screen first, then the propagator.
    fn step(&mut self, s: usize, adjoint: &mut [C64]) {
        super::march::step(&self.plan.fft, adjoint, (&mut self.ws, &mut self.work), self.plan.steps[s].operators(), true);
    }

    /// The transpose of crossing plane `n` in direction `sign` (`f ← S·(f + sign·R·f)`, the
    /// reflected wave `sign·R_φ·f` kept with adjoint `kept`, `R_φ` with the faces' phases):
    /// `a ← S·a`, then `a ← a + sign·(Rᵀ·a + R_φᵀ·kept)`.
    fn cross(&mut self, n: usize, adjoint: &mut [C64], sign: f64, kept: Option<&Wave<f64>>) {
        let Some(interface) = self.interface(n) else { return };
        if let Some(pairs) = interface.elastic() {
            if let Some(k) = kept {
                self.unpacked.resize(adjoint.len(), C64::new(0.0, 0.0));
                k.write_to(&mut self.unpacked);
            }
            let unpacked = kept.map(|_| &self.unpacked[..]);
            super::elastic::cross_transposed(pairs, &self.plan.fft, adjoint, sign, unpacked, &mut self.work, &mut self.ws);
            return;
        }
        if interface.walls().is_some() {
            if let Some(k) = kept {
                self.unpacked.resize(adjoint.len(), C64::new(0.0, 0.0));
                k.write_to(&mut self.unpacked);
            }
            let unpacked = kept.map(|_| &self.unpacked[..]);
            interface.cross_transposed_walls(&self.plan.fft, adjoint, sign, unpacked, &mut self.work, &mut self.ws);
            return;
        }
        // A face that converts no shear crosses ψ alone (`march::cross`): the SV field passes.
        let adjoint = &mut adjoint[..self.plan.grid.lateral_len()];
        interface.normalise_transmitted(adjoint, sign);
        if self.work.len() != adjoint.len() {
            self.work = vec![C64::new(0.0, 0.0); adjoint.len()];
        }
        self.incident.copy_from_slice(adjoint);
        let faces = interface.pointwise().is_some_and(|p| p.2.is_some());
        if let Some(k) = kept {
            if faces {
                // The kept wave carries the faces' phases, the transmitted one does not.
                self.unpacked.resize(adjoint.len(), C64::new(0.0, 0.0));
                k.write_to(&mut self.unpacked);
                interface.reflect_transposed(&self.plan.fft, &self.unpacked, &mut self.reflected, &mut self.work, &mut self.ws, Some(sign));
                adjoint.iter_mut().zip(&self.reflected).for_each(|(a, r)| *a += sign * r);
            } else {
                k.add_to(&mut self.incident, false);
            }
        }
        interface.reflect_transposed(&self.plan.fft, &self.incident, &mut self.reflected, &mut self.work, &mut self.ws, None);
        adjoint.iter_mut().zip(&self.reflected).for_each(|(a, r)| *a += sign * r);
    }

    /// The transpose of `Sweeper::forward` from `from` to `to` with sources on `sources`:
    /// `adjoint` holds on entry the adjoint of the field leaving `to`, on return that of the
    /// field entering `from`; `kept(n)` is the adjoint of the reflection kept at plane `n`.
    /// Returns the adjoints of the sources, by plane.
    fn forward<'k>(
        &mut self,
        adjoint: &mut [C64],
        from: usize,
        to: usize,
        entering: bool,
        sources: &[usize],
        kept: &dyn Fn(usize) -> Option<&'k Wave<f64>>,
    ) -> Adjoints {
        let mut out = Adjoints::new();
        for n in (from..=to).rev() {
            if sources.contains(&n) {
                out.insert(n, self.keep(n, adjoint));
            }
            if n > from || entering {
                self.cross(n, adjoint, 1.0, kept(n));
                self.record(n, adjoint);
            }
            if n > from {
                self.step(n - 1, adjoint);
            }
        }
        out
    }

    /// The transpose of `Sweeper::backward` of waves starting on `sources` (and `inject`) down
    /// to `bottom`: `leaving` is the adjoint of the wave leaving `bottom`, `emitted(m)` that of
    /// the forward wave reflected at `m`. Returns the adjoints of the sources (by plane) and of
    /// the injected wave.
    fn backward<'k>(
        &mut self,
        mut adjoint: Vec<C64>,
        sources: &[usize],
        bottom: usize,
        inject: Option<usize>,
        emitted: &dyn Fn(usize) -> Option<&'k Wave<f64>>,
    ) -> (Adjoints, Option<Vec<C64>>) {
        let mut out = Adjoints::new();
        let mut injected = None;
        let Some(top) = sources.iter().copied().chain(inject).max() else {
            return (out, injected);
        };
        for m in bottom..=top {
            if m > bottom {
                self.step(m - 1, &mut adjoint);
            }
            if inject == Some(m) {
                injected = Some(adjoint.clone());
            }
            let source_here = sources.contains(&m);
            if m < top || source_here {
                self.record(m, &mut adjoint);
            }
            if source_here {
                out.insert(m, self.keep(m, &adjoint));
            }
            if m < top {
                self.cross(m, &mut adjoint, -1.0, emitted(m));
            }
        }
        (out, injected)
    }
}

/// What one round trip of the reverberation consumed and produced (plane lists).
struct Trip {
    /// Planes of the backward waves it started from.
    inside: Vec<usize>,
    /// Planes of the forward waves its backward sweep reflected (`None`: none, the last trip).
    emitted: Option<Vec<usize>>,
}

impl HasPlan {
    /// The transpose of [`HasPlan::propagate`] for one recorded plane: for `weights` on `plane`
    /// (row-major `(ny, nx)`), the source-plane vector `m` with
    /// `Σ weights · propagate(s).planes[plane] = Σ m · s` for every source `s` (no complex
    /// conjugate: a transpose, not an adjoint), `reflections` as in [`RecordSpec`]. With a single
    /// pixel's weight, `m` is the field a point source there sends back to the source plane in this
    /// model (reciprocity). Costs one march.
    pub fn transposed(&self, plane: usize, weights: &[C64], reflections: bool) -> Result<Vec<C64>> {
        let g = &self.grid;
        if plane >= g.nz {
            return Err(HasError::invalid("plane", format!("plane {plane} is beyond the grid ({} planes)", g.nz)));
        }
        if weights.len() != g.lateral_len() {
            return Err(HasError::invalid("weights", format!("has {} samples, grid has {}", weights.len(), g.lateral_len())));
        }
        if weights.iter().any(|v| !v.re.is_finite() || !v.im.is_finite()) {
            return Err(HasError::invalid("weights", "contains NaN or infinite values"));
        }
        let mut out = Vec::new();
        super::march::in_pool(|| out = self.transposed_here(plane, weights, reflections));
        // The source is a compressional field: the transpose of setting its SV half to zero.
        out.truncate(g.lateral_len());
        Ok(out)
    }

    fn transposed_here(&self, plane: usize, weights: &[C64], reflections: bool) -> Vec<C64> {
        let spec = RecordSpec { planes: vec![plane], reflections, ..RecordSpec::default() };
        let last = spec.last_plane(self.grid.nz);
        let zone = self.zone.filter(|z| z.first <= last);
        let in_zone = |n: usize| zone.is_some_and(|z| (z.first..=z.last).contains(&n));
        let keep = |n: usize| reflections || in_zone(n);
        let reflecting = |n: usize| self.steps.get(n).is_some_and(|s| s.interface.is_some());
        // The planes of the reflections a forward sweep keeps, and of the forward waves a
        // backward sweep from `top` reflects inside `emit`.
        let kept_by = |from: usize, to: usize, entering: bool| -> Vec<usize> {
            (from..=to).filter(|&n| (n > from || entering) && reflecting(n) && keep(n)).collect()
        };
        let emitted_by = |bottom: usize, top: usize, emit: Range<usize>| -> Vec<usize> {
            (bottom..top).filter(|m| emit.contains(m) && reflecting(*m)).collect()
        };
        let mut t = Transposer {
            plan: self,
            ws: self.fft.workspace(true),
            work: Vec::new(),
            reflected: vec![C64::new(0.0, 0.0); self.grid.lateral_len()],
            incident: vec![C64::new(0.0, 0.0); self.grid.lateral_len()],
            unpacked: Vec::new(),
            plane,
            weights,
        };
        let mut adjoint = t.zero();
        let Some(z) = zone else {
            let outside = kept_by(0, last, true);
            let reflected = if reflections { t.backward(t.zero(), &outside, 0, None, &|_| None).0 } else { Adjoints::new() };
            t.forward(&mut adjoint, 0, last, true, &[], &|n| reflected.get(&n));
            return adjoint;
        };
        // The plane lists of the march, in its order (see `HasPlan::march`).
        let mut outside: Vec<usize> = Vec::new();
        let mut inside: Vec<usize> = Vec::new();
        for n in kept_by(0, z.first, true).into_iter().chain(kept_by(z.first, z.last, false)) {
            if in_zone(n) {
                inside.push(n)
            } else {
                outside.push(n)
            }
        }
        let mut trips: Vec<Trip> = Vec::new();
        while trips.len() < z.round_trips && !inside.is_empty() {
            let top = inside.iter().copied().max().unwrap_or(z.first);
            let emitted = emitted_by(z.first, top, z.first..z.last + 1);
            if emitted.is_empty() {
                trips.push(Trip { inside: std::mem::take(&mut inside), emitted: None });
                break;
            }
            let consumed = std::mem::take(&mut inside);
            for n in kept_by(emitted[0], z.last, false) {
                if in_zone(n) {
                    inside.push(n)
                } else {
                    outside.push(n)
                }
            }
            trips.push(Trip { inside: consumed, emitted: Some(emitted) });
        }
        if last > z.last {
            outside.extend(kept_by(z.last, last, false));
        }
        // Transposed, last stage first.
        let (reflected, leaving) = if reflections {
            let waves: Vec<usize> = outside.iter().chain(&inside).copied().collect();
            let (a, leaving) = t.backward(t.zero(), &waves, 0, Some(z.first), &|_| None);
            (a, leaving)
        } else {
            (Adjoints::new(), None)
        };
        if last > z.last {
            t.forward(&mut adjoint, z.last, last, false, &[], &|n| reflected.get(&n));
        }
        // The adjoint of the waves left inside after the last trip: they join the reflections.
        let mut inside_adjoint: Adjoints = if reflections { reflected.clone() } else { Adjoints::new() };
        for trip in trips.iter().rev() {
            let mut emitted_adjoint = Adjoints::new();
            if let Some(emitted) = &trip.emitted {
                let mut a = adjoint.clone();
                let next = &inside_adjoint;
                emitted_adjoint = t.forward(&mut a, emitted[0], z.last, false, emitted, &|n| {
                    if in_zone(n) {
                        next.get(&n)
                    } else {
                        reflected.get(&n)
                    }
                });
            }
            let start = leaving.clone().unwrap_or_else(|| t.zero());
            inside_adjoint = t.backward(start, &trip.inside, z.first, None, &|m| emitted_adjoint.get(&m)).0;
        }
        let kept = |n: usize| if in_zone(n) { inside_adjoint.get(&n) } else { reflected.get(&n) };
        t.forward(&mut adjoint, z.first, z.last, false, &[], &kept);
        t.forward(&mut adjoint, 0, z.first, true, &[], &kept);
        adjoint
    }
}
