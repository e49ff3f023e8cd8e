//! One error type for the crate: every fallible public function returns [`Result`].

/// What went wrong, with the name of the parameter or file it concerns. New kinds may be added
/// (`#[non_exhaustive]`): match with a wildcard arm.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum HasError {
    /// A parameter is out of range, non-finite, of the wrong length, ...
    #[error("{name}: {reason}")]
    InvalidParameter {
        /// The parameter, as named in scenario files or the API (e.g. `grid.spacing_mm`).
        name: String,
        /// What is wrong with it and what is allowed.
        reason: String,
    },
    /// A file could not be found.
    #[error("{path}: no such file{}", .named_by.as_deref().map(|n| format!(" ({n})")).unwrap_or_default())]
    FileNotFound {
        /// The path as given.
        path: String,
        /// What names the file, when that is not its reader's caller (e.g. a scenario's key).
        named_by: Option<String>,
    },
    /// A file exists but could not be read or parsed.
    #[error("{path}: {reason}")]
    BadFile {
        /// The path as given.
        path: String,
        /// The reader's or parser's message, on one line.
        reason: String,
    },
    /// The request would need more memory than the budget of [`crate::memory::limit`].
    #[error("{what} needs {:.1} GiB, more than the {:.1} GiB this machine has for it; {suggestion}", gib(*.bytes), gib(*.limit))]
    TooLarge {
        /// The request, e.g. `a 2048 x 2048 grid`.
        what: String,
        /// Memory it would need, bytes.
        bytes: u64,
        /// The budget, bytes.
        limit: u64,
        /// How to make the request smaller.
        suggestion: String,
    },
    /// A long computation was stopped through its cancel flag.
    #[error("interrupted")]
    Interrupted,
}

/// Bytes in GiB.
fn gib(bytes: u64) -> f64 {
    bytes as f64 / 2f64.powi(30)
}

impl HasError {
    /// Shorthand for [`HasError::InvalidParameter`].
    pub fn invalid(name: impl Into<String>, reason: impl Into<String>) -> Self {
        HasError::InvalidParameter { name: name.into(), reason: reason.into() }
    }

    /// The same error about parameter `name`, for a caller that knows the parameter by another
    /// name (e.g. a command-line option); other kinds are returned unchanged.
    pub fn naming(self, name: &str) -> Self {
        match self {
            HasError::InvalidParameter { reason, .. } => HasError::invalid(name, reason),
            e => e,
        }
    }

    /// A missing file's error saying what names it (`named_by`, e.g. "the `[ct] file` of
    /// scenario \"head\""); other errors unchanged.
    pub fn named_by(self, named_by: impl Into<String>) -> Self {
        match self {
            HasError::FileNotFound { path, .. } => HasError::FileNotFound { path, named_by: Some(named_by.into()) },
            e => e,
        }
    }

    /// A failed read of the file `path`: [`HasError::FileNotFound`] if it does not exist, else
    /// [`HasError::BadFile`] with the system's message.
    pub fn reading(path: &str, e: &std::io::Error) -> Self {
        match e.kind() {
            std::io::ErrorKind::NotFound => HasError::FileNotFound { path: path.to_string(), named_by: None },
            _ => HasError::BadFile { path: path.to_string(), reason: e.to_string() },
        }
    }
}

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
