//! Long computations off the GIL, stopped by Ctrl-C.

use has_core::control::Control;
use pyo3::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;

/// Runs `work` on a worker thread with the GIL released, checking for Ctrl-C (Python signals)
/// every 50 ms; a signal sets `cancel` (which the work polls) and is raised once it returns.
pub(crate) fn run_interruptible<T: Send>(py: Python<'_>, cancel: &AtomicBool, work: impl FnOnce() -> T + Send) -> PyResult<T> {
    let mut signal: Option<PyErr> = None;
    let out = py.detach(|| {
        std::thread::scope(|scope| {
            let worker = scope.spawn(work);
            while !worker.is_finished() {
                std::thread::sleep(std::time::Duration::from_millis(50));
                if signal.is_none() {
                    if let Err(e) = Python::attach(|py| py.check_signals()) {
                        cancel.store(true, Ordering::Relaxed);
                        signal = Some(e);
                    }
                }
            }
            worker.join()
        })
    });
    if let Some(e) = signal {
        return Err(e);
    }
    out.map_err(|_| crate::error::worker_panicked())
}

/// [`run_interruptible`] with a `Control` that reports `(done, total)` to `progress`, a Python
/// callable (an exception it raises cancels the run and is raised here, as is Ctrl-C).
pub(crate) fn run_with_progress<T: Send>(
    py: Python<'_>,
    progress: Option<&Py<PyAny>>,
    work: impl FnOnce(Control<'_>) -> T + Send,
) -> PyResult<T> {
    let cancel = AtomicBool::new(false);
    let failed: Mutex<Option<PyErr>> = Mutex::new(None);
    let report = |done: usize, total: usize| {
        if let Some(f) = progress {
            if let Err(e) = Python::attach(|py| f.call1(py, (done, total)).map(drop)) {
                failed.lock().unwrap_or_else(|p| p.into_inner()).get_or_insert(e);
                cancel.store(true, Ordering::Relaxed);
            }
        }
    };
    let out = run_interruptible(py, &cancel, || work(Control::default().with_cancel(&cancel).with_progress(&report)))?;
    if let Some(e) = failed.into_inner().unwrap_or_else(|p| p.into_inner()) {
        return Err(e);
    }
    Ok(out)
}
