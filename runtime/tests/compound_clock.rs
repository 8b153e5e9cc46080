//! Compounds on the clock seam: a compound in a system on a virtual clock runs its
//! supervision timing (restart backoff, recovery retries) and its
//! instances on that clock, so a test steps through exact sequences with no sleep.

mod support;

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use coolbot::port::{DataOut, LastIn};
use coolbot::{
    Clock, Component, CompoundBuilder, Fault, Handle, InputKind, OutputKind, Policy, Step,
    Supervision, System, VirtualClock,
};
use support::WAIT;
use support::shell::{Idle, ShellBuilder, input, output};

/// A component that fails when its `trip` output is pulled (while `fails` is set).
fn trippable(name: &str, fails: &Arc<AtomicBool>) -> Component {
    let trip = DataOut::<u64>::new();
    let fails = Arc::clone(fails);
    let answer_with = trip.clone();
    ShellBuilder::new(name)
        .output(output("trip", OutputKind::Data, true), &trip)
        .answer(move |_| {
            if fails.load(Ordering::SeqCst) {
                return Err(Fault::message("tripped"));
            }
            answer_with.send(1);
            Ok(())
        })
        .build()
}

/// A system on a virtual clock with compound `k` (built by `build` from a builder
/// holding instance `w`, whose `trip` it exports) and `o`, which pulls `k.trip`.
struct Rig {
    clock: Arc<VirtualClock>,
    system: System,
    k: Handle,
    trip: LastIn<u64>,
}

fn rig(build: impl FnOnce(CompoundBuilder) -> CompoundBuilder, fails: &Arc<AtomicBool>) -> Rig {
    let clock = VirtualClock::new();
    let builder = CompoundBuilder::new("k", Idle)
        .instance(trippable("w", fails))
        .export_output::<u64>("trip", "w.trip");
    let k = build(builder).build().expect("build k");
    let trip = LastIn::<u64>::new();
    let o = ShellBuilder::new("o")
        .input(input("trip", InputKind::Last, true), &trip)
        .build();
    let mut system = System::with_clock(Clock::virtual_clock(&clock));
    let k = system.add(k).expect("add k");
    system.add(o).expect("add o");
    system.connect("k.trip", "o.trip").expect("trip");
    system.run_all().expect("run");
    Rig {
        clock,
        system,
        k,
        trip,
    }
}

impl Rig {
    /// Fail `w` (its answer to a pull of `trip` fails) and wait until the compound
    /// published the `Failed` step number `failures`.
    fn fail_w(&self, failures: usize) {
        let _ = self.trip.request();
        self.k
            .wait_for(
                |m| count(&m.supervision, "w", &Step::Failed) >= failures,
                WAIT,
            )
            .unwrap_or_else(|_| panic!("w failed {failures} time(s): {:?}", self.k.snapshot()));
    }

    /// Advance the clock by `ms` milliseconds, until every component settled.
    fn advance(&self, ms: u64) {
        self.clock
            .advance(Duration::from_millis(ms))
            .expect("the components settle");
    }

    /// How many steps `step` about `instance` the compound published so far.
    fn steps(&self, instance: &str, step: &Step) -> usize {
        count(&self.k.snapshot().supervision, instance, step)
    }
}

fn count(steps: &[Supervision], instance: &str, step: &Step) -> usize {
    steps
        .iter()
        .filter(|s| s.instance == instance && s.step == *step)
        .count()
}

#[test]
fn the_restart_backoff_runs_on_the_virtual_clock() {
    // `restart` with a backoff of 40 ms, doubling: the first restart is at once, the
    // second 40 ms after its fault, the third 80 ms after its fault, in clock time.
    let fails = Arc::new(AtomicBool::new(true));
    let rig = rig(
        |k| {
            k.on_error("w", Policy::Restart)
                .restart_budget(10, Duration::from_secs(60))
                .restart_backoff(Duration::from_millis(40), Duration::from_secs(1))
        },
        &fails,
    );
    rig.fail_w(1);
    rig.k
        .wait_for(|m| count(&m.supervision, "w", &Step::Restarted) == 1, WAIT)
        .expect("the first restart is at once");
    for (failures, backoff) in [(2, 40), (3, 80)] {
        rig.fail_w(failures);
        rig.advance(backoff - 1);
        assert_eq!(
            rig.steps("w", &Step::Restarted),
            failures - 1,
            "not restarted 1 ms before its backoff of {backoff} ms"
        );
        rig.advance(1);
        assert_eq!(
            rig.steps("w", &Step::Restarted),
            failures,
            "restarted when its backoff of {backoff} ms is over"
        );
        let w = rig.k.instance("w").expect("w");
        w.wait_for(|m| m.state == coolbot::State::Running, WAIT)
            .expect("w runs again");
    }
    assert!(rig.system.shutdown().clean());
}

#[test]
fn recovery_retries_run_on_the_virtual_clock() {
    // `w` fails into the recovery queue (its substitute `s` stands in): the queue
    // retries every 100 ms of clock time, and `w` recovers at the retry after the
    // one that brought it back.
    let fails = Arc::new(AtomicBool::new(true));
    let s_fails = Arc::new(AtomicBool::new(false));
    let rig = rig(
        |k| {
            k.instance(trippable("s", &s_fails))
                .substitute("s", "w")
                .on_error("w", Policy::Substitute)
                .recovery(Duration::from_millis(100), Duration::from_millis(1000))
        },
        &fails,
    );
    rig.fail_w(1);
    rig.k
        .wait_for(
            |m| {
                m.supervision
                    .iter()
                    .any(|s| matches!(&s.step, Step::Substituted { by } if by == "s"))
            },
            WAIT,
        )
        .expect("s stands in");
    rig.advance(99);
    assert_eq!(rig.steps("w", &Step::Retried), 0, "no retry before 100 ms");
    rig.advance(1);
    assert_eq!(rig.steps("w", &Step::Retried), 1, "the retry at 100 ms");
    assert_eq!(rig.steps("w", &Step::Recovered), 0, "on probation");
    rig.advance(100);
    assert_eq!(rig.steps("w", &Step::Recovered), 1, "recovered at 200 ms");
    assert_eq!(rig.steps("w", &Step::Retired), 0);
    assert!(rig.system.shutdown().clean());
}
