//! Progress reporting and cancellation for long operations.
//!
//! Every long operation takes a `&Progress`, reports `(fraction, stage name)` through it, and
//! polls [`Progress::check`] often enough that a cancel takes effect within a fraction of a
//! second; `check` returns [`Error::Cancelled`] once cancelled.

use crate::error::{Error, Result};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// Callback receiving `(fraction in [0, 1], stage name)`.
pub type ProgressFn = dyn Fn(f32, &str) + Send + Sync;

/// A progress sink plus a shared cancel flag. Cheap to clone.
#[derive(Clone)]
pub struct Progress {
    cancel: Arc<AtomicBool>,
    report: Option<Arc<ProgressFn>>,
    /// Sub-range `[start, start + span]` of the parent's fraction this progress maps into.
    start: f32,
    span: f32,
}

impl Default for Progress {
    fn default() -> Self {
        Self::none()
    }
}

impl std::fmt::Debug for Progress {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Progress")
            .field("cancelled", &self.is_cancelled())
            .finish()
    }
}

impl Progress {
    /// Reports nowhere and is never cancelled (unless [`Progress::cancel`] is called).
    pub fn none() -> Self {
        Self {
            cancel: Arc::new(AtomicBool::new(false)),
            report: None,
            start: 0.0,
            span: 1.0,
        }
    }

    /// Reports to `report`.
    pub fn new(report: impl Fn(f32, &str) + Send + Sync + 'static) -> Self {
        Self {
            report: Some(Arc::new(report)),
            ..Self::none()
        }
    }

    /// Shares `flag` as the cancel flag (e.g. set by a Ctrl+C handler).
    pub fn with_cancel_flag(mut self, flag: Arc<AtomicBool>) -> Self {
        self.cancel = flag;
        self
    }

    /// The shared cancel flag.
    pub fn cancel_flag(&self) -> Arc<AtomicBool> {
        self.cancel.clone()
    }

    /// A child that maps its `[0, 1]` onto `[from, to]` of this one; shares the cancel flag.
    pub fn sub(&self, from: f32, to: f32) -> Progress {
        Progress {
            cancel: self.cancel.clone(),
            report: self.report.clone(),
            start: self.start + self.span * from,
            span: self.span * (to - from),
        }
    }

    /// Reports `fraction` (of this progress's range) of the stage `stage`.
    pub fn report(&self, fraction: f32, stage: &str) {
        if let Some(report) = &self.report {
            report(self.start + self.span * fraction.clamp(0.0, 1.0), stage);
        }
    }

    /// Asks the work to stop.
    pub fn cancel(&self) {
        self.cancel.store(true, Ordering::Relaxed);
    }

    /// True once cancelled.
    pub fn is_cancelled(&self) -> bool {
        self.cancel.load(Ordering::Relaxed)
    }

    /// `Err(Error::Cancelled)` once cancelled.
    pub fn check(&self) -> Result<()> {
        if self.is_cancelled() {
            Err(Error::Cancelled)
        } else {
            Ok(())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Mutex;

    #[test]
    fn sub_ranges_map_into_parent() {
        let seen = Arc::new(Mutex::new(Vec::new()));
        let s = seen.clone();
        let p = Progress::new(move |f, _| s.lock().unwrap().push(f));
        let child = p.sub(0.5, 1.0).sub(0.0, 0.5);
        child.report(1.0, "x");
        child.report(0.0, "x");
        assert_eq!(*seen.lock().unwrap(), vec![0.75, 0.5]);
        assert!(child.check().is_ok());
        p.cancel();
        assert!(matches!(child.check(), Err(Error::Cancelled)));
    }
}
