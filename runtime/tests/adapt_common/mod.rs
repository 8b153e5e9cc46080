//! A periodic component whose section sleeps for a time set per quality level by the
//! test (the simulated work), so that time violations do not depend on the machine's
//! load; and the waits the adaptation tests share.

#![allow(dead_code, reason = "each test crate uses part of this module")]

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::time::Duration;

use coolbot::adapt::AdaptAction;
use coolbot::{
    AdaptConfig, Adaptation, Automaton, Component, Context, Fault, Handle, Monitor, PeriodicSpec,
    PortSet, Section, SectionResult, Spec, StateSpec, TimingSpec, Value,
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
    /// Raise the spec's first exception once, in the next section.
    pub fault: std::sync::atomic::AtomicBool,
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

const WORK: &[StateSpec] = &[StateSpec {
    name: "work",
    entry: false,
    exit: false,
    periodic: Some(PeriodicSpec { period: None }),
    on: &[],
    after: &[],
    may: &[],
}];

/// A 10 ms period that may stretch to 40 ms, two quality levels.
pub static SLEEPER: Spec = Spec {
    type_name: "Sleeper",
    doc: "Sleeps in its periodic section.",
    states: WORK,
    initial: 0,
    inputs: &[],
    outputs: &[],
    variables: &[],
    exceptions: &[],
    timing: TimingSpec {
        period: Some(ms(10)),
        max_period: Some(ms(40)),
        max_response: None,
        priority: 0,
        qualities: &["full", "reduced"],
    },
};

/// The same without a period interval (10 ms, quality levels only).
pub static FIXED: Spec = Spec {
    timing: TimingSpec {
        max_period: None,
        ..SLEEPER.timing
    },
    ..SLEEPER
};

/// [`SLEEPER`] with an exception whose continuity plan is `{ degrade; }`.
pub static PLANNED: Spec = Spec {
    exceptions: &[coolbot::ExceptionSpec {
        name: "noisy",
        description: "the readings are too noisy at this quality",
        plan: &[coolbot::PlanStep::Degrade],
    }],
    ..SLEEPER
};

struct Sleeper {
    spec: &'static Spec,
    load: Arc<Load>,
}

impl Automaton for Sleeper {
    fn spec(&self) -> &'static Spec {
        self.spec
    }
    fn start(&mut self, _cx: &mut Context) -> Result<(), Fault> {
        Ok(())
    }
    fn stop(&mut self, _cx: &mut Context) {}
    fn section(&mut self, _state: usize, _section: Section, cx: &mut Context) -> SectionResult {
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
            std::thread::sleep(Duration::from_micros(work));
        }
        self.load.runs.fetch_add(1, Ordering::SeqCst);
        if !self.spec.exceptions.is_empty() && self.load.fault.swap(false, Ordering::SeqCst) {
            return Err(Fault::exception(0, "too noisy"));
        }
        Ok(())
    }
    fn choose(&mut self, _state: usize, _cx: &mut Context) -> Option<usize> {
        None
    }
    fn exception(&mut self, _exception: usize, _message: &str, _cx: &mut Context) {}
    fn answer(&mut self, _output: usize, _cx: &mut Context) -> Result<(), Fault> {
        Ok(())
    }
    fn configure(&mut self, _configuration: &Value) -> Result<(), String> {
        Ok(())
    }
    fn set(&mut self, _variable: usize, _value: &Value) -> Result<(), String> {
        Err("no variables".to_owned())
    }
    fn get(&self, _variable: usize) -> Value {
        Value::Unit
    }
}

/// A sleeper named `name` on `spec`.
pub fn sleeper(name: &str, spec: &'static Spec, load: &Arc<Load>) -> Component {
    Component::new(
        name,
        Box::new(Sleeper {
            spec,
            load: Arc::clone(load),
        }),
        PortSet::new(),
    )
}

/// Detection tuned for tests: quick verdicts, a strict spare test; spare time judged
/// from the sections alone and no equalization, so that the outcomes do not depend on
/// what else the machine runs (the idle probe and equalization have tests of their
/// own: `src/idle.rs`, `src/adapt.rs`, `tests/equalize.rs`).
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

/// Wait for `pred` on `handle`'s monitor, panicking with the last monitor.
pub fn wait(handle: &Handle, what: &str, pred: impl Fn(&Monitor) -> bool) -> Monitor {
    handle
        .wait_for(pred, WAIT)
        .unwrap_or_else(|timeout| panic!("{what}: {timeout}: {:#?}", timeout.last))
}

/// Wait until `f` holds, polling (for counters no event announces).
pub fn eventually(what: &str, f: impl Fn() -> bool) {
    let deadline = std::time::Instant::now() + WAIT;
    while !f() {
        assert!(std::time::Instant::now() < deadline, "timed out: {what}");
        std::thread::sleep(ms(5));
    }
}

/// A supervisor with one state and no sections: the compound only coordinates.
pub struct Plain;

static PLAIN: Spec = Spec {
    type_name: "Group",
    doc: "",
    states: &[StateSpec {
        name: "supervising",
        entry: false,
        exit: false,
        periodic: None,
        on: &[],
        after: &[],
        may: &[],
    }],
    initial: 0,
    inputs: &[],
    outputs: &[],
    variables: &[],
    exceptions: &[],
    timing: TimingSpec::NONE,
};

impl coolbot::Supervisor for Plain {
    fn spec(&self) -> &'static Spec {
        &PLAIN
    }
}

/// A sleeper on [`SLEEPER`] with priority `priority` (negative: a nice value, which
/// any process may set) and the quick detection settings.
pub fn member(name: &str, priority: i32, load: &Arc<Load>) -> Component {
    sleeper(name, &SLEEPER, load)
        .with_timing(TimingSpec {
            priority,
            ..SLEEPER.timing
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
