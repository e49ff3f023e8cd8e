//! How a long computation is watched and stopped, passed as one value: a flag another thread may
//! set to cancel it (the run then ends at its next check: with [`HasError::Interrupted`], or for
//! a search, `Estimator::run`, with its best point so far and `Stop::Interrupted`) and a progress
//! callback `(done, total)`. `Control::default()` watches nothing.

use crate::error::{HasError, Result};
use std::sync::atomic::{AtomicBool, Ordering};

/// A progress callback: `(done, total)` units of the current stage.
pub type Progress<'a> = &'a (dyn Fn(usize, usize) + Sync);

/// The cancel flag and the progress callback of one run (either may be absent).
#[derive(Clone, Copy, Default)]
pub struct Control<'a> {
    cancel: Option<&'a AtomicBool>,
    progress: Option<Progress<'a>>,
}

impl<'a> Control<'a> {
    /// Stopped when `flag` is set.
    pub fn with_cancel(self, flag: &'a AtomicBool) -> Self {
        Control { cancel: Some(flag), ..self }
    }

    /// Reports its progress to `report(done, total)`.
    pub fn with_progress(self, report: Progress<'a>) -> Self {
        Control { progress: Some(report), ..self }
    }

    /// The cancel flag, for code that checks it itself.
    pub fn cancel(&self) -> Option<&'a AtomicBool> {
        self.cancel
    }

    /// Whether the run was cancelled.
    pub fn cancelled(&self) -> bool {
        self.cancel.is_some_and(|c| c.load(Ordering::Relaxed))
    }

    /// [`HasError::Interrupted`] once the run was cancelled.
    pub fn check(&self) -> Result<()> {
        if self.cancelled() {
            return Err(HasError::Interrupted);
        }
        Ok(())
    }

    /// Reports `done` of `total`.
    pub fn report(&self, done: usize, total: usize) {
        if let Some(p) = self.progress {
            p(done, total);
        }
    }
}

impl std::fmt::Debug for Control<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Control").field("cancelled", &self.cancelled()).field("progress", &self.progress.is_some()).finish()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Mutex;

    #[test]
    fn a_control_reports_and_stops_only_when_asked() {
        let none = Control::default();
        none.report(1, 2);
        assert!(none.check().is_ok() && none.cancel().is_none());
        let (flag, seen) = (AtomicBool::new(false), Mutex::new(Vec::new()));
        let report = |d: usize, t: usize| seen.lock().unwrap().push((d, t));
        let c = Control::default().with_cancel(&flag).with_progress(&report);
        c.report(3, 4);
        assert!(c.check().is_ok());
        flag.store(true, Ordering::Relaxed);
        assert!(matches!(c.check(), Err(HasError::Interrupted)) && c.cancelled());
        assert_eq!(*seen.lock().unwrap(), vec![(3, 4)]);
    }
}
