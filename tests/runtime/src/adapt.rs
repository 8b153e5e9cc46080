//! The adaptation tests' shared parts (`adapt.rs`, `adapt_hierarchy.rs`): the
//! behaviour of the periodic sleepers of `cool/adapt.cool`, whose section sleeps for a
//! time set per quality level by the test (the simulated work), so that time
//! violations do not depend on the machine's load; and the waits the tests share.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::time::Duration;

use coolbot::adapt::AdaptAction;
use coolbot::{
    AdaptConfig, Adaptation, Clock, Component, Handle, Monitor, SectionResult, System, TimingSpec,
    VirtualClock,
};

use crate::generated::{
    adapt_fixed_sleeper, adapt_planned_sleeper, adapt_sleeper, adapt_steady_sleeper,
};

/// Generous: the machine is shared and loaded.
pub const WAIT: Duration = Duration::from_secs(60);

pub const fn ms(n: u64) -> Duration {
    Duration::from_millis(n)
}

/// The simulated work and what the section saw.
#[derive(Debug, Default)]
pub struct Load {
    /// Microseconds slept by the section, per quality level (0, 1, 2).
    pub work: [AtomicU64; 3],
    /// Sections run.
    pub runs: AtomicU64,
    /// The longest period and the lowest quality (highest index) the section saw.
    pub longest_period: AtomicU64,
    pub lowest_quality: AtomicUsize,
    /// The period the last section saw, in microseconds.
    pub last_period: AtomicU64,
    /// Busy-wait instead of sleeping (CPU work rather than waiting).
    pub spin: std::sync::atomic::AtomicBool,
    /// Raise the component's exception (`AdaptPlannedSleeper`'s `noisy`) once, in the
    /// next section.
    pub fault: std::sync::atomic::AtomicBool,
    /// A section is taking its work's time now.
    pub busy: std::sync::atomic::AtomicBool,
}

impl Load {
    pub fn new() -> Arc<Load> {
        Arc::new(Load::default())
    }

    /// Work per quality level, in milliseconds.
    pub fn set(&self, work: [u64; 3]) {
        for (slot, ms) in self.work.iter().zip(work) {
            slot.store(ms * 1000, Ordering::SeqCst);
        }
    }

    pub fn runs(&self) -> u64 {
        self.runs.load(Ordering::SeqCst)
    }
}

/// The sleepers' behaviour: each periodic section sleeps (or spins) for the work
/// `load` sets for the quality level it runs at, and records what it saw.
pub struct Sleeping {
    load: Arc<Load>,
}

impl Sleeping {
    pub fn new(load: &Arc<Load>) -> Sleeping {
        Sleeping {
            load: Arc::clone(load),
        }
    }

    fn work(&mut self, cx: &mut coolbot::Context) {
        let quality = cx.quality().min(2);
        let period = cx.period().unwrap_or_default();
        let micros = u64::try_from(period.as_micros()).unwrap_or(u64::MAX);
        self.load.longest_period.fetch_max(micros, Ordering::SeqCst);
        self.load.last_period.store(micros, Ordering::SeqCst);
        self.load
            .lowest_quality
            .fetch_max(quality, Ordering::SeqCst);
        let work = self.load.work[quality].load(Ordering::SeqCst);
        if self.load.spin.load(Ordering::SeqCst) {
            let until = std::time::Instant::now() + Duration::from_micros(work);
            while std::time::Instant::now() < until {
                std::hint::spin_loop();
            }
        } else {
            // The clock's time: a sleep on the real clock, the virtual clock's time
            // in a test that steps it.
            self.load.busy.store(true, Ordering::SeqCst);
            cx.spend(Duration::from_micros(work));
            self.load.busy.store(false, Ordering::SeqCst);
        }
        self.load.runs.fetch_add(1, Ordering::SeqCst);
    }
}

impl adapt_sleeper::Behavior for Sleeping {
    fn work_periodic(&mut self, cx: &mut adapt_sleeper::Cx<'_>) -> SectionResult {
        self.work(cx.rt);
        Ok(())
    }
}

impl adapt_fixed_sleeper::Behavior for Sleeping {
    fn work_periodic(&mut self, cx: &mut adapt_fixed_sleeper::Cx<'_>) -> SectionResult {
        self.work(cx.rt);
        Ok(())
    }
}

impl adapt_steady_sleeper::Behavior for Sleeping {
    fn work_periodic(&mut self, cx: &mut adapt_steady_sleeper::Cx<'_>) -> SectionResult {
        self.work(cx.rt);
        Ok(())
    }
}

impl adapt_planned_sleeper::Behavior for Sleeping {
    fn work_periodic(&mut self, cx: &mut adapt_planned_sleeper::Cx<'_>) -> SectionResult {
        self.work(cx.rt);
        if self.load.fault.swap(false, Ordering::SeqCst) {
            return Err(coolbot::Fault::exception(
                adapt_planned_sleeper::Exception::Noisy.index(),
                "too noisy",
            ));
        }
        Ok(())
    }

    fn on_noisy(&mut self, _cx: &mut adapt_planned_sleeper::Cx<'_>, _message: &str) {}
}

/// An `AdaptSleeper` named `name`.
pub fn sleeper(name: &str, load: &Arc<Load>) -> Component {
    adapt_sleeper::component(name, Sleeping::new(load))
}

/// An `AdaptFixedSleeper` named `name`.
pub fn fixed_sleeper(name: &str, load: &Arc<Load>) -> Component {
    adapt_fixed_sleeper::component(name, Sleeping::new(load))
}

/// An `AdaptSteadySleeper` named `name`.
pub fn steady_sleeper(name: &str, load: &Arc<Load>) -> Component {
    adapt_steady_sleeper::component(name, Sleeping::new(load))
}

/// An `AdaptPlannedSleeper` named `name`.
pub fn planned_sleeper(name: &str, load: &Arc<Load>) -> Component {
    adapt_planned_sleeper::component(name, Sleeping::new(load))
}

/// Detection tuned for tests: quick verdicts, a strict spare test; spare time judged
/// from the sections alone and no equalization, so that the outcomes do not depend on
/// what else the machine runs (the idle probe and equalization have tests of their
/// own: `runtime/src/idle.rs`, `runtime/src/adapt.rs`, `equalize.rs`).
pub fn quick() -> AdaptConfig {
    AdaptConfig {
        violations: 2,
        window: 3,
        spare_ratio: 0.5,
        spare_periods: 4,
        hold_periods: 2,
        equalize: false,
        idle_probe: false,
        ..AdaptConfig::default()
    }
}

/// The level changes (degradations and promotions) in a history, with the component.
pub fn moves(history: &[Adaptation]) -> Vec<(String, AdaptAction, u32, u32)> {
    history
        .iter()
        .filter(|step| matches!(step.action, AdaptAction::Degraded | AdaptAction::Promoted))
        .map(|step| (step.component.clone(), step.action, step.from, step.to))
        .collect()
}

/// A system on a fresh virtual clock.
pub fn on_virtual_clock() -> (System, Arc<VirtualClock>) {
    let clock = VirtualClock::new();
    (System::with_clock(Clock::virtual_clock(&clock)), clock)
}

/// `component` added to a system on a fresh virtual clock, and run.
pub fn running_on_virtual_clock(component: Component) -> (System, Handle, Arc<VirtualClock>) {
    let (mut system, clock) = on_virtual_clock();
    let handle = system.add(component).expect("add");
    system.run_all().expect("run");
    (system, handle, clock)
}

/// The virtual time a test steps at most before it gives up on a condition.
pub const VIRTUAL_LIMIT: Duration = Duration::from_secs(120);

/// Step `clock` a millisecond at a time until `pred` holds of `handle`'s monitor;
/// panics with the last monitor after [`VIRTUAL_LIMIT`] of virtual time.
pub fn step_until(
    clock: &VirtualClock,
    handle: &Handle,
    what: &str,
    pred: impl Fn(&Monitor) -> bool,
) -> Monitor {
    let mut last = handle.snapshot();
    step_until_true(clock, what, || {
        last = handle.snapshot();
        pred(&last)
    });
    last
}

/// Step `clock` a millisecond at a time until `f` holds; panics after
/// [`VIRTUAL_LIMIT`] of virtual time.
pub fn step_until_true(clock: &VirtualClock, what: &str, mut f: impl FnMut() -> bool) {
    let until = clock.elapsed() + VIRTUAL_LIMIT;
    while !f() {
        assert!(
            clock.elapsed() < until,
            "not {what} within {VIRTUAL_LIMIT:?} of the virtual clock"
        );
        clock.advance(ms(1)).expect("settled");
    }
}

/// Step `clock` until no section of a component working `load` is taking its time:
/// the component has settled and starts nothing before the clock moves again, so a
/// command to it is taken at once (during a section taking the clock's time, it would
/// wait for the clock).
pub fn at_rest(clock: &VirtualClock, load: &Load) {
    step_until_true(clock, "the section's work done", || {
        !load.busy.load(Ordering::SeqCst)
    });
}

/// Wait until `f` holds, polling (for counters no event announces).
pub fn eventually(what: &str, f: impl Fn() -> bool) {
    let deadline = std::time::Instant::now() + WAIT;
    while !f() {
        assert!(std::time::Instant::now() < deadline, "timed out: {what}");
        std::thread::sleep(ms(5));
    }
}

/// An `AdaptSleeper` with priority `priority` (negative: a nice value, which any
/// process may set; a description's priorities are `0..=99`) and the quick detection
/// settings.
pub fn member(name: &str, priority: i32, load: &Arc<Load>) -> Component {
    sleeper(name, load)
        .with_timing(TimingSpec {
            priority,
            ..adapt_sleeper::SPEC.timing
        })
        .with_adaptation(quick())
}

/// Replays a compound's adaptation steps (top level, width 1) and checks the
/// homogeneity interval: an instance is degraded only up to the current maximum
/// level, and the maximum is raised only when every instance is at it (or at its own
/// top, `max`). Returns the instances' levels at the end.
pub fn check_homogeneity(
    compound: &str,
    members: &[&str],
    max: u32,
    steps: &[Adaptation],
) -> Vec<u32> {
    let mut levels = vec![0u32; members.len()];
    let mut cap = 1;
    for step in steps {
        let position = members.iter().position(|m| *m == step.component);
        match (step.action, position) {
            (AdaptAction::CapRaised, None) if step.component == compound => {
                assert_eq!(step.from, cap, "{step}");
                assert!(
                    levels.iter().all(|l| *l >= cap || *l == max),
                    "cap raised with an instance below it: {levels:?}, {step}"
                );
                cap = step.to;
            }
            (AdaptAction::FloorLowered, None) if step.component == compound => {
                cap = step.to + 1;
            }
            (AdaptAction::Degraded, Some(index)) => {
                assert_eq!(step.from, levels[index], "{step}");
                assert!(step.to <= cap, "degraded above the cap {cap}: {step}");
                levels[index] = step.to;
            }
            (AdaptAction::Promoted, Some(index)) => {
                assert_eq!(step.from, levels[index], "{step}");
                levels[index] = step.to;
            }
            _ => {}
        }
    }
    levels
}
