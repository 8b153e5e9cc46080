//! Two periodic components that start in phase on one core (the equalization bench;
//! the test, `tests/runtime/tests/equalize.rs`, runs the same on generated components):
//! each section spins until its thread used `WORK` of CPU time and records how
//! late it started against its deadline (`Context::deadline`) and how late it ended.

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use coolbot::{
    AdaptConfig, Automaton, Component, Context, PortSet, Section, SectionResult, Spec, StateSpec,
    TimingSpec,
};

/// The period of both components.
pub const PERIOD: Duration = Duration::from_millis(20);
/// The CPU each section needs: together 60 % of one core, so that in phase one waits.
pub const WORK: Duration = Duration::from_millis(6);

static SPINNER: Spec = Spec::new("Spinner", "")
    .with_states(&[StateSpec::new("spinning").with_periodic(None)])
    .with_timing(TimingSpec {
        // No period interval: adaptation (turned on by `spinner`) has no period to
        // stretch, so both keep the same period whatever the load.
        period: Some(PERIOD),
        max_period: None,
        max_response: None,
        priority: 0,
        qualities: &[],
    });

/// One section: when it started, how late, and how long after its deadline it ended.
pub type Starts = Arc<Mutex<Vec<(Instant, Duration, Duration)>>>;

/// How many sections `starts` holds.
#[allow(dead_code, reason = "the bench does not count (the test's copy does)")]
pub fn count(starts: &Starts) -> usize {
    starts
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
        .len()
}

struct Spinner(Starts);

impl Automaton for Spinner {
    fn spec(&self) -> &'static Spec {
        &SPINNER
    }
    fn section(&mut self, _state: usize, _section: Section, cx: &mut Context) -> SectionResult {
        let now = Instant::now();
        let deadline = cx.deadline().unwrap_or(now);
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
    Component::new(name, Box::new(Spinner(Arc::clone(starts))), PortSet::new()).with_adaptation(
        AdaptConfig {
            equalize,
            ..AdaptConfig::on()
        },
    )
}

/// Pin the calling thread, and so every thread it spawns later, to CPU 0.
pub fn pin_to_one_core() {
    let mut cpus = rustix::thread::CpuSet::new();
    cpus.set(0);
    rustix::thread::sched_setaffinity(None, &cpus).expect("pin to CPU 0");
}
