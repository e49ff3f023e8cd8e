//! What a simulation's plan is made of, as typed results: the grid it marches on and how it
//! crosses changes of medium. `to_dict` writes each from its getters (the keys `arfi field
//! --json` writes under `propagation`).

use crate::results::{fields_dict, fields_repr};
use has_core::simulation::{Propagation, Simulation};
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// The methods of a frozen value class: its `_fields` (what `to_dict` writes, in order),
/// `to_dict`, `__repr__` and a `__hash__` that agrees with `==` (that of the tuple of its fields:
/// Python hashes -0.0 as 0.0).
macro_rules! value_methods {
    ($class:ty, $name:literal, [$($field:literal),+ $(,)?]) => {
        #[pymethods]
        impl $class {
            /// The attributes `to_dict` writes, in order.
            #[classattr]
            fn _fields() -> Vec<&'static str> {
                vec![$($field),+]
            }

            /// The value as a dict of its attributes (nested values as dicts).
            fn to_dict<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyDict>> {
                fields_dict(slf.as_any())
            }

            fn __hash__(slf: &Bound<'_, Self>) -> PyResult<isize> {
                let values = [$(slf.getattr($field)?),+];
                pyo3::types::PyTuple::new(slf.py(), values)?.hash()
            }

            fn __repr__(slf: &Bound<'_, Self>) -> PyResult<String> {
                fields_repr(slf.as_any(), $name)
            }
        }
    };
}

value_methods!(CoreGrid, "Grid", ["nx", "ny", "nz", "dx_mm", "dy_mm", "dz_mm", "z0_mm"]);
value_methods!(CoreReverberation, "Reverberation", ["first_interface_z_mm", "last_interface_z_mm", "round_trips"]);
value_methods!(CorePropagation, "Propagation", ["interfaces", "screen", "reflections", "shear", "reverberation"]);

/// The grid the march runs on (mm): `nx` x `ny` points spaced `dx_mm`, `dy_mm` on each plane,
/// `nz` planes `dz_mm` apart from `z0_mm` (the source plane's z).
#[pyclass(module = "arfi._core", name = "Grid", frozen, eq, get_all, skip_from_py_object)]
#[derive(Clone, PartialEq)]
pub(crate) struct CoreGrid {
    nx: usize,
    ny: usize,
    nz: usize,
    dx_mm: f64,
    dy_mm: f64,
    dz_mm: f64,
    z0_mm: f64,
}

impl CoreGrid {
    pub(crate) fn of(sim: &Simulation) -> Self {
        let g = &sim.grid;
        CoreGrid { nx: g.nx, ny: g.ny, nz: g.nz, dx_mm: g.dx * 1e3, dy_mm: g.dy * 1e3, dz_mm: g.dz * 1e3, z0_mm: g.z0 * 1e3 }
    }
}

/// The layers between which waves bouncing inside them are added: the z (mm) of the first and
/// last interface, and the round trips added.
#[pyclass(module = "arfi._core", name = "Reverberation", frozen, eq, get_all, skip_from_py_object)]
#[derive(Clone, PartialEq)]
pub(crate) struct CoreReverberation {
    first_interface_z_mm: f64,
    last_interface_z_mm: f64,
    round_trips: usize,
}

/// How the march crosses changes of medium: `interfaces` (`"angular"`: plane-wave coefficients
/// of every angular-spectrum component, exact at planar interfaces, with total reflection beyond
/// the critical angle; `"normal-incidence"`: `T = 2·Z2/(Z1+Z2)` per pixel), `screen`
/// (`"oblique"`: each pixel's wave crosses its slab along the line to the focus; `"vertical"`:
/// along z, the original HAS screen), `reflections` (waves sent back towards the source added),
/// `shear` (shear waves carried through solids whose faces lie on the planes or on planar walls
/// tilted against them, with mode conversion at each such face) and `reverberation` (None, or
/// where the waves bouncing inside layers are added).
#[pyclass(module = "arfi._core", name = "Propagation", frozen, eq, get_all, skip_from_py_object)]
#[derive(Clone, PartialEq)]
pub(crate) struct CorePropagation {
    interfaces: &'static str,
    screen: &'static str,
    reflections: bool,
    shear: bool,
    reverberation: Option<CoreReverberation>,
}

impl From<Propagation> for CorePropagation {
    fn from(p: Propagation) -> Self {
        CorePropagation {
            interfaces: p.interfaces,
            screen: p.screen,
            reflections: p.reflections,
            shear: p.shear,
            reverberation: p.reverberation.map(|(a, b, n)| CoreReverberation {
                first_interface_z_mm: a * 1e3,
                last_interface_z_mm: b * 1e3,
                round_trips: n,
            }),
        }
    }
}
