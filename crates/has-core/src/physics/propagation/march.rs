//! Marching a source through a plan: the one-way sweep, the round trips of the reverberation
//! zone and the backward pass of reflections (what is recorded on the way: `record.rs`).
//!
//! The march carries the flux-normalised field `ψ = p·sqrt(Z_s/Z)` (see [`super::interface`]),
//! and beside it the shear wave's where a solid's faces convert (`elastic.rs`).
//!
//! A march runs in the precision of the operators it is given ([`Operators`]): the plan's own
//! (double precision) or a [`super::SinglePlan`]'s; it records in double precision either way.

use super::interface::Interface;
pub(super) use super::record::{pressure_scale, Recorder};
pub use super::record::{RecordSpec, Recording, Window};
use super::{HasPlan, Zone};
use crate::physics::fft::{each_pair, map_collect, Fft2, FftWorkspace};
use crate::physics::grid::Grid;
use crate::physics::medium::SliceProperties;
use num_complex::{Complex, Complex64 as C64};
use rustfft::num_traits::NumAssign;
use rustfft::FftNum;
use std::ops::Range;
use std::sync::Arc;

/// A real type a march runs in: `f64`, or `f32` for a single-precision march.
pub(crate) trait Real: FftNum + NumAssign + Into<f64> {}
impl Real for f32 {}
impl Real for f64 {}

/// What a march needs of a plan, in the precision `T` it marches in.
pub(super) trait Operators<T: Real>: Sync {
    /// The grid marched on.
    fn grid(&self) -> &Grid;
    /// The reverberation zone and its round trips.
    fn zone(&self) -> Option<Zone>;
    /// The 2-D FFTs.
    fn fft(&self) -> &Fft2<T>;
    /// The interface at plane `n`, if any.
    fn interface(&self, n: usize) -> Option<&Interface<T>>;
    /// The propagator and the screen of the step through slab `s` (plane `s` to `s + 1`), and
    /// those of its second reference medium where it has one.
    fn step(&self, s: usize) -> StepOperators<'_, T>;
    /// The properties of the slab the beam crossed to reach plane `n`.
    fn slab(&self, n: usize) -> &SliceProperties;
    /// The medium the source radiates from (half a step before plane 0).
    fn source_medium(&self) -> &SliceProperties;
    /// The length of a marched field: a plane, or `[ψ | s]` where the plan carries shear.
    fn field_len(&self) -> usize;
    /// The medium on the side of plane `n` its recording is taken on (the source's on plane 0).
    fn before(&self, n: usize) -> &SliceProperties {
        if n == 0 {
            self.source_medium()
        } else {
            self.slab(n)
        }
    }
}

impl Operators<f64> for HasPlan {
    fn grid(&self) -> &Grid {
        &self.grid
    }
    fn zone(&self) -> Option<Zone> {
        self.zone
    }
    fn fft(&self) -> &Fft2<f64> {
        &self.fft
    }
    fn interface(&self, n: usize) -> Option<&Interface<f64>> {
        self.steps.get(n)?.interface.as_deref()
    }
    fn step(&self, s: usize) -> StepOperators<'_, f64> {
        self.steps[s].operators()
    }
    fn slab(&self, n: usize) -> &SliceProperties {
        self.slab_properties(n)
    }
    fn source_medium(&self) -> &SliceProperties {
        &self.source_medium
    }
    fn field_len(&self) -> usize {
        HasPlan::field_len(self)
    }
}

/// `v` in double precision.
pub(super) fn double<T: Real>(v: Complex<T>) -> C64 {
    C64::new(v.re.into(), v.im.into())
}

/// A zero of `Complex<T>`.
pub(super) fn zero<T: Real>() -> Complex<T> {
    Complex::new(T::zero(), T::zero())
}

/// How many round trips of the reverberation a march adds.
#[derive(Debug, Clone, Copy)]
pub(super) enum RoundTrips {
    /// The plan's number.
    Fixed,
    /// Until the next one is below this fraction of the incident amplitude (counting them).
    UntilBelow(f64),
}

/// A wave kept on one plane: every pixel, or only the pixels of a pointwise interface (zero
/// elsewhere), which is what such an interface reflects.
#[derive(Clone)]
pub(super) enum Wave<T: Real> {
    Dense(Vec<Complex<T>>),
    Sparse { pixels: Arc<Vec<u32>>, values: Vec<Complex<T>> },
}

impl<T: Real> Wave<T> {
    /// `field ← field + wave`.
    pub(super) fn add_to(&self, field: &mut [Complex<T>], parallel: bool) {
        match self {
            Wave::Dense(w) => each_pair(parallel, field, w, |f, &w| *f += w),
            Wave::Sparse { pixels, values } => pixels.iter().zip(values).for_each(|(&i, &w)| field[i as usize] += w),
        }
    }

    /// `plane ← wave` (zero off a sparse wave's pixels).
    pub(super) fn write_to(&self, plane: &mut [Complex<T>]) {
        match self {
            // A wave `[ψ | s]` written to a plane of ψ alone gives its ψ (and a ψ wave to a
            // plane `[ψ | s]`, zero SV).
            Wave::Dense(w) => {
                debug_assert!(w.len() == plane.len() || w.len() == 2 * plane.len() || plane.len() == 2 * w.len());
                let m = plane.len().min(w.len());
                plane[..m].copy_from_slice(&w[..m]);
                plane[m..].fill(zero());
            }
            Wave::Sparse { pixels, values } => {
                plane.fill(zero());
                pixels.iter().zip(values).for_each(|(&i, &w)| plane[i as usize] = w);
            }
        }
    }

    /// The samples that may not be zero.
    fn samples(&self) -> &[Complex<T>] {
        match self {
            Wave::Dense(w) => w,
            Wave::Sparse { values, .. } => values,
        }
    }
}

/// Crosses `interface` in the direction `sign` (+1 forward, -1 backward): `field ← S·(field +
/// sign·R ⊛ field)` with the flux normalisation `S` ([`Interface::normalise_transmitted`]);
/// returns the reflected wave `sign·R ⊛ field` when `keep` (a pointwise face's with its factor
/// `exp(±i·φ)`, see `face_phase`). A pointwise
/// interface touches, and keeps, only its own pixels; a spectral one uses `reflected` and `work`
/// (made as long as `field` if they are not) and keeps every pixel.
pub(super) fn cross<T: Real>(
    interface: &Interface<T>,
    fft: &Fft2<T>,
    field: &mut [Complex<T>],
    sign: f64,
    keep: bool,
    (reflected, work): (&mut Vec<Complex<T>>, &mut Vec<Complex<T>>),
    ws: &mut FftWorkspace<T>,
) -> Option<Wave<T>> {
    if let Some(pairs) = interface.elastic() {
        return super::elastic::cross(pairs, fft, field, sign, keep, work, ws);
    }
    // Where the march carries shear, a face that converts none crosses ψ alone; the SV field
    // passes, and the next slab's screen clears it from pixels that are no longer solid (beyond
    // the continuation's reach, `elastic::screen`). Oblique walls of a solid convert at their
    // treads (`oblique_shear.rs`).
    let n = fft.nx * fft.ny;
    if let Some((pixels, r, phase)) = interface.pointwise() {
        // Oblique walls' treads take their walls' filters, from the field before the crossing.
        let walls = interface.walls().map(|w| (w, w.cross(fft, pixels, field, (sign, keep), work, ws)));
        let (psi, sv) = field.split_at_mut(n);
        let dir = usize::from(sign < 0.0);
        // Walls that transmit into a solid give their treads the SV wave they transmit, and the
        // fluid's pixels ahead of them its continuation (`oblique_shear::CONTINUATION`); elsewhere
        // the SV field passes.
        if let Some((w, ([_, sv_transmitted, ..], ahead))) = &walls {
            if !sv.is_empty() {
                for g in w.groups.iter().filter(|g| g.transmits_sv(dir)) {
                    g.members.iter().for_each(|&m| sv[pixels[m as usize] as usize] = sv_transmitted[m as usize]);
                }
                ahead.iter().for_each(|&(i, v)| sv[i as usize] = v);
            }
        }
        // The reflected wave leaves the face's true position (see `face_phase`).
        let at_face = |m: usize, w: Complex<T>| match phase {
            Some(phase) => {
                let f = phase[m];
                w * if sign < 0.0 { Complex::new(T::one(), T::zero()) / f } else { f }
            }
            None => w,
        };
        let mut values = Vec::with_capacity(if keep { pixels.len() } else { 0 });
        for (m, (&i, &r)) in pixels.iter().zip(r).enumerate() {
            let f = &mut psi[i as usize];
            let w = match &walls {
                Some((w, ([transmitted, _, reflected, _], _))) if w.grouped[m] => {
                    *f = transmitted[m];
                    reflected.get(m).copied().unwrap_or_else(zero)
                }
                _ => {
                    let w = if sign < 0.0 { -(*f * r) } else { *f * r };
                    *f += w;
                    w
                }
            };
            if keep {
                values.push(at_face(m, w));
            }
        }
        interface.normalise_transmitted(psi, sign);
        // Walls that convert keep the SV field's reflected wave at their treads too.
        let kept = match &walls {
            Some((w, ([.., sv_reflected], _))) if keep && w.kept.is_some() => {
                let grouped = (0..pixels.len()).filter(|&m| w.grouped[m]);
                values.extend(grouped.map(|m| at_face(m, sv_reflected.get(m).copied().unwrap_or_else(zero))));
                w.kept.clone()
            }
            _ => None,
        };
        return keep.then(|| Wave::Sparse { pixels: kept.unwrap_or_else(|| pixels.clone()), values });
    }
    let field = &mut field[..n];
    for buffer in [&mut *reflected, &mut *work] {
        buffer.resize(field.len(), zero());
    }
    interface.reflect(fft, field, reflected, work, ws);
    let parallel = ws.is_parallel();
    if sign < 0.0 {
        each_pair(parallel, field, reflected, |f, &r| *f -= r);
    } else {
        each_pair(parallel, field, reflected, |f, &r| *f += r);
    }
    interface.normalise_transmitted(field, sign);
    keep.then(|| Wave::Dense(map_collect(parallel, reflected, |&r| if sign < 0.0 { -r } else { r })))
}

/// A propagator and a screen.
type Filter<'a, T> = (&'a [Complex<T>], &'a [Complex<T>]);

/// A step's propagator and screen, its second reference medium's (`references.rs`), and the SV
/// field's (`elastic.rs`).
pub(super) type StepOperators<'a, T> = (Filter<'a, T>, Option<Filter<'a, T>>, Option<Filter<'a, T>>);

/// One step, `ψ ← S·IFFT(P·FFT(ψ))`, plus `S₂·IFFT(P₂·FFT(ψ))` where the slab has a second
/// reference medium (`work` then holds that part); `transposed`: the step's transpose, the
/// screens applied first. A field `[ψ | s]` steps its SV half with the shear operators, or clears
/// it where the slab holds no solid.
pub(super) fn step<T: Real>(
    fft: &Fft2<T>,
    field: &mut [Complex<T>],
    (ws, work): (&mut FftWorkspace<T>, &mut Vec<Complex<T>>),
    ((propagator, screen), second, shear): StepOperators<'_, T>,
    transposed: bool,
) {
    let (field, sv) = field.split_at_mut(fft.nx * fft.ny);
    let apply = |f: &mut [Complex<T>], ws: &mut FftWorkspace<T>, p: &[Complex<T>], s: &[Complex<T>]| {
        if transposed {
            fft.filter(f, ws, Some(s), p, None);
        } else {
            fft.filter(f, ws, None, p, Some(s));
        }
    };
    if let Some((p2, s2)) = second {
        work.clear();
        work.extend_from_slice(field);
        apply(work, ws, p2, s2);
        apply(field, ws, propagator, screen);
        each_pair(ws.is_parallel(), field, work, |f, &w| *f += w);
    } else {
        apply(field, ws, propagator, screen);
    }
    if !sv.is_empty() {
        match shear {
            Some((p, s)) => apply(sv, ws, p, s),
            None => sv.fill(zero()),
        }
    }
}

/// Waves starting at given planes, in increasing plane order.
type Sources<T> = Vec<(usize, Wave<T>)>;

/// Buffers of one march.
struct Sweeper<'a, T: Real, O: Operators<T>> {
    ops: &'a O,
    ws: FftWorkspace<T>,
    work: Vec<Complex<T>>,
    reflected: Vec<Complex<T>>,
}

impl<'a, T: Real, O: Operators<T>> Sweeper<'a, T, O> {
    fn new(ops: &'a O, parallel: bool) -> Self {
        Sweeper { ops, ws: ops.fft().workspace(parallel), work: Vec::new(), reflected: Vec::new() }
    }

    /// Crosses the interface at plane `n` (if any) in the direction `sign` (+1 forward, -1
    /// backward), see [`cross`].
    fn cross(&mut self, n: usize, field: &mut [Complex<T>], sign: f64, keep: bool) -> Option<Wave<T>> {
        let interface = self.ops.interface(n)?;
        cross(interface, self.ops.fft(), field, sign, keep, (&mut self.reflected, &mut self.work), &mut self.ws)
    }

    /// Propagates `field` through slab `s` (from plane `s` to `s + 1`, or back).
    fn step(&mut self, s: usize, field: &mut [Complex<T>]) {
        step(self.ops.fft(), field, (&mut self.ws, &mut self.work), self.ops.step(s), false);
    }

    /// Forward sweep from plane `from` to plane `to`. With `entering`, `field` is the incident
    /// wave at `from` (recorded, then the interface crossed); otherwise it has crossed `from`
    /// already. `sources` (forward waves just past an interface) are added on their planes;
    /// reflections at interface planes `n` with `keep(n)` are returned. On return `field` has
    /// crossed plane `to`.
    #[allow(clippy::too_many_arguments)]
    fn forward(
        &mut self,
        field: &mut [Complex<T>],
        from: usize,
        to: usize,
        entering: bool,
        mut sources: Sources<T>,
        keep: &dyn Fn(usize) -> bool,
        power: bool,
        rec: &mut Recorder,
    ) -> Sources<T> {
        let mut back = Sources::new();
        sources.reverse();
        for n in from..=to {
            if n > from {
                self.step(n - 1, field);
            }
            if n > from || entering {
                rec.add(n, field, self.ops.before(n), self.ops.source_medium());
                if power {
                    rec.power(n, self.ops.source_medium(), field);
                }
                if let Some(r) = self.cross(n, field, 1.0, keep(n)) {
                    back.push((n, r));
                }
            }
            while sources.last().is_some_and(|s| s.0 == n) {
                if let Some((_, s)) = sources.pop() {
                    s.add_to(field, self.ws.is_parallel());
                }
            }
        }
        back
    }

    /// Backward sweep of `sources` (backward waves leaving interface planes towards -z) down to
    /// plane `bottom`, crossing every interface on the way; the wave `inject` is added on its
    /// plane after that plane is recorded. Returns the backward wave leaving `bottom` and the
    /// forward waves reflected at interface planes in `emit`.
    fn backward(
        &mut self,
        mut sources: Sources<T>,
        bottom: usize,
        emit: Range<usize>,
        inject: Option<(usize, &[Complex<T>])>,
        rec: &mut Recorder,
    ) -> (Vec<Complex<T>>, Sources<T>) {
        let mut b = vec![zero(); self.ops.field_len()];
        let mut forward = Sources::new();
        let Some(top) = sources.last().map(|s| s.0).max(inject.map(|i| i.0)) else {
            return (b, forward);
        };
        let mut started = false;
        for m in (bottom..=top).rev() {
            if started {
                if let Some(r) = self.cross(m, &mut b, -1.0, emit.contains(&m)) {
                    forward.push((m, r));
                }
            }
            while sources.last().is_some_and(|s| s.0 == m) {
                if let Some((_, s)) = sources.pop() {
                    s.add_to(&mut b, self.ws.is_parallel());
                }
                started = true;
            }
            if started {
                rec.add(m, &b, self.ops.before(m), self.ops.source_medium());
            }
            if let Some((_, w)) = inject.filter(|i| i.0 == m) {
                each_pair(self.ws.is_parallel(), &mut b, w, |b, &w| *b += w);
                started = true;
            }
            if m > bottom && started {
                self.step(m - 1, &mut b);
            }
        }
        forward.reverse();
        (b, forward)
    }
}

/// Root-sum-square of the samples.
fn rss<T: Real>(v: &[Complex<T>]) -> f64 {
    v.iter().map(|&v| double(v).norm_sqr()).sum::<f64>().sqrt()
}

/// Root-sum-square of the waves' samples.
fn norm<T: Real>(waves: &Sources<T>) -> f64 {
    waves.iter().flat_map(|(_, w)| w.samples()).map(|&v| double(v).norm_sqr()).sum::<f64>().sqrt()
}

/// Marches `field` (the source on plane 0) with the operators `ops` and returns what `spec` asks
/// for, with the number of reverberation round trips added.
pub(super) fn march<T: Real, O: Operators<T>>(
    ops: &O,
    mut field: Vec<Complex<T>>,
    spec: &RecordSpec,
    parallel: bool,
    trips: RoundTrips,
) -> (Recording, usize) {
    let g = ops.grid();
    let last = spec.last_plane(g.nz);
    field.resize(ops.field_len(), zero());
    let mut rec = Recorder::new(g, spec, last);
    let mut sweeper = Sweeper::new(ops, parallel);
    let zone = ops.zone().filter(|z| z.first <= last);
    let in_zone = |n: usize| zone.is_some_and(|z| (z.first..=z.last).contains(&n));
    let keep = |n: usize| spec.reflections || in_zone(n);
    let (mut outside, mut inside) = (Sources::new(), Sources::new());
    let mut sort = |waves: Sources<T>, inside: &mut Sources<T>| {
        for w in waves {
            if in_zone(w.0) {
                inside.push(w);
            } else {
                outside.push(w);
            }
        }
    };
    let mut back_exit: Option<(usize, Vec<Complex<T>>)> = None;
    let mut done = 0;
    match zone {
        None => sort(sweeper.forward(&mut field, 0, last, true, Sources::new(), &keep, true, &mut rec), &mut inside),
        Some(z) => {
            sort(sweeper.forward(&mut field, 0, z.first, true, Sources::new(), &keep, true, &mut rec), &mut inside);
            let incident = rss(&field);
            sort(sweeper.forward(&mut field, z.first, z.last, false, Sources::new(), &keep, true, &mut rec), &mut inside);
            let (cap, tolerance) = match trips {
                RoundTrips::Fixed => (z.round_trips, None),
                RoundTrips::UntilBelow(t) => (super::MAX_ROUND_TRIPS, Some(t * incident)),
            };
            let mut leaving = vec![zero(); ops.field_len()];
            while done < cap && !inside.is_empty() {
                // Counting, a backward sweep is kept only if its round trip is added, so
                // that the recording equals the march with that many trips.
                let mut trial = tolerance.map(|_| Recorder::new(g, spec, last));
                let (b, u) =
                    sweeper.backward(std::mem::take(&mut inside), z.first, z.first..z.last + 1, None, trial.as_mut().unwrap_or(&mut rec));
                if tolerance.is_some_and(|t| norm(&u) < t) {
                    break;
                }
                if let Some(t) = trial {
                    rec.absorb(t);
                }
                each_pair(parallel, &mut leaving, &b, |l, &b| *l += b);
                if u.is_empty() {
                    break;
                }
                let start = u[0].0;
                let mut f = vec![zero(); ops.field_len()];
                let back = sweeper.forward(&mut f, start, z.last, false, u, &keep, false, &mut rec);
                each_pair(parallel, &mut field, &f, |a, &b| *a += b);
                sort(back, &mut inside);
                done += 1;
            }
            if last > z.last {
                sort(sweeper.forward(&mut field, z.last, last, false, Sources::new(), &keep, true, &mut rec), &mut inside);
            }
            if spec.reflections {
                back_exit = Some((z.first, leaving));
            }
        }
    }
    if spec.reflections {
        outside.append(&mut inside);
        outside.sort_by_key(|w| w.0);
        let inject = back_exit.as_ref().map(|(p, w)| (*p, w.as_slice()));
        if !outside.is_empty() || inject.is_some() {
            sweeper.backward(outside, 0, 0..0, inject, &mut rec);
        }
    }
    (rec.finish(), done)
}

impl HasPlan {
    /// Marches `field` (the source on plane 0) in double precision (see [`march`]).
    pub(super) fn march(&self, field: Vec<C64>, spec: &RecordSpec, parallel: bool, trips: RoundTrips) -> (Recording, usize) {
        march(self, field, spec, parallel, trips)
    }

    /// The round trips the reference beam needs (see [`super::REVERBERATION_TOLERANCE`]) and
    /// its recording for `spec` with that many: the same as [`HasPlan::propagate`] once the
    /// zone holds the count, if `spec` reaches the zone (`spec.last_plane(nz) >= zone.first`)
    /// and asks for no reflections. The count does not depend on `spec`.
    pub(super) fn round_trips_needed(&self, reference: &[C64], spec: &RecordSpec) -> (Recording, usize) {
        self.march(reference.to_vec(), spec, true, RoundTrips::UntilBelow(super::REVERBERATION_TOLERANCE))
    }
}

/// Runs `f` on a rayon worker: the parallel loops of every step then stay inside the pool
/// instead of waking the calling thread at each of them (called from outside the pool, e.g. from
/// Python's thread, each loop is queued to the pool and its caller woken when it is done).
pub(super) fn in_pool(f: impl FnOnce() + Send) {
    rayon::scope(|s| s.spawn(|_| f()));
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::propagation::interface::{Coefficients, InterfaceModel};

    /// Crossing a pointwise interface touches its own pixels alone and keeps its reflection
    /// there: the same samples, to the bit, as the whole plane's reflection `R ⊛ p` added to the
    /// field (the operator's plain form) and normalised, in either direction; zero on every other
    /// pixel. The normalised transmission is `sqrt(1 - R²)` both ways (1e-15: rounding).
    #[test]
    fn a_pointwise_crossing_equals_the_whole_planes_reflection() {
        let g = Grid::new(12, 10, 0.5e-3, 0.5e-3, 4, 0.5e-3, 0.0).unwrap();
        let n = g.lateral_len();
        let water = SliceProperties::fluid(vec![1500.0; n], vec![1000.0; n], vec![0.0; n]);
        // Ten distinct bone-like pixels (more pairs than the spectral model takes), water elsewhere.
        let mut bone = water.clone();
        for (m, i) in (7..n).step_by(11).enumerate() {
            bone.sound_speed[i] = 2000.0 + 100.0 * m as f64;
            bone.density[i] = 1500.0 + 30.0 * m as f64;
        }
        let omega = 2.0 * std::f64::consts::PI * 5e5;
        let interface = Interface::new(&g, &water, &bone, omega, InterfaceModel::Angular, None, &mut Coefficients::default()).unwrap();
        let (pixels, _, _) = interface.pointwise().expect("per-pixel interface");
        assert_eq!(pixels.len(), (7..n).step_by(11).count());
        let fft = Fft2::new(g.nx, g.ny);
        let mut ws = fft.workspace(false);
        let p: Vec<C64> = (0..n).map(|i| C64::new((i as f64 * 0.37).sin(), (i as f64 * 0.11).cos())).collect();
        for sign in [1.0, -1.0] {
            let (mut reflected, mut work) = (vec![C64::new(0.0, 0.0); n], vec![C64::new(0.0, 0.0); n]);
            interface.reflect(&fft, &p, &mut reflected, &mut work, &mut ws);
            let whole: Vec<C64> = reflected.iter().map(|&r| if sign < 0.0 { -r } else { r }).collect();
            let mut crossed: Vec<C64> = p.iter().zip(&whole).map(|(&p, &r)| p + r).collect();
            interface.normalise_transmitted(&mut crossed, sign);
            let mut field = p.clone();
            let kept = cross(&interface, &fft, &mut field, sign, true, (&mut Vec::new(), &mut Vec::new()), &mut ws).unwrap();
            assert_eq!(field, crossed, "sign {sign}");
            for i in 0..n {
                let (za, zb) = (1.5e6, bone.density[i] * bone.sound_speed[i]);
                let r = (zb - za) / (za + zb);
                let want = p[i] * (1.0 - r * r).sqrt();
                assert!((field[i] - want).norm() < 1e-15, "sign {sign}, pixel {i}: {} vs {want}", field[i]);
            }
            let mut kept_plane = vec![C64::new(0.0, 0.0); n];
            kept.add_to(&mut kept_plane, false);
            assert_eq!(kept_plane, whole, "sign {sign}");
            assert!(matches!(kept, Wave::Sparse { .. }));
        }
    }
}
