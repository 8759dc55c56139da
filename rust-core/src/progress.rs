//! Progress of a long build on stderr: a line once it has taken a second,
//! then every two seconds and at the end. A material builds its tables
//! while Mitsuba loads the scene, where stderr is what the user sees.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::Instant;

/// Counts the steps of a build that any thread may finish.
pub struct Progress {
    what: &'static str,
    total: usize,
    done: AtomicUsize,
    start: Instant,
    /// Seconds since `start` of the last line printed.
    last_line: Mutex<f64>,
}

impl Progress {
    pub fn new(what: &'static str, total: usize) -> Progress {
        Progress {
            what,
            total,
            done: AtomicUsize::new(0),
            start: Instant::now(),
            last_line: Mutex::new(f64::NEG_INFINITY),
        }
    }

    /// One more step is done.
    pub fn step(&self) {
        let done = self.done.fetch_add(1, Ordering::Relaxed) + 1;
        let elapsed = self.start.elapsed().as_secs_f64();
        if elapsed <= 1.0 {
            return;
        }
        let mut last = self.last_line.lock().unwrap_or_else(|e| e.into_inner());
        if elapsed - *last > 2.0 || done == self.total {
            *last = elapsed;
            eprintln!(
                "stam: {}: {:.0}% ({elapsed:.0} s)",
                self.what,
                100.0 * done as f64 / self.total.max(1) as f64
            );
        }
    }

    pub fn seconds(&self) -> f64 {
        self.start.elapsed().as_secs_f64()
    }
}
