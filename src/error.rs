//! The crate's error type.
//!
//! Library code never panics on bad input: every fallible function returns [`Result`]. The variants
//! separate "the caller passed something malformed" ([`Error::InvalidInput`]), "the input is well
//! formed but does not determine an answer" ([`Error::Degenerate`]) and "a calibration pipeline could
//! not find a trustworthy solution" ([`Error::Calibration`]). File problems are [`Error::Io`] (the
//! operating system refused: missing file, permissions) or [`Error::Format`] (the bytes are not a
//! valid point cloud). The Python layer maps the first two to `ValueError`, a calibration failure to
//! `lidarcal.CalibrationError`, [`Error::Io`] to `OSError` (its subclass for the kind, e.g.
//! `FileNotFoundError`) and [`Error::Format`] to `lidarcal.FileFormatError`, a `ValueError`.

/// Errors returned by lidarcal.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Error {
    /// Malformed input: wrong length, non-finite values, negative weights, bad parameters.
    #[error("invalid input: {0}")]
    InvalidInput(String),
    /// Well-formed input that does not determine the requested quantity
    /// (e.g. parallel vectors given to Kabsch).
    #[error("degenerate input: {0}")]
    Degenerate(String),
    /// A calibration could not produce a trustworthy result: `kind` says which way (callers can
    /// branch on it), `message` says why in words.
    #[error("calibration failed ({kind}): {message}")]
    Calibration {
        /// The kind of failure.
        kind: FailureKind,
        /// What was found, and what to change.
        message: String,
    },
    /// A numerical routine produced non-finite values (a bug or an extreme input).
    #[error("numerical failure: {0}")]
    Numerical(String),
    /// Reading or writing a file failed; the message names the path and the OS error.
    #[error("I/O error: {message}")]
    Io {
        /// What the operating system reported (`NotFound`, `PermissionDenied`, ...).
        kind: std::io::ErrorKind,
        /// The path and the OS message.
        message: String,
    },
    /// A file's contents are not a valid point cloud of its format (bad header, truncated data,
    /// a corrupt compressed block); the message names the file and the problem.
    #[error("malformed file: {0}")]
    Format(String),
}

/// Why a calibration refused to return a result: the kind a caller can branch on. Its
/// [`name`](FailureKind::name) is what Python's `CalibrationError.kind`, the CLI and the exports
/// carry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum FailureKind {
    /// More than one answer fits the data about equally well (a symmetric scene, a cube corner
    /// without `up`, identical structures side by side).
    Ambiguous,
    /// The data do not constrain every degree of freedom (a corridor, parallel poles, a straight
    /// street of ground and facades only).
    Unobservable,
    /// Fewer features than the method needs (planes, poles, bright points, overlapping points).
    TooFewFeatures,
    /// A pose was found but the clouds do not agree under it: the final check found it
    /// inconsistent, or no hypothesis verified.
    NoAgreement,
    /// The pose lies outside what the options allow (beyond `max_translation`, an absurd pole
    /// radius or fit residual).
    OutOfRange,
    /// The wall-clock budget ran out.
    TimeBudget,
    /// Two methods returned certified results that disagree beyond their uncertainty.
    InconsistentMethods,
}

impl FailureKind {
    /// Every kind, in declaration order.
    pub const ALL: [FailureKind; 7] = [
        FailureKind::Ambiguous,
        FailureKind::Unobservable,
        FailureKind::TooFewFeatures,
        FailureKind::NoAgreement,
        FailureKind::OutOfRange,
        FailureKind::TimeBudget,
        FailureKind::InconsistentMethods,
    ];

    /// `"ambiguous"`, `"unobservable"`, `"too_few_features"`, `"no_agreement"`,
    /// `"out_of_range"`, `"time_budget"` or `"inconsistent_methods"`.
    pub fn name(self) -> &'static str {
        match self {
            FailureKind::Ambiguous => "ambiguous",
            FailureKind::Unobservable => "unobservable",
            FailureKind::TooFewFeatures => "too_few_features",
            FailureKind::NoAgreement => "no_agreement",
            FailureKind::OutOfRange => "out_of_range",
            FailureKind::TimeBudget => "time_budget",
            FailureKind::InconsistentMethods => "inconsistent_methods",
        }
    }
}

impl std::fmt::Display for FailureKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl Error {
    /// An [`Error::Calibration`] of `kind`.
    pub fn calibration(kind: FailureKind, message: impl Into<String>) -> Self {
        Error::Calibration {
            kind,
            message: message.into(),
        }
    }

    /// The failure kind of an [`Error::Calibration`], `None` for the other variants.
    pub fn kind(&self) -> Option<FailureKind> {
        match self {
            Error::Calibration { kind, .. } => Some(*kind),
            _ => None,
        }
    }

    /// This error with `prefix: ` put before its message (the variant and kind kept).
    pub fn context(self, prefix: &str) -> Self {
        match self {
            Error::InvalidInput(m) => Error::InvalidInput(format!("{prefix}: {m}")),
            Error::Degenerate(m) => Error::Degenerate(format!("{prefix}: {m}")),
            Error::Calibration { kind, message } => Error::Calibration {
                kind,
                message: format!("{prefix}: {message}"),
            },
            Error::Numerical(m) => Error::Numerical(format!("{prefix}: {m}")),
            Error::Format(m) => Error::Format(format!("{prefix}: {m}")),
            Error::Io { kind, message } => Error::Io {
                kind,
                message: format!("{prefix}: {message}"),
            },
        }
    }
}

/// Shorthand for `Result<T, lidarcal::Error>`.
pub type Result<T> = std::result::Result<T, Error>;

/// `Err(InvalidInput)` "`name` must be finite and positive, got `value`" unless it is.
pub(crate) fn ensure_positive(name: &str, value: f64) -> Result<()> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(Error::InvalidInput(format!(
            "{name} must be finite and positive, got {value}"
        )))
    }
}

/// Returns `Err(InvalidInput)` naming `what` and the first offending index if any value is not finite.
pub(crate) fn ensure_finite<'a, I>(what: &str, values: I) -> Result<()>
where
    I: IntoIterator<Item = &'a f64>,
{
    let mut count = 0usize;
    let mut first = None;
    for (i, v) in values.into_iter().enumerate() {
        if !v.is_finite() {
            count += 1;
            first.get_or_insert(i);
        }
    }
    match first {
        None => Ok(()),
        Some(i) => Err(Error::InvalidInput(format!(
            "{what} contains {count} non-finite value(s) (NaN or inf), the first at flat index {i}"
        ))),
    }
}

/// Largest accepted magnitude of a point coordinate (metres): 100 000 km. No LiDAR return is that
/// far; such a value is corrupt data or a unit mistake. Below it every computation stays finite
/// and accurate (a single return at 3e8 m beside a normal scan leaves a calibration unchanged; one
/// at 1e9 m made it fail), and georeferenced clouds (UTM coordinates, ~1e7 m) pass.
pub const MAX_COORDINATE: f64 = 1e8;

/// [`ensure_finite`] for points, which must also lie within [`MAX_COORDINATE`] of the origin
/// (per coordinate). The message names `what`, the count and the first offending point.
pub(crate) fn ensure_points<'a, I>(what: &str, points: I) -> Result<()>
where
    I: IntoIterator<Item = &'a nalgebra::Point3<f64>>,
    I::IntoIter: Clone,
{
    let points = points.into_iter();
    ensure_finite(what, points.clone().flat_map(|p| p.coords.iter()))?;
    let far = |p: &nalgebra::Point3<f64>| p.coords.iter().any(|c| c.abs() > MAX_COORDINATE);
    let mut offending = points.enumerate().filter(|(_, p)| far(p));
    let Some((first, p)) = offending.next() else {
        return Ok(());
    };
    let count = offending.count() + 1;
    let worst = p.coords.amax();
    Err(Error::InvalidInput(format!(
        "{what} has {count} point(s) with a coordinate beyond +/-{MAX_COORDINATE:e} m, the \
         first at row {first} (|coordinate| = {worst:e}): no LiDAR return is that far (corrupt \
         values or wrong units)"
    )))
}
