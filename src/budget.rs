//! Wall-clock budgets: a calibration given `time_budget` stops with an error, instead of running
//! on, when a pathological input (a huge cloud with a clustering tolerance that joins everything,
//! RANSAC on a huge noisy cloud) would take longer.
//!
//! The long loops (RANSAC batches, the clustering's breadth-first search, the robust refinement's
//! rounds, the pole hypotheses) check the [`Deadline`] between units of work of at most a few
//! milliseconds, so a run stops shortly after its budget. A budget never changes a result: the
//! run either finishes with exactly the answer it would give without one, or fails with
//! [`Error::Calibration`] naming the stage and the time spent. (Only whether it fails depends on
//! the machine's speed.)
//!
//! ```
//! use std::time::Duration;
//! use lidarcal::budget::Deadline;
//! let unlimited = Deadline::new(None);
//! assert!(unlimited.check("anything").is_ok());
//! let spent = Deadline::new(Some(Duration::ZERO));
//! std::thread::sleep(Duration::from_millis(1));
//! let err = spent.check("clustering").unwrap_err().to_string();
//! assert!(err.contains("time budget of 0.000 s exhausted during clustering"), "{err}");
//! ```

use std::time::{Duration, Instant};

use crate::error::{Error, FailureKind, Result};

/// A start time and an optional budget; [`Deadline::check`] fails once the budget is spent.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Deadline {
    start: Instant,
    budget: Option<Duration>,
}

impl Deadline {
    /// A deadline `budget` from now (`None`: never).
    pub fn new(budget: Option<Duration>) -> Self {
        Deadline {
            start: Instant::now(),
            budget,
        }
    }

    /// `Err(Error::Calibration)` naming `stage` when the budget is spent.
    pub fn check(&self, stage: &str) -> Result<()> {
        let Some(budget) = self.budget else {
            return Ok(());
        };
        let elapsed = self.start.elapsed();
        if elapsed > budget {
            return Err(Error::calibration(
                FailureKind::TimeBudget,
                format!(
                "time budget of {:.3} s exhausted during {stage} (after {:.3} s): the input is \
                 too large or pathological for these options; raise the budget, subsample the \
                 clouds or tighten the options",
                budget.as_secs_f64(),
                elapsed.as_secs_f64()
            ),
            ));
        }
        Ok(())
    }
}

/// Checks a budget given in seconds (finite and positive) and converts it.
pub fn budget_from_secs(seconds: Option<f64>) -> Result<Option<Duration>> {
    seconds
        .map(|s| {
            Duration::try_from_secs_f64(s)
                .ok()
                .filter(|_| s > 0.0)
                .ok_or_else(|| {
                    Error::InvalidInput(format!(
                        "time_budget_s must be finite and positive, got {s}"
                    ))
                })
        })
        .transpose()
}
