//! One error type for the crate: every fallible public function returns [`Result`].

use std::fmt;

/// What went wrong, with the name of the parameter or file it concerns.
#[derive(Debug, Clone, PartialEq)]
pub enum HasError {
    /// A parameter is out of range, non-finite, of the wrong length, ...
    InvalidParameter { name: String, reason: String },
    /// A file could not be found.
    FileNotFound { path: String },
    /// A file exists but could not be read or parsed.
    BadFile { path: String, reason: String },
    /// The request would need more memory than the budget of [`crate::memory::limit`].
    TooLarge { what: String, bytes: u64, limit: u64, suggestion: String },
    /// A long computation was stopped through its cancel flag.
    Interrupted,
}

impl HasError {
    /// Shorthand for [`HasError::InvalidParameter`].
    pub fn invalid(name: impl Into<String>, reason: impl Into<String>) -> Self {
        HasError::InvalidParameter { name: name.into(), reason: reason.into() }
    }
}

impl fmt::Display for HasError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            HasError::InvalidParameter { name, reason } => write!(f, "{name}: {reason}"),
            HasError::FileNotFound { path } => write!(f, "{path}: no such file"),
            HasError::BadFile { path, reason } => write!(f, "{path}: {reason}"),
            HasError::TooLarge { what, bytes, limit, suggestion } => write!(
                f,
                "{what} needs {:.1} GiB, more than the {:.1} GiB this machine has for it; {suggestion}",
                *bytes as f64 / 2f64.powi(30),
                *limit as f64 / 2f64.powi(30)
            ),
            HasError::Interrupted => write!(f, "interrupted"),
        }
    }
}

impl std::error::Error for HasError {}

/// Result with [`HasError`].
pub type Result<T> = std::result::Result<T, HasError>;

/// Checks that `value` is finite and strictly positive.
pub fn require_positive(name: &str, value: f64) -> Result<()> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(HasError::invalid(name, format!("must be a finite number > 0, got {value}")))
    }
}

/// Checks that `value` is finite and >= 0.
pub fn require_non_negative(name: &str, value: f64) -> Result<()> {
    if value.is_finite() && value >= 0.0 {
        Ok(())
    } else {
        Err(HasError::invalid(name, format!("must be a finite number >= 0, got {value}")))
    }
}

/// Checks that `value` lies in `[lo, hi]` (finite); `why` says where the range comes from.
pub fn require_in_range(name: &str, value: f64, lo: f64, hi: f64, why: &str) -> Result<()> {
    if value.is_finite() && (lo..=hi).contains(&value) {
        Ok(())
    } else {
        Err(HasError::invalid(name, format!("must be between {lo} and {hi} ({why}), got {value}")))
    }
}

/// Checks that every value is finite.
pub fn require_finite(name: &str, values: &[f64]) -> Result<()> {
    match values.iter().position(|v| !v.is_finite()) {
        None => Ok(()),
        Some(i) => Err(HasError::invalid(name, format!("value {i} is not finite ({})", values[i]))),
    }
}
