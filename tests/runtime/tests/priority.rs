//! `priority` applied to a component's OS thread (`docs/runtime.md`, "Priority"): what
//! the monitoring port publishes, and what the thread really got, read on the thread
//! itself (its nice value through `getpriority`, its scheduling policy).
//!
//! Raising a thread's priority needs privileges (`CAP_SYS_NICE`) that a container may
//! not grant: those tests accept either outcome and check that what is published is
//! what the thread has. Lowering it (a negative priority: a higher nice value) is
//! always permitted, so it is checked exactly.
#![cfg(target_os = "linux")]

use std::sync::Arc;
use std::sync::atomic::{AtomicI32, AtomicU64, Ordering};
use std::time::Duration;

use coolbot::crossbeam_channel::Receiver;
use coolbot::{
    Command, Handle, MonitorEvent, OsPriority, SectionResult, State, System, TimingSpec,
};
use coolbot_runtime_tests::generated::prio_reporter;
use rustix::process::getpriority_process;
use rustix::thread::gettid;
use thread_priority::{RealtimeThreadSchedulePolicy, ThreadSchedulePolicy};

const WAIT: Duration = Duration::from_secs(10);

/// What the component's thread reports about itself from its periodic section.
#[derive(Default)]
struct Seen {
    nice: AtomicI32,
    /// 1 if the thread is under `SCHED_RR`, 0 if not, -1 if unknown.
    round_robin: AtomicI32,
    /// Activations so far (a reading is fresh once this moved past a command).
    activations: AtomicU64,
}

impl Seen {
    /// Wait for two more activations (so the next reading is taken after now).
    fn fresh(&self) -> (i32, bool) {
        let from = self.activations.load(Ordering::SeqCst);
        let deadline = std::time::Instant::now() + WAIT;
        while self.activations.load(Ordering::SeqCst) < from + 2 {
            assert!(
                std::time::Instant::now() < deadline,
                "the component stopped"
            );
            std::thread::sleep(Duration::from_millis(1));
        }
        (
            self.nice.load(Ordering::SeqCst),
            self.round_robin.load(Ordering::SeqCst) == 1,
        )
    }
}

struct Reporter {
    seen: Arc<Seen>,
}

impl prio_reporter::Behavior for Reporter {
    fn report_periodic(&mut self, _cx: &mut prio_reporter::Cx<'_>) -> SectionResult {
        let nice = getpriority_process(Some(gettid())).expect("getpriority");
        let round_robin = match thread_priority::thread_schedule_policy() {
            Ok(ThreadSchedulePolicy::Realtime(RealtimeThreadSchedulePolicy::RoundRobin)) => 1,
            Ok(_) => 0,
            Err(_) => -1,
        };
        self.seen.nice.store(nice, Ordering::SeqCst);
        self.seen.round_robin.store(round_robin, Ordering::SeqCst);
        self.seen.activations.fetch_add(1, Ordering::SeqCst);
        Ok(())
    }
}

/// `PrioReporter`'s timing (`cool/priority.cool`: priority 0) with `priority`.
fn priority(priority: i32) -> TimingSpec {
    TimingSpec {
        priority,
        ..prio_reporter::SPEC.timing
    }
}

/// The nice value new threads of this process inherit (the test thread's own).
fn base_nice() -> i32 {
    getpriority_process(Some(gettid())).expect("getpriority")
}

fn run(timing: TimingSpec) -> (System, Handle, Arc<Seen>) {
    let seen = Arc::new(Seen::default());
    let reporter = Reporter {
        seen: Arc::clone(&seen),
    };
    let mut system = System::new();
    let handle = system
        .add(prio_reporter::component("reporter", reporter).with_timing(timing))
        .expect("add");
    system.run_all().expect("run");
    (system, handle, seen)
}

/// The `OsPriority` events received so far.
fn priority_events(events: &Receiver<MonitorEvent>) -> Vec<OsPriority> {
    events
        .try_iter()
        .filter_map(|event| match event {
            MonitorEvent::OsPriority(applied) => Some(applied),
            _ => None,
        })
        .collect()
}

#[test]
fn priority_zero_leaves_the_thread_as_created() {
    let base = base_nice();
    let (system, handle, seen) = run(prio_reporter::SPEC.timing);
    assert_eq!(handle.snapshot().os_priority, OsPriority::Inherited);
    assert_eq!(seen.fresh(), (base, false));
    assert!(system.shutdown().clean());
}

#[test]
fn negative_priority_raises_the_nice_value_and_set_priority_changes_it() {
    let base = base_nice();
    let (system, handle, seen) = run(priority(-3));
    let first = (base + 3).min(19);
    let snapshot = handle.snapshot();
    assert_eq!(snapshot.priority, -3);
    assert_eq!(snapshot.os_priority, OsPriority::Nice(first));
    assert_eq!(seen.fresh(), (first, false));

    // At run time, through the control port: published with an event when the nice
    // value changes (not when the process already runs at the maximum, 19).
    let events = handle.subscribe();
    handle
        .command(Command::SetPriority(-7))
        .expect("set priority");
    let expected = (base + 7).min(19);
    let snapshot = handle.snapshot();
    assert_eq!(snapshot.priority, -7);
    assert_eq!(snapshot.os_priority, OsPriority::Nice(expected));
    let published = if expected == first {
        Vec::new()
    } else {
        vec![OsPriority::Nice(expected)]
    };
    assert_eq!(priority_events(&events), published);
    assert_eq!(seen.fresh(), (expected, false));
    assert_eq!(handle.state(), State::Running);
    assert!(system.shutdown().clean());
}

#[test]
fn positive_priority_is_applied_or_its_refusal_published() {
    let base = base_nice();
    let (system, handle, seen) = run(priority(5));
    let applied = handle.snapshot().os_priority;
    let (nice, round_robin) = seen.fresh();
    println!("priority 5 on this machine: {applied:?}");
    match &applied {
        OsPriority::RoundRobin(level) => {
            assert_eq!(*level, 5);
            assert!(round_robin, "published SCHED_RR, the thread is not");
        }
        OsPriority::Nice(published) => {
            assert_eq!(*published, (base - 5).max(-20));
            assert_eq!(nice, *published);
            assert!(!round_robin);
        }
        OsPriority::NotApplied(why) => {
            assert!(why.contains("SCHED_RR"), "{why}");
            assert_eq!((nice, round_robin), (base, false));
        }
        OsPriority::Inherited => panic!("priority 5 was not even tried"),
    }
    // Refused or not, the component runs.
    assert_eq!(handle.state(), State::Running);

    // Back to 0: normal scheduling at the nice value the thread was created with
    // (always permitted after SCHED_RR or a lower nice value was granted).
    handle
        .command(Command::SetPriority(0))
        .expect("set priority");
    // (After a refusal nothing had changed, and setting the same nice value is
    // permitted too.)
    assert_eq!(handle.snapshot().os_priority, OsPriority::Nice(base));
    assert_eq!(seen.fresh(), (base, false));
    assert!(system.shutdown().clean());
}
