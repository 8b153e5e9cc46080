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
    clock_ignoring, clock_recovering, clock_redundant, clock_restarting, clock_trip_puller,
    clock_trippable,
};
use coolbot_runtime_tests::support::WAIT;
use coolbot_runtime_tests::support::compound::{CompoundRig, count};

/// A `ClockTrippable`'s behaviour: its answer to a pull of `trip` fails while `fails`
/// is set; its `start` hook takes `slow_start` of real time (a driver opening a
/// device), and fails while `start_fails` is set (the device is not there).
struct Trippable {
    fails: Arc<AtomicBool>,
    slow_start: Duration,
    start_fails: Arc<AtomicBool>,
}

impl clock_trippable::Behavior for Trippable {
    fn start(&mut self, _cx: &mut clock_trippable::Cx<'_>) -> coolbot::SectionResult {
        std::thread::sleep(self.slow_start);
        if self.start_fails.load(Ordering::SeqCst) {
            return Err(coolbot::Fault::message("no device"));
        }
        Ok(())
    }

    fn answer_trip(&mut self, _cx: &mut clock_trippable::Cx<'_>) -> Result<u64, coolbot::Fault> {
        if self.fails.load(Ordering::SeqCst) {
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
impl clock_ignoring::Supervisor for NoSections {}
impl clock_redundant::Supervisor for NoSections {}

/// The parts of either compound: `w` fails while `fails`, `s` while `s_fails`; `w`'s
/// `start` takes `slow_start` of real time, and fails while `w_start_fails`; `s`'s
/// while `s_start_fails`.
struct Parts {
    fails: Arc<AtomicBool>,
    s_fails: Arc<AtomicBool>,
    slow_start: Duration,
    w_start_fails: Arc<AtomicBool>,
    s_start_fails: Arc<AtomicBool>,
}

impl Parts {
    fn new(fails: &Arc<AtomicBool>, s_fails: &Arc<AtomicBool>) -> Parts {
        Parts {
            fails: Arc::clone(fails),
            s_fails: Arc::clone(s_fails),
            slow_start: Duration::ZERO,
            w_start_fails: Arc::new(AtomicBool::new(false)),
            s_start_fails: Arc::new(AtomicBool::new(false)),
        }
    }

    /// `s`'s behaviour.
    fn s(&self) -> Trippable {
        Trippable {
            fails: Arc::clone(&self.s_fails),
            slow_start: Duration::ZERO,
            start_fails: Arc::clone(&self.s_start_fails),
        }
    }

    /// `w`'s behaviour.
    fn w(&self) -> Trippable {
        Trippable {
            fails: Arc::clone(&self.fails),
            slow_start: self.slow_start,
            start_fails: Arc::clone(&self.w_start_fails),
        }
    }
}

impl clock_restarting::Parts for Parts {
    fn supervisor(&mut self) -> impl clock_restarting::Supervisor {
        NoSections
    }
    fn w(&mut self) -> impl clock_trippable::Behavior {
        Parts::w(self)
    }
}

impl clock_recovering::Parts for Parts {
    fn supervisor(&mut self) -> impl clock_recovering::Supervisor {
        NoSections
    }
    fn w(&mut self) -> impl clock_trippable::Behavior {
        Parts::w(self)
    }
    fn s(&mut self) -> impl clock_trippable::Behavior {
        Parts::s(self)
    }
}

/// `ClockIgnoring` and `ClockRedundant`: `w` and `s` as in `ClockRecovering`.
macro_rules! w_and_s {
    ($($m:ident),*) => {$(
        impl $m::Parts for Parts {
            fn supervisor(&mut self) -> impl $m::Supervisor {
                NoSections
            }
            fn w(&mut self) -> impl clock_trippable::Behavior {
                Parts::w(self)
            }
            fn s(&mut self) -> impl clock_trippable::Behavior {
                Parts::s(self)
            }
        }
    )*};
}

w_and_s!(clock_ignoring, clock_redundant);

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

/// `w` cannot start when the compound starts (its device, or its node, is not there
/// yet): under `substitute` that is a fault like a later one. `s` stands in from the
/// start, the compound runs, and the queue retries `w` every 100 ms of clock time
/// until it starts; then it takes its place back.
#[test]
fn an_instance_that_cannot_start_is_substituted_from_the_start_and_recovered() {
    let never = Arc::new(AtomicBool::new(false));
    let parts = Parts::new(&never, &never);
    let start_fails = Arc::clone(&parts.w_start_fails);
    start_fails.store(true, Ordering::SeqCst);
    let rig = rig(clock_recovering::component("k", parts));
    rig.rig.wait_steps(
        "w",
        1,
        |step| matches!(step, Step::Substituted { by } if by == "s"),
    );
    let failed = rig.rig.compound.snapshot().supervision;
    assert!(
        failed
            .iter()
            .any(|s| s.instance == "w" && s.step == Step::Failed && s.detail.contains("no device")),
        "the step says why: {failed:?}"
    );
    rig.rig.wait_instance_state("s", State::Running);
    assert_eq!(rig.rig.compound.state(), State::Running);
    assert_eq!(rig.rig.instance("w").state(), State::StartingError);

    rig.advance(100);
    assert_eq!(rig.steps("w", &Step::RetryFailed), 1, "still no device");
    start_fails.store(false, Ordering::SeqCst);
    rig.advance(100);
    assert_eq!(rig.steps("w", &Step::Retried), 1, "it starts at 200 ms");
    rig.advance(100);
    assert_eq!(rig.steps("w", &Step::Recovered), 1, "recovered at 300 ms");
    rig.rig.wait_instance_state("w", State::Running);
    rig.rig.wait_instance_state("s", State::Ready);
    assert!(rig.rig.shutdown().clean());
}

/// Under a policy that does not handle it (`restart`: nothing restarts from
/// `starting_error`), an instance that cannot start leaves the compound unable to
/// start, and the error names the instance and its reason. A restart of the compound
/// starts it again: once it can start, the compound runs.
#[test]
fn an_instance_that_cannot_start_under_restart_fails_the_compounds_start() {
    let (parts, start_fails) = w_cannot_start();
    let mut rig = CompoundRig::on_virtual_clock(clock_restarting::component("k", parts));
    fails_to_start_for_w(&mut rig);

    start_fails.store(false, Ordering::SeqCst);
    rig.command(coolbot::Controllable::Running)
        .expect("the compound restarts");
    rig.wait_instance_state("w", State::Running);
    assert_eq!(rig.compound.state(), State::Running);
    let _ = rig.system.shutdown();
}

/// A redundant group none of whose members can start has nothing to run on: the
/// compound cannot start, and says which member could not.
#[test]
fn a_redundant_group_none_of_whose_members_can_start_fails_the_compounds_start() {
    let (parts, _start_fails) = w_cannot_start();
    parts.s_start_fails.store(true, Ordering::SeqCst);
    let mut rig = CompoundRig::on_virtual_clock(clock_redundant::component("k", parts));
    fails_to_start_for_w(&mut rig);
    let _ = rig.system.shutdown();
}

/// Run the system of `rig`: its compound's start ends in `starting_error`, naming
/// `w` and why it could not start.
fn fails_to_start_for_w(rig: &mut CompoundRig) {
    let _ = rig.system.run_all();
    let failed = rig
        .compound
        .wait_for(|m| m.state != State::Starting, WAIT)
        .expect("the compound's start ends");
    assert_eq!(failed.state, State::StartingError);
    let error = failed.error.unwrap_or_default();
    assert!(
        error.contains("instance `w` could not start") && error.contains("no device"),
        "{error}"
    );
}

/// `Parts` whose `w` cannot start until the flag returned is cleared.
fn w_cannot_start() -> (Parts, Arc<AtomicBool>) {
    let never = Arc::new(AtomicBool::new(false));
    let parts = Parts::new(&never, &never);
    parts.w_start_fails.store(true, Ordering::SeqCst);
    let start_fails = Arc::clone(&parts.w_start_fails);
    (parts, start_fails)
}

/// Under `ignore`, an instance that cannot start stays in `starting_error` and the
/// compound runs on without it.
#[test]
fn an_instance_that_cannot_start_under_ignore_is_left_and_the_compound_runs() {
    let (parts, _start_fails) = w_cannot_start();
    let mut rig = CompoundRig::on_virtual_clock(clock_ignoring::component("k", parts));
    rig.run();
    rig.wait_steps("w", 1, |step| *step == Step::Ignored);
    rig.wait_instance_state("s", State::Running);
    assert_eq!(rig.compound.state(), State::Running);
    assert_eq!(rig.instance("w").state(), State::StartingError);
    assert!(rig.shutdown().clean());
}

/// A redundant member that cannot start leaves its group to the members that
/// started: `s` leads from the start, and `w` joins when a retry starts it.
#[test]
fn a_redundant_member_that_cannot_start_leaves_the_group_to_the_others() {
    let (parts, start_fails) = w_cannot_start();
    let mut rig = CompoundRig::on_virtual_clock(clock_redundant::component("k", parts));
    rig.run();
    rig.wait_steps(
        "w",
        1,
        |step| matches!(step, Step::Substituted { by } if by == "s"),
    );
    rig.wait_instance_state("s", State::Running);
    assert_eq!(rig.compound.state(), State::Running);
    start_fails.store(false, Ordering::SeqCst);
    rig.advance(Duration::from_millis(100));
    assert_eq!(rig.steps("w", &Step::Retried), 1, "it starts at 100 ms");
    rig.advance(Duration::from_millis(100));
    assert_eq!(rig.steps("w", &Step::Recovered), 1, "recovered at 200 ms");
    rig.wait_instance_state("w", State::Running);
    assert!(rig.shutdown().clean());
}
