//! The estimate's options by name, for callers that set them one at a time (the Python bindings,
//! a configuration file): each option is declared once here, with its kind and meaning, and read
//! into and back out of [`EstimateRequest`], so that a binding needs no code per option. Names
//! carry their unit (`prior_correlation_mm` is held in metres by the request).

use super::{EstimateRequest, Method};
use crate::error::{HasError, Result};
use crate::inverse::element::nuisance::Nuisance;
use crate::inverse::prior::Prior;

/// What kind of value an option takes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OptionKind {
    /// True or false.
    Flag,
    /// An integer >= 0.
    Count,
    /// A finite real number.
    Number,
    /// A word from a list.
    Text,
    /// Names (a list, or one comma-separated string).
    Names,
    /// Real values, one per element or group.
    Values,
    /// Rows of real values (modes x elements).
    Rows,
}

/// A value of an option.
#[derive(Debug, Clone, PartialEq)]
pub enum OptionValue {
    /// See [`OptionKind::Flag`].
    Flag(bool),
    /// See [`OptionKind::Count`].
    Count(u64),
    /// See [`OptionKind::Number`].
    Number(f64),
    /// See [`OptionKind::Text`].
    Text(String),
    /// See [`OptionKind::Names`].
    Names(Vec<String>),
    /// See [`OptionKind::Values`].
    Values(Vec<f64>),
    /// See [`OptionKind::Rows`].
    Rows(Vec<Vec<f64>>),
}

impl OptionKind {
    /// The kind's name, as help texts and stubs write it.
    pub fn name(self) -> &'static str {
        match self {
            OptionKind::Flag => "flag",
            OptionKind::Count => "count",
            OptionKind::Number => "number",
            OptionKind::Text => "text",
            OptionKind::Names => "names",
            OptionKind::Values => "values",
            OptionKind::Rows => "rows",
        }
    }
}

impl OptionValue {
    /// The kind of this value.
    pub fn kind(&self) -> OptionKind {
        match self {
            OptionValue::Flag(_) => OptionKind::Flag,
            OptionValue::Count(_) => OptionKind::Count,
            OptionValue::Number(_) => OptionKind::Number,
            OptionValue::Text(_) => OptionKind::Text,
            OptionValue::Names(_) => OptionKind::Names,
            OptionValue::Values(_) => OptionKind::Values,
            OptionValue::Rows(_) => OptionKind::Rows,
        }
    }
}

/// One option: its name (with its unit), kind, whether it may be unset (`None`: the method's
/// default), and what it means.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OptionSpec {
    /// The option's name, as callers and the JSON write it.
    pub name: &'static str,
    /// What it takes.
    pub kind: OptionKind,
    /// Whether it may be unset (reads back as `None`).
    pub optional: bool,
    /// What it means, for help texts and stubs.
    pub doc: &'static str,
}

const fn spec(name: &'static str, kind: OptionKind, optional: bool, doc: &'static str) -> OptionSpec {
    OptionSpec { name, kind, optional, doc }
}

/// Every option of an estimate, in the order they are listed and written.
pub const OPTIONS: &[OptionSpec] = &[
    spec(
        "method",
        OptionKind::Text,
        false,
        "the search: 'lbfgs' (analytic gradient, seeded multi-start; the default), 'nelder-mead' (the paper's: zero \
         start, <= 8000 evaluations) or 'pso'",
    ),
    spec(
        "max_evaluations",
        OptionKind::Count,
        true,
        "the search's evaluation limit (None: the method's; per element 200, or 120 when W or the shift is fitted)",
    ),
    spec("time_limit_s", OptionKind::Number, true, "the wall-clock limit per stage (s; None: none)"),
    spec("seed", OptionKind::Count, false, "the seed of the random starts, the swarm and the ambiguity assessment (default 0)"),
    spec("starts", OptionKind::Count, true, "L-BFGS starts (None: 20)"),
    spec("fit_amplitude", OptionKind::Flag, false, "fit one amplitude scale (the images' amplitude over the model's) for all images"),
    spec(
        "threshold",
        OptionKind::Number,
        false,
        "a rival solution makes the estimate ambiguous when it would leave less than this fraction of the ideal \
         focus after the estimate's correction (default 0.9)",
    ),
    spec(
        "noise_rad",
        OptionKind::Number,
        true,
        "the images' noise standard deviation (rad) where it is known (e.g. that of the difference of two reference \
         acquisitions over sqrt(2)); None: each image's floor from its background",
    ),
    spec(
        "prior",
        OptionKind::Values,
        true,
        "the predicted aberration (rad, per element or per group, in the sign of the estimate: subtracting it \
         corrects); the estimate is then the posterior optimum",
    ),
    spec("prior_std_rad", OptionKind::Number, true, "the expected error of each predicted phase (rad); required with a prior"),
    spec(
        "prior_correlation_mm",
        OptionKind::Number,
        true,
        "the length over which the prediction's errors are correlated (mm): a per-element estimate then corrects \
         the prediction by smooth fields only (Solin & Sarkka 2020)",
    ),
    spec(
        "prior_modes",
        OptionKind::Rows,
        true,
        "error modes of known shape (modes x elements, rad per standard deviation of each), their coefficients \
         fitted with the smooth corrections (per element, with prior_correlation_mm)",
    ),
    spec(
        "fit_nuisance",
        OptionKind::Names,
        false,
        "what else the images may differ in from the model, fitted with per-element phases: 'amplitude', \
         'broadening', 'registration_shift', 'background_phase' or 'all'; group estimates fit the amplitude only",
    ),
    spec(
        "prior_conflict_z",
        OptionKind::Number,
        true,
        "per element with a searched prior: the images conflict with the prediction (the prediction is \
         recommended) when their chi-squared at it lies more than this many standard deviations above what truths \
         within the prior's std give (default 3)",
    ),
    spec("suggest", OptionKind::Flag, false, "per element, also choose the next image to take (a focus shift)"),
];

/// The option named `name`, or an error listing them.
pub fn option_spec(name: &str) -> Result<&'static OptionSpec> {
    OPTIONS.iter().find(|o| o.name == name).ok_or_else(|| {
        let names: Vec<&str> = OPTIONS.iter().map(|o| o.name).collect();
        HasError::invalid(name, format!("is not an estimate option (options: {})", names.join(", ")))
    })
}

fn wrong(name: &str, kind: OptionKind) -> HasError {
    let want = match kind {
        OptionKind::Flag => "True or False",
        OptionKind::Count => "an integer >= 0",
        OptionKind::Number => "a finite number",
        OptionKind::Text => "a string",
        OptionKind::Names => "names",
        OptionKind::Values => "a one-dimensional array of real numbers",
        OptionKind::Rows => "a two-dimensional array of real numbers",
    };
    HasError::invalid(name, format!("must be {want}"))
}

impl EstimateRequest {
    /// The request of the defaults with `given` options set (each once; unknown names and values
    /// of the wrong kind are errors naming them), then [`EstimateRequest::check`]ed.
    pub fn from_options(given: &[(&str, OptionValue)]) -> Result<Self> {
        let mut r = EstimateRequest::default();
        let (mut mean, mut std, mut correlation, mut modes) = (None, None, None, None);
        for (k, (name, value)) in given.iter().enumerate() {
            let spec = option_spec(name)?;
            if given[..k].iter().any(|(n, _)| n == name) {
                return Err(HasError::invalid(*name, "is given twice"));
            }
            if value.kind() != spec.kind {
                return Err(wrong(name, spec.kind));
            }
            match (spec.name, value.clone()) {
                ("method", OptionValue::Text(m)) => r.method = Method::parse(&m)?,
                ("max_evaluations", OptionValue::Count(n)) => r.max_evaluations = Some(n as usize),
                ("time_limit_s", OptionValue::Number(t)) => r.time_limit_s = Some(t),
                ("seed", OptionValue::Count(s)) => r.seed = s,
                ("starts", OptionValue::Count(n)) => r.starts = Some(n as usize),
                ("fit_amplitude", OptionValue::Flag(f)) => r.fit_amplitude = f,
                ("threshold", OptionValue::Number(t)) => r.threshold = t,
                ("noise_rad", OptionValue::Number(n)) => r.noise_rad = Some(n),
                ("prior", OptionValue::Values(v)) => mean = Some(v),
                ("prior_std_rad", OptionValue::Number(s)) => std = Some(s),
                ("prior_correlation_mm", OptionValue::Number(l)) => correlation = Some(l * 1e-3),
                ("prior_modes", OptionValue::Rows(m)) => modes = Some(m),
                ("fit_nuisance", OptionValue::Names(n)) => r.nuisance = Nuisance::parse(&n)?,
                ("prior_conflict_z", OptionValue::Number(z)) => r.prior_conflict_z = z,
                ("suggest", OptionValue::Flag(f)) => r.suggest = f,
                (name, _) => return Err(HasError::invalid(name, "is declared in OPTIONS but not read by from_options")),
            }
        }
        r.prior = Prior::from_parts(mean, std, correlation, modes)?;
        if r.prior.is_none() && given.iter().any(|(n, _)| *n == "prior_conflict_z") {
            return Err(HasError::invalid("prior_conflict_z", "was given without a prior (it judges the images against one)"));
        }
        r.check()?;
        Ok(r)
    }

    /// The value of option `name` (`None`: unset, the method's default).
    pub fn option(&self, name: &str) -> Result<Option<OptionValue>> {
        use OptionValue as V;
        let prior = self.prior.as_ref();
        Ok(match option_spec(name)?.name {
            "method" => Some(V::Text(self.method.name().into())),
            "max_evaluations" => self.max_evaluations.map(|n| V::Count(n as u64)),
            "time_limit_s" => self.time_limit_s.map(V::Number),
            "seed" => Some(V::Count(self.seed)),
            "starts" => self.starts.map(|n| V::Count(n as u64)),
            "fit_amplitude" => Some(V::Flag(self.fit_amplitude)),
            "threshold" => Some(V::Number(self.threshold)),
            "noise_rad" => self.noise_rad.map(V::Number),
            "prior" => prior.map(|p| V::Values(p.mean().to_vec())),
            "prior_std_rad" => prior.map(|p| V::Number(p.std_rad())),
            "prior_correlation_mm" => prior.and_then(Prior::correlation_length).map(|l| V::Number(l * 1e3)),
            "prior_modes" => prior.map(Prior::modes).filter(|m| !m.is_empty()).map(|m| V::Rows(m.to_vec())),
            "fit_nuisance" => Some(V::Names(self.nuisance.names().into_iter().map(String::from).collect())),
            "prior_conflict_z" => prior.map(|_| V::Number(self.prior_conflict_z)),
            "suggest" => Some(V::Flag(self.suggest)),
            name => return Err(HasError::invalid(name, "is declared in OPTIONS but not written by option")),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_option_is_read_and_written_back() {
        let given: Vec<(&str, OptionValue)> = vec![
            ("method", OptionValue::Text("nelder-mead".into())),
            ("max_evaluations", OptionValue::Count(50)),
            ("time_limit_s", OptionValue::Number(3.0)),
            ("seed", OptionValue::Count(7)),
            ("fit_amplitude", OptionValue::Flag(true)),
            ("threshold", OptionValue::Number(0.8)),
            ("noise_rad", OptionValue::Number(0.02)),
            ("prior", OptionValue::Values(vec![0.1, 0.2])),
            ("prior_std_rad", OptionValue::Number(0.3)),
            ("prior_correlation_mm", OptionValue::Number(20.0)),
            ("prior_modes", OptionValue::Rows(vec![vec![1.0, -1.0]])),
            ("fit_nuisance", OptionValue::Names(vec!["amplitude".into()])),
            ("prior_conflict_z", OptionValue::Number(5.0)),
            ("suggest", OptionValue::Flag(true)),
        ];
        let r = EstimateRequest::from_options(&given).unwrap();
        assert_eq!(r.prior.as_ref().unwrap().correlation_length(), Some(0.02));
        for (name, value) in &given {
            let back = r.option(name).unwrap().unwrap();
            match (&back, value) {
                (OptionValue::Number(a), OptionValue::Number(b)) => assert!((a - b).abs() < 1e-12 * b.abs(), "{name}"),
                _ => assert_eq!(&back, value, "{name}"),
            }
        }
        // Every declared option is read and written: each alone, with a value of its kind, is
        // taken or refused by its own rule, never for want of a match arm.
        for o in OPTIONS {
            let value = match o.kind {
                OptionKind::Flag => OptionValue::Flag(true),
                OptionKind::Count => OptionValue::Count(3),
                OptionKind::Number => OptionValue::Number(0.5),
                OptionKind::Text => OptionValue::Text("lbfgs".into()),
                OptionKind::Names => OptionValue::Names(vec![]),
                OptionKind::Values => OptionValue::Values(vec![0.0]),
                OptionKind::Rows => OptionValue::Rows(vec![vec![0.0]]),
            };
            if let Err(e) = EstimateRequest::from_options(&[(o.name, value)]) {
                assert!(!e.to_string().contains("is declared in OPTIONS"), "{e}");
            }
        }
        let d = EstimateRequest::default();
        assert!(OPTIONS.iter().all(|o| d.option(o.name).unwrap().is_none() == o.optional));
        assert_eq!(EstimateRequest::from_options(&[]).unwrap(), d);
        // What option() gives back makes the same request again, with a prior and without.
        let again = |r: &EstimateRequest| {
            let given: Vec<(&str, OptionValue)> = OPTIONS.iter().filter_map(|o| r.option(o.name).unwrap().map(|v| (o.name, v))).collect();
            EstimateRequest::from_options(&given).unwrap()
        };
        assert_eq!(again(&d), d);
        let with_prior = EstimateRequest::from_options(&[
            ("prior", OptionValue::Values(vec![0.1, 0.2])),
            ("prior_std_rad", OptionValue::Number(0.3)),
            ("prior_conflict_z", OptionValue::Number(4.0)),
        ])
        .unwrap();
        assert_eq!(again(&with_prior), with_prior);
        let starts = EstimateRequest::from_options(&[("starts", OptionValue::Count(3))]).unwrap();
        assert_eq!(starts.option("starts").unwrap(), Some(OptionValue::Count(3)));
    }

    #[test]
    fn bad_options_are_refused_naming_them() {
        let err = |given: &[(&str, OptionValue)]| EstimateRequest::from_options(given).unwrap_err().to_string();
        assert!(err(&[("bogus", OptionValue::Flag(true))]).contains("bogus: is not an estimate option (options: method,"));
        assert!(err(&[("seed", OptionValue::Number(1.0))]).contains("seed: must be an integer >= 0"));
        assert!(err(&[("seed", OptionValue::Count(1)), ("seed", OptionValue::Count(2))]).contains("seed: is given twice"));
        assert!(err(&[("prior_std_rad", OptionValue::Number(0.3))]).contains("prior_std_rad: was given without a prior"));
        assert!(err(&[("prior_conflict_z", OptionValue::Number(4.0))]).contains("prior_conflict_z: was given without a prior"));
        assert!(err(&[("threshold", OptionValue::Number(1.5))]).contains("threshold: must be a fraction"));
        assert!(err(&[("method", OptionValue::Text("simplex".into()))]).contains("method"));
    }
}
