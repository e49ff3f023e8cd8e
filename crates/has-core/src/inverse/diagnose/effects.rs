//! The effects of the model-discrepancy library, their parameters and the names they are
//! reported under: one table ([`PARAMETERS`]) that `diagnose` reports with and
//! [`Effects::set`] reads back.

use crate::error::{HasError, Result};
use crate::simulation::Simulation;

/// A candidate effect of the model-discrepancy library.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Effect {
    /// A scale on the force-to-ARFI-phase amplitude.
    Amplitude,
    /// The width W of the isotropic Gaussian broadening (paper Eq. 2).
    Broadening,
    /// An in-plane offset of the image against the model.
    RegistrationShift,
    /// A constant plus a linear phase ramp across the image.
    BackgroundPhase,
    /// An offset of the imaged slice from the model's along its normal.
    SliceOffset,
    /// Different broadening widths along the two image axes.
    BroadeningAnisotropic,
    /// Attenuation of the material at the focus (absorbs the beam and sets the force).
    Attenuation,
    /// Sound speed of the material at the focus (moves and blurs the focus).
    SoundSpeed,
    /// A group of elements that emits nothing.
    ElementDropout,
    /// One phase per group added to the drive (the aberration the estimators fit).
    PhaseAberration,
}

impl Effect {
    /// Every effect, in a fixed order (ties go to the earlier: simpler before costlier).
    pub const ALL: [Effect; 10] = [
        Effect::Amplitude,
        Effect::Broadening,
        Effect::RegistrationShift,
        Effect::BackgroundPhase,
        Effect::SliceOffset,
        Effect::BroadeningAnisotropic,
        Effect::Attenuation,
        Effect::SoundSpeed,
        Effect::ElementDropout,
        Effect::PhaseAberration,
    ];

    /// The name reported and accepted (`"broadening"`, `"phase_aberration"`, ...).
    pub fn name(&self) -> &'static str {
        match self {
            Effect::Amplitude => "amplitude",
            Effect::Broadening => "broadening",
            Effect::RegistrationShift => "registration_shift",
            Effect::BackgroundPhase => "background_phase",
            Effect::SliceOffset => "slice_offset",
            Effect::BroadeningAnisotropic => "broadening_anisotropic",
            Effect::Attenuation => "attenuation",
            Effect::SoundSpeed => "sound_speed",
            Effect::ElementDropout => "element_dropout",
            Effect::PhaseAberration => "phase_aberration",
        }
    }

    /// The effect of a name.
    pub fn from_name(name: &str) -> Option<Effect> {
        Effect::ALL.into_iter().find(|e| e.name() == name)
    }

    /// The effect of a name, or an error listing the names.
    pub fn named(name: &str) -> Result<Effect> {
        Effect::from_name(name).ok_or_else(|| {
            let known: Vec<&str> = Effect::ALL.iter().map(|e| e.name()).collect();
            HasError::invalid("effects", format!("unknown effect {name:?} (known: {})", known.join(", ")))
        })
    }

    /// Indices into [`View::to_vec`] of this effect's image-space parameters (none for field
    /// effects).
    pub(super) fn slots(&self) -> &'static [usize] {
        match self {
            Effect::Amplitude => &[0],
            Effect::Broadening => &[1],
            Effect::BroadeningAnisotropic => &[1, 2],
            Effect::RegistrationShift => &[3, 4],
            Effect::BackgroundPhase => &[5, 6, 7],
            Effect::SliceOffset => &[8],
            _ => &[],
        }
    }
}

/// The image-space parameters of the model, in the units of their names.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct View {
    /// Scale on the amplitude (1 = the model's).
    pub scale: f64,
    /// Mean broadening width W (mm).
    pub broadening_width_mm: f64,
    /// Difference of the broadening widths along u and v (mm).
    pub broadening_anisotropy_mm: f64,
    /// Registration shift of the image along u and v (mm).
    pub shift_mm: [f64; 2],
    /// Background phase `offset + slope_u·u + slope_v·v`: the offset (rad; u, v pixel-centre
    /// coordinates in mm).
    pub background_offset_rad: f64,
    /// The background's slopes along u and v (rad/mm).
    pub background_slope_rad_per_mm: [f64; 2],
    /// Offset of the slice along its normal (mm), within ±[`SLICE_REACH_MM`].
    pub slice_offset_mm: f64,
}

/// The largest slice offset fitted (mm): the extra field recorded on each side of the slice.
pub const SLICE_REACH_MM: f64 = 8.0;

/// Parameter names with units, in [`View::to_vec`] order.
const NAMES: [&str; 9] = [
    "scale",
    "broadening_width_mm",
    "broadening_anisotropy_mm",
    "dx_mm",
    "dy_mm",
    "offset_rad",
    "slope_x_rad_per_mm",
    "slope_y_rad_per_mm",
    "dz_mm",
];
/// Initial simplex steps, in [`View::to_vec`] order.
pub(super) const STEPS: [f64; 9] = [0.05, 0.5, 0.5, 0.5, 0.5, 0.01, 2e-4, 2e-4, 1.0];

impl View {
    /// The model as built: no scale, the simulation's width, nothing else.
    pub fn of(sim: &Simulation) -> Self {
        View {
            scale: 1.0,
            broadening_width_mm: sim.sampler.as_ref().map_or(0.0, |s| s.broadening.width) * 1e3, // no sampler: the forward model refuses
            broadening_anisotropy_mm: 0.0,
            shift_mm: [0.0; 2],
            background_offset_rad: 0.0,
            background_slope_rad_per_mm: [0.0; 2],
            slice_offset_mm: 0.0,
        }
    }

    /// The broadening widths along u and v (mm).
    pub fn widths_mm(&self) -> [f64; 2] {
        let (w, a) = (self.broadening_width_mm, self.broadening_anisotropy_mm);
        [(w + 0.5 * a).abs(), (w - 0.5 * a).abs()]
    }

    pub(super) fn to_vec(self) -> [f64; 9] {
        let b = self.background_slope_rad_per_mm;
        [
            self.scale,
            self.broadening_width_mm,
            self.broadening_anisotropy_mm,
            self.shift_mm[0],
            self.shift_mm[1],
            self.background_offset_rad,
            b[0],
            b[1],
            self.slice_offset_mm,
        ]
    }

    pub(super) fn from_vec(v: &[f64; 9]) -> Self {
        View {
            scale: v[0],
            broadening_width_mm: v[1].abs(),
            broadening_anisotropy_mm: v[2],
            shift_mm: [v[3], v[4]],
            background_offset_rad: v[5],
            background_slope_rad_per_mm: [v[6], v[7]],
            slice_offset_mm: v[8],
        }
    }
}

/// The field-side parameters of the model: what the array and the medium do differently.
#[derive(Debug, Clone, PartialEq)]
pub struct FieldState {
    /// Phase (rad) added to every element of each group, on top of each image's known phases
    /// (empty = none).
    pub group_phases: Vec<f64>,
    /// Groups whose elements emit nothing (sorted).
    pub dead_groups: Vec<usize>,
    /// Sound speed of the material at the focus (m/s).
    pub sound_speed: f64,
    /// Attenuation of the material at the focus (dB/cm/MHz).
    pub attenuation_db_cm_mhz: f64,
}

/// Every parameter of the extended model.
#[derive(Debug, Clone, PartialEq)]
pub struct Effects {
    /// Image-space parameters: applied to the recorded `|p|²` window.
    pub view: View,
    /// Field parameters: change the HAS field (a new march).
    pub field: FieldState,
}

impl Effects {
    /// The simulation's own model: no effect added.
    pub fn none(sim: &Simulation) -> Self {
        let m = &sim.medium.materials[focal_material(sim)];
        Effects {
            view: View::of(sim),
            field: FieldState {
                group_phases: vec![],
                dead_groups: vec![],
                sound_speed: m.sound_speed,
                attenuation_db_cm_mhz: m.attenuation_db_cm_mhz,
            },
        }
    }
}

/// Index of the material at the focus.
pub(super) fn focal_material(sim: &Simulation) -> usize {
    let f = sim.focus;
    sim.medium.material_at(f[0], f[1], f[2])
}

/// What kind of value a parameter takes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ValueKind {
    /// One number ([`Value::Number`]).
    Number,
    /// One number per group ([`Value::Numbers`]).
    Numbers,
    /// Group indices ([`Value::Indices`]).
    Indices,
}

/// One parameter of the library: the name `diagnose` reports it under and [`Effects::set`]
/// accepts (units in the name), the effect it belongs to, its kind and meaning.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Parameter {
    /// The name `diagnose` reports and [`Effects::set`] accepts (unit in the name).
    pub name: &'static str,
    /// The effect it belongs to.
    pub effect: Effect,
    /// Whether it is one number, a list, or group indices.
    pub kind: ValueKind,
    /// What it means, for reports and `--help`.
    pub meaning: &'static str,
}

const fn param(name: &'static str, effect: Effect, kind: ValueKind, meaning: &'static str) -> Parameter {
    Parameter { name, effect, kind, meaning }
}

/// Every parameter of the library, in [`Effect::ALL`] order: the one table of names.
pub const PARAMETERS: [Parameter; 15] = [
    param("scale", Effect::Amplitude, ValueKind::Number, "scale on the force-to-phase amplitude (1: the model's)"),
    param("broadening_width_mm", Effect::Broadening, ValueKind::Number, "width W of the isotropic Gaussian broadening (mm)"),
    param("dx_mm", Effect::RegistrationShift, ValueKind::Number, "shift of the image against the model along its first axis (mm)"),
    param("dy_mm", Effect::RegistrationShift, ValueKind::Number, "shift of the image against the model along its second axis (mm)"),
    param("offset_rad", Effect::BackgroundPhase, ValueKind::Number, "constant background phase (rad)"),
    param("slope_x_rad_per_mm", Effect::BackgroundPhase, ValueKind::Number, "background phase ramp along the image's first axis (rad/mm)"),
    param("slope_y_rad_per_mm", Effect::BackgroundPhase, ValueKind::Number, "background phase ramp along the image's second axis (rad/mm)"),
    param("dz_mm", Effect::SliceOffset, ValueKind::Number, "offset of the imaged slice along its normal (mm, within ±8)"),
    param("broadening_width_u_mm", Effect::BroadeningAnisotropic, ValueKind::Number, "broadening width along the image's first axis (mm)"),
    param("broadening_width_v_mm", Effect::BroadeningAnisotropic, ValueKind::Number, "broadening width along the image's second axis (mm)"),
    param(
        "broadening_anisotropy_mm",
        Effect::BroadeningAnisotropic,
        ValueKind::Number,
        "width along the first axis minus width along the second (mm), broadening_width_mm their mean",
    ),
    param("attenuation_db_cm_mhz", Effect::Attenuation, ValueKind::Number, "attenuation of the material at the focus (dB/cm/MHz)"),
    param("sound_speed_m_s", Effect::SoundSpeed, ValueKind::Number, "sound speed of the material at the focus (m/s)"),
    param("dead_groups", Effect::ElementDropout, ValueKind::Indices, "groups whose elements emit nothing"),
    param("group_phases_rad", Effect::PhaseAberration, ValueKind::Numbers, "phase added to every element of each group (rad)"),
];

impl Parameter {
    /// The parameter of a name, or an error listing the names.
    pub fn named(name: &str) -> Result<&'static Parameter> {
        PARAMETERS.iter().find(|p| p.name == name).ok_or_else(|| {
            let names: Vec<&str> = PARAMETERS.iter().map(|p| p.name).collect();
            HasError::invalid("effects", format!("unknown parameter {name:?}; the parameters are {}", names.join(", ")))
        })
    }
}

impl Effects {
    /// Sets the parameter `name` (any name of [`PARAMETERS`], as `diagnose` reports them) to
    /// `value`. Broadening widths along u and v set the mean width and the anisotropy together
    /// (the other width is kept).
    pub fn set(&mut self, name: &str, value: &Value) -> Result<()> {
        let p = Parameter::named(name)?;
        let key = || format!("effects[{name:?}]");
        let number = || match value {
            Value::Number(x) if x.is_finite() => Ok(*x),
            Value::Number(_) => Err(HasError::invalid(key(), "must be finite")),
            _ => Err(HasError::invalid(key(), "must be a number")),
        };
        let v = &mut self.view;
        match p.name {
            "scale" => v.scale = number()?,
            "broadening_width_mm" => v.broadening_width_mm = number()?,
            "broadening_anisotropy_mm" => v.broadening_anisotropy_mm = number()?,
            "broadening_width_u_mm" | "broadening_width_v_mm" => {
                let width = number()?;
                crate::error::require_non_negative(&key(), width)?;
                let mut w = v.widths_mm();
                w[usize::from(p.name == "broadening_width_v_mm")] = width;
                v.broadening_width_mm = 0.5 * (w[0] + w[1]);
                v.broadening_anisotropy_mm = w[0] - w[1];
            }
            "dx_mm" => v.shift_mm[0] = number()?,
            "dy_mm" => v.shift_mm[1] = number()?,
            "offset_rad" => v.background_offset_rad = number()?,
            "slope_x_rad_per_mm" => v.background_slope_rad_per_mm[0] = number()?,
            "slope_y_rad_per_mm" => v.background_slope_rad_per_mm[1] = number()?,
            "dz_mm" => v.slice_offset_mm = number()?,
            "sound_speed_m_s" => self.field.sound_speed = number()?,
            "attenuation_db_cm_mhz" => self.field.attenuation_db_cm_mhz = number()?,
            "group_phases_rad" => match value {
                Value::Numbers(x) if x.iter().all(|v| v.is_finite()) => self.field.group_phases = x.clone(),
                Value::Numbers(_) => return Err(HasError::invalid(key(), "must be finite")),
                _ => return Err(HasError::invalid(key(), "must be a list of numbers (one per group)")),
            },
            "dead_groups" => match value {
                Value::Indices(g) => {
                    let mut g = g.clone();
                    g.sort_unstable();
                    g.dedup();
                    self.field.dead_groups = g;
                }
                _ => return Err(HasError::invalid(key(), "must be a list of group indices")),
            },
            other => return Err(HasError::invalid("effects", format!("parameter {other:?} cannot be set"))),
        }
        Ok(())
    }
}

/// One fitted value of an effect.
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    /// One number (e.g. a width in mm).
    Number(f64),
    /// A list of numbers (e.g. a shift along u and v, or group phases).
    Numbers(Vec<f64>),
    /// Indices (e.g. the dead groups).
    Indices(Vec<usize>),
}

/// The parameters an effect changed between `before` and `after`, named with units.
pub(super) fn params_of(effect: Effect, after: &Effects, before: &Effects) -> Vec<(&'static str, Value)> {
    let f = &after.field;
    match effect {
        Effect::PhaseAberration => vec![("group_phases_rad", Value::Numbers(crate::phase::centred(&f.group_phases)))],
        Effect::ElementDropout => {
            let new: Vec<usize> = f.dead_groups.iter().copied().filter(|g| !before.field.dead_groups.contains(g)).collect();
            vec![("dead_groups", Value::Indices(new))]
        }
        Effect::SoundSpeed => vec![("sound_speed_m_s", Value::Number(f.sound_speed))],
        Effect::Attenuation => vec![("attenuation_db_cm_mhz", Value::Number(f.attenuation_db_cm_mhz))],
        Effect::BroadeningAnisotropic => {
            let w = after.view.widths_mm();
            vec![("broadening_width_u_mm", Value::Number(w[0])), ("broadening_width_v_mm", Value::Number(w[1]))]
        }
        e => {
            let v = after.view.to_vec();
            e.slots().iter().map(|&s| (NAMES[s], Value::Number(v[s]))).collect()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::inverse::element::nuisance::Nuisance;

    #[test]
    fn nuisance_fitted_with_the_phases_is_named_as_its_effect() {
        // An estimate's fit_nuisance takes and reports the names diagnose gives the same effects.
        let same = [Effect::Amplitude, Effect::Broadening, Effect::RegistrationShift, Effect::BackgroundPhase];
        assert_eq!(Nuisance::NAMES, same.map(|e| e.name()));
    }

    #[test]
    fn the_table_names_every_reported_parameter_and_each_can_be_set() {
        // Every effect has parameters; the image-space names reported are in the table under
        // their effect; every parameter of the table takes a value of its kind.
        for e in Effect::ALL {
            assert!(PARAMETERS.iter().any(|p| p.effect == e), "{} has no parameter", e.name());
            for &slot in e.slots() {
                let p = Parameter::named(NAMES[slot]).unwrap();
                assert!(p.effect == e || e == Effect::BroadeningAnisotropic, "{} under {}", p.name, e.name());
            }
        }
        let view = View {
            scale: 1.0,
            broadening_width_mm: 2.7,
            broadening_anisotropy_mm: 0.0,
            shift_mm: [0.0; 2],
            background_offset_rad: 0.0,
            background_slope_rad_per_mm: [0.0; 2],
            slice_offset_mm: 0.0,
        };
        let field = FieldState { group_phases: vec![], dead_groups: vec![], sound_speed: 1533.0, attenuation_db_cm_mhz: 0.46 };
        let mut e = Effects { view, field };
        for p in PARAMETERS {
            let value = match p.kind {
                ValueKind::Number => Value::Number(1.5),
                ValueKind::Numbers => Value::Numbers(vec![0.1; 16]),
                ValueKind::Indices => Value::Indices(vec![3, 1, 3]),
            };
            e.set(p.name, &value).unwrap();
        }
        assert_eq!(e.field.dead_groups, vec![1, 3]);
        // Widths u = v = 1.5 mm (mean 1.5), then the anisotropy 1.5 mm on that mean.
        assert_eq!(e.view.widths_mm(), [2.25, 0.75]);
        let err = e.set("broadening_width_w_mm", &Value::Number(1.0)).unwrap_err().to_string();
        assert!(err.contains("unknown parameter") && err.contains("broadening_width_u_mm"), "{err}");
        assert!(e.set("dz_mm", &Value::Numbers(vec![1.0])).is_err());
        assert!(e.set("scale", &Value::Number(f64::NAN)).is_err());
    }
}
