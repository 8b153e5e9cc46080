//! Two periodic components that start in phase on one core (`equalize.rs`; the bench
//! `runtime/benches/equalize.rs` runs the same on its own copy): each section of the
//! generated `EqualizeSpinner` spins until its thread used `WORK` of CPU time and
//! records how late it started against its deadline (`Context::deadline`) and how
//! late it ended.

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use coolbot::{AdaptConfig, Component, SectionResult};

use crate::generated::equalize_spinner;

/// The period of both components (`EqualizeSpinner`'s).
pub const PERIOD: Duration = Duration::from_millis(20);
/// The CPU each section needs: together 60 % of one core, so that in phase one waits.
pub const WORK: Duration = Duration::from_millis(6);

/// One section: when it started, how late, and how long after its deadline it ended.
pub type Starts = Arc<Mutex<Vec<(Instant, Duration, Duration)>>>;

/// How many sections `starts` holds.
pub fn count(starts: &Starts) -> usize {
    starts
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
        .len()
}

/// `EqualizeSpinner`'s behaviour: spin for `WORK` of thread CPU time, record.
pub struct Spinning(Starts);

impl equalize_spinner::Behavior for Spinning {
    fn spinning_periodic(&mut self, cx: &mut equalize_spinner::Cx<'_>) -> SectionResult {
        let now = Instant::now();
        let deadline = cx.rt.deadline().unwrap_or(now);
        let cpu = cpu_time::ThreadTime::now();
        while cpu.elapsed() < WORK {
            std::hint::spin_loop();
        }
        self.0
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .push((
                now,
                now.saturating_duration_since(deadline),
                deadline.elapsed(),
            ));
        Ok(())
    }
}

/// A spinner named `name`, recording into `starts`, with adaptation on (nothing to
/// degrade: one period, one quality) and `equalize` as given.
pub fn spinner(name: &str, starts: &Starts, equalize: bool) -> Component {
    equalize_spinner::component(name, Spinning(Arc::clone(starts))).with_adaptation(AdaptConfig {
        equalize,
        ..AdaptConfig::on()
    })
}

/// Pin the calling thread, and so every thread it spawns later, to CPU 0.
#[cfg(target_os = "linux")]
pub fn pin_to_one_core() {
    let mut cpus = rustix::thread::CpuSet::new();
    cpus.set(0);
    rustix::thread::sched_setaffinity(None, &cpus).expect("pin to CPU 0");
}
