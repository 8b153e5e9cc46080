//! Compounds on the clock seam: a compound in a system on a virtual clock runs its
//! supervision timing (restart backoff, recovery retries) and its
//! instances on that clock, so a test steps through exact sequences with no sleep.
//! The compounds are `cool/compound_clock.cool`'s, without a `supervisor` block.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use coolbot::crossbeam_channel::{self, Sender};
use coolbot::port::LastIn;
use coolbot::{Component, CompoundError, State, Step};
use coolbot_runtime_tests::generated::{
    clock_recovering, clock_restarting, clock_trip_puller, clock_trippable,
};
use coolbot_runtime_tests::support::WAIT;
use coolbot_runtime_tests::support::compound::{CompoundRig, count};

/// A `ClockTrippable`'s behaviour: its answer to a pull of `trip` fails while `fails`
/// is set; its `start` hook takes `slow_start` of real time (a driver opening a
/// device).
struct Trippable(Arc<AtomicBool>, Duration);

impl clock_trippable::Behavior for Trippable {
    fn start(&mut self, _cx: &mut clock_trippable::Cx<'_>) -> coolbot::SectionResult {
        std::thread::sleep(self.1);
        Ok(())
    }

    fn answer_trip(&mut self, _cx: &mut clock_trippable::Cx<'_>) -> Result<u64, coolbot::Fault> {
        if self.0.load(Ordering::SeqCst) {
            return Err(coolbot::Fault::message("tripped"));
        }
        Ok(1)
    }
}

/// A `ClockTripPuller`'s behaviour: hands its `trip` input to the test when it starts.
struct Hand(Sender<LastIn<u64>>);

impl clock_trip_puller::Behavior for Hand {
    fn start(&mut self, cx: &mut clock_trip_puller::Cx<'_>) -> coolbot::SectionResult {
        let _ = self.0.send(cx.inputs.trip.clone());
        Ok(())
    }
}

/// The compounds have no supervisor block: their supervisor has nothing to do.
struct NoSections;

impl clock_restarting::Supervisor for NoSections {}
impl clock_recovering::Supervisor for NoSections {}

/// The parts of either compound: `w` fails while `fails`, `s` while `s_fails`; `w`'s
/// `start` takes `slow_start` of real time.
struct Parts {
    fails: Arc<AtomicBool>,
    s_fails: Arc<AtomicBool>,
    slow_start: Duration,
}

impl Parts {
    fn new(fails: &Arc<AtomicBool>, s_fails: &Arc<AtomicBool>) -> Parts {
        Parts {
            fails: Arc::clone(fails),
            s_fails: Arc::clone(s_fails),
            slow_start: Duration::ZERO,
        }
    }
}

impl clock_restarting::Parts for Parts {
    fn supervisor(&mut self) -> impl clock_restarting::Supervisor {
        NoSections
    }
    fn w(&mut self) -> impl clock_trippable::Behavior {
        Trippable(Arc::clone(&self.fails), self.slow_start)
    }
}

impl clock_recovering::Parts for Parts {
    fn supervisor(&mut self) -> impl clock_recovering::Supervisor {
        NoSections
    }
    fn w(&mut self) -> impl clock_trippable::Behavior {
        Trippable(Arc::clone(&self.fails), self.slow_start)
    }
    fn s(&mut self) -> impl clock_trippable::Behavior {
        Trippable(Arc::clone(&self.s_fails), Duration::ZERO)
    }
}

/// A system on a virtual clock with compound `k` (exporting its instance `w`'s
/// `trip`) and a `ClockTripPuller` `o`, which pulls `k.trip`.
struct Rig {
    rig: CompoundRig,
    trip: LastIn<u64>,
}

fn rig(k: Result<Component, CompoundError>) -> Rig {
    let mut rig = CompoundRig::on_virtual_clock(k);
    let (hand, trip) = crossbeam_channel::bounded(1);
    rig.add(clock_trip_puller::component("o", Hand(hand)));
    rig.connect("k.trip", "o.trip");
    rig.run();
    let trip = trip.recv_timeout(WAIT).expect("o started");
    Rig { rig, trip }
}

impl Rig {
    /// Fail `w` (its answer to a pull of `trip` fails) and wait until the compound
    /// published the `Failed` step number `failures`.
    fn fail_w(&self, failures: usize) {
        let _ = self.trip.request();
        self.rig
            .wait_steps("w", failures, |step| *step == Step::Failed);
    }

    /// Advance the clock by `ms` milliseconds, until every component settled.
    fn advance(&self, ms: u64) {
        self.rig.advance(Duration::from_millis(ms));
    }

    /// How many steps `step` about `instance` the compound published so far.
    fn steps(&self, instance: &str, step: &Step) -> usize {
        self.rig.steps(instance, step)
    }
}

#[test]
fn the_restart_backoff_runs_on_the_virtual_clock() {
    // `restart` with a backoff of 40 ms, doubling: the first restart is at once, the
    // second 40 ms after its fault, the third 80 ms after its fault, in clock time.
    let fails = Arc::new(AtomicBool::new(true));
    let s_fails = Arc::new(AtomicBool::new(false));
    let rig = rig(clock_restarting::component(
        "k",
        Parts::new(&fails, &s_fails),
    ));
    rig.fail_w(1);
    rig.rig
        .compound
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
        rig.rig.wait_instance_state("w", State::Running);
    }
    assert!(rig.rig.shutdown().clean());
}

/// `w` fails into the recovery queue (its substitute `s` stands in): the queue
/// retries every 100 ms of clock time, and `w` recovers at the retry after the one
/// that brought it back; `w`'s `start` takes `slow_start` of real time.
fn recovery_retries(slow_start: Duration) {
    let fails = Arc::new(AtomicBool::new(true));
    let s_fails = Arc::new(AtomicBool::new(false));
    let parts = Parts {
        slow_start,
        ..Parts::new(&fails, &s_fails)
    };
    let rig = rig(clock_recovering::component("k", parts));
    rig.fail_w(1);
    rig.rig.wait_steps(
        "w",
        1,
        |step| matches!(step, Step::Substituted { by } if by == "s"),
    );
    rig.advance(99);
    assert_eq!(rig.steps("w", &Step::Retried), 0, "no retry before 100 ms");
    rig.advance(1);
    assert_eq!(rig.steps("w", &Step::Retried), 1, "the retry at 100 ms");
    assert_eq!(rig.steps("w", &Step::Recovered), 0, "on probation");
    rig.advance(100);
    assert_eq!(rig.steps("w", &Step::Recovered), 1, "recovered at 200 ms");
    assert_eq!(rig.steps("w", &Step::Retired), 0);
    assert!(rig.rig.shutdown().clean());
}

#[test]
fn recovery_retries_run_on_the_virtual_clock() {
    recovery_retries(Duration::ZERO);
}

/// A retry's restart that takes real time (longer than the real clock's look at its
/// answer) is answered at the clock's time all the same: the compound waits for it
/// in the clock's time, not for a moment of real time.
#[test]
fn a_recovery_retry_whose_restart_takes_real_time_is_answered_at_the_clocks_time() {
    recovery_retries(Duration::from_millis(50));
}
