//! A section that takes time of its clock (`Context::spend`, `docs/runtime.md`,
//! "Taking time"): on a virtual clock it is measured that long and trips its
//! `max_response`, `advance` does not wait for it nor for its execution group, and
//! its system's shutdown does not wait for the clock; in a harness the clock moves
//! on by itself.

use std::sync::Arc;
use std::time::Duration;

use coolbot::{
    Clock, Command, CompoundBuilder, Controllable, Section, SectionResult, Spec, State, Supervisor,
    SupervisorCx, System, Value, VirtualClock,
};
use coolbot_runtime_tests::generated::cmp_counting;
use coolbot_runtime_tests::supervision::Coordinating;
use coolbot_runtime_tests::support::Log;
use coolbot_runtime_tests::{relay, stage};

/// `Stage`'s period (its `max_response` is 5 ms).
const PERIOD: Duration = Duration::from_millis(10);

/// A periodic stage that takes `costs[n]` of its clock's time in its `n`th period
/// (from 0; nothing past the list), and `start_cost` in its `start` hook.
struct Busy {
    name: &'static str,
    log: Log,
    costs: Vec<Duration>,
    period: usize,
    start_cost: Duration,
}

impl stage::Behavior for Busy {
    fn start(&mut self, cx: &mut stage::Cx<'_>) -> SectionResult {
        cx.rt.spend(self.start_cost);
        Ok(())
    }

    fn work_periodic(&mut self, cx: &mut stage::Cx<'_>) -> SectionResult {
        let (name, period) = (self.name, self.period);
        self.log.push(format!("{name}:{period}"));
        if let Some(cost) = self.costs.get(period) {
            cx.rt.spend(*cost);
        }
        self.period += 1;
        self.log.push(format!("{name}:{period} done"));
        cx.outputs
            .out
            .send(u64::try_from(period).unwrap_or(u64::MAX));
        Ok(())
    }
}

fn busy(name: &'static str, log: &Log, costs: &[u64]) -> Busy {
    Busy {
        name,
        log: log.clone(),
        costs: costs.iter().copied().map(Duration::from_millis).collect(),
        period: 0,
        start_cost: Duration::ZERO,
    }
}

fn ms(n: u64) -> Duration {
    Duration::from_millis(n)
}

#[test]
fn a_section_taking_clock_time_is_measured_that_long_and_trips_its_max_response() {
    let log = Log::default();
    // Period 0: 3 ms, within the 5 ms `max_response`; period 1: 8 ms, beyond it.
    // The first period takes 3 ms of the clock: `advance` does not wait for it, and
    // it is not done before the clock gets there.
    let (system, clock, a) = one_stage(&log, &[3, 8]);
    assert_eq!(log.take(), ["a:0"]);
    clock.advance(ms(2)).expect("settled");
    assert_eq!(log.take(), Vec::<String>::new());
    clock.advance(ms(1)).expect("settled");
    assert_eq!(log.take(), ["a:0 done"]);
    let monitor = a.snapshot();
    assert_eq!(monitor.elapsed_time, ms(3));
    assert_eq!(monitor.overruns, 0);
    // The second period: its 8 ms trip the watch once past 5 ms (counted then); the
    // section's outcome is discarded when it returns, and the component fails.
    clock.advance(ms(7)).expect("settled");
    assert_eq!(log.take(), ["a:1"]);
    clock.advance(ms(5)).expect("settled");
    assert_eq!(a.snapshot().overruns, 0, "exactly its max_response so far");
    clock.advance(ms(1)).expect("settled");
    assert_eq!(a.snapshot().overruns, 1);
    assert_eq!(log.take(), Vec::<String>::new());
    clock.advance(ms(2)).expect("settled");
    assert_eq!(log.take(), ["a:1 done"]);
    let monitor = a.snapshot();
    assert_eq!(monitor.state, State::RunningError);
    assert_eq!(monitor.elapsed_time, ms(11));
    assert!(
        monitor
            .error
            .as_deref()
            .is_some_and(|e| e.starts_with("overrun in state `work`")),
        "{monitor:?}"
    );
    assert!(system.shutdown().clean());
}

#[test]
fn advancing_waits_neither_for_a_member_taking_clock_time_nor_for_its_group() {
    let log = Log::default();
    let clock = VirtualClock::new();
    let mut system = System::with_clock(Clock::virtual_clock(&clock));
    // `a` takes 4 ms in its first period; `b` shares its thread; `alone` has one of
    // its own.
    system
        .add(stage::component("a", busy("a", &log, &[4])))
        .expect("a");
    system
        .add(stage::component("b", busy("b", &log, &[])))
        .expect("b");
    system
        .add(stage::component("alone", busy("alone", &log, &[])))
        .expect("alone");
    system.connect("a.out", "b.feed").expect("a -> b");
    system.group("control", &["a", "b"]).expect("group");
    system.run_all().expect("running");
    clock.settle().expect("settled");
    // `alone` ran its first period; `a` is in the middle of its own, and `b` waits for
    // the thread.
    clock.advance(PERIOD).expect("settled");
    let mut first = log.take();
    first.sort();
    assert_eq!(first, ["a:0", "alone:0", "alone:0 done"]);
    clock.advance(ms(3)).expect("settled");
    assert_eq!(log.take(), Vec::<String>::new());
    // At 4 ms `a` is done, and `b` runs after it in the same pass.
    clock.advance(ms(1)).expect("settled");
    assert_eq!(log.take(), ["a:0 done", "b:0", "b:0 done"]);
    // The next period, nobody takes time: all three run and settle at 10 ms.
    clock.advance(PERIOD - ms(4)).expect("settled");
    let mut second = log.take();
    second.sort();
    assert_eq!(
        second,
        [
            "a:1",
            "a:1 done",
            "alone:1",
            "alone:1 done",
            "b:1",
            "b:1 done"
        ]
    );
    assert!(system.shutdown().clean());
}

#[test]
fn shutting_down_does_not_wait_for_a_section_taking_clock_time() {
    let log = Log::default();
    let (system, clock, _) = one_stage(&log, &[3_600_000]);
    assert_eq!(log.take(), ["a:0"]);
    // An hour of the clock that nobody advances: the shutdown ends the section.
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
    assert_eq!(log.take(), ["a:0 done"]);
    assert_eq!(clock.elapsed(), PERIOD);
}

#[test]
fn in_a_harness_a_section_taking_clock_time_moves_the_clock_on() {
    let log = Log::default();
    let mut harness = stage::Harness::running(busy("a", &log, &[3])).expect("running");
    // The first period, at 10 ms, takes 3 ms: the clock is at 13 ms when it is done,
    // past the 10 ms asked for.
    harness.advance(PERIOD).expect("advanced");
    assert_eq!(log.take(), ["a:0", "a:0 done"]);
    assert_eq!(harness.inner().elapsed(), ms(13));
    assert_eq!(harness.inner().monitor().elapsed_time, ms(3));
    // The second, at 20 ms, takes none.
    harness.advance(PERIOD).expect("advanced");
    assert_eq!(log.take(), ["a:1", "a:1 done"]);
    assert_eq!(harness.inner().elapsed(), ms(23));
}

/// A system on a fresh virtual clock with the stage `a` (given costs), running, and
/// its first period started.
fn one_stage(log: &Log, costs: &[u64]) -> (System, Arc<VirtualClock>, coolbot::Handle) {
    let clock = VirtualClock::new();
    let mut system = System::with_clock(Clock::virtual_clock(&clock));
    let a = system
        .add(stage::component("a", busy("a", log, costs)))
        .expect("a");
    system.run_all().expect("running");
    clock.settle().expect("settled");
    clock.advance(PERIOD).expect("settled");
    (system, clock, a)
}

#[test]
fn a_section_taking_exactly_its_max_response_does_not_overrun() {
    let log = Log::default();
    let (system, clock, a) = one_stage(&log, &[5]);
    clock.advance(ms(5)).expect("settled");
    assert_eq!(log.take(), ["a:0", "a:0 done"]);
    let monitor = a.snapshot();
    assert_eq!((monitor.state, monitor.overruns), (State::Running, 0));
    assert!(system.shutdown().clean());
}

#[test]
fn a_section_whose_cost_one_advance_crosses_is_tripped_at_that_advance() {
    let log = Log::default();
    let (system, clock, a) = one_stage(&log, &[8]);
    // One step past both its 5 ms `max_response` and its 8 ms: the watch trips it at
    // the step's time, before the section returns.
    clock.advance(ms(20)).expect("settled");
    assert_eq!(log.take(), ["a:0", "a:0 done"]);
    let monitor = a.snapshot();
    assert_eq!((monitor.state, monitor.overruns), (State::RunningError, 1));
    assert!(
        monitor
            .error
            .as_deref()
            .is_some_and(|e| e.contains("returned after 20ms")),
        "{monitor:?}"
    );
    assert!(system.shutdown().clean());
}

#[test]
fn outside_a_section_taking_clock_time_takes_none() {
    let log = Log::default();
    let clock = VirtualClock::new();
    let mut system = System::with_clock(Clock::virtual_clock(&clock));
    let a = system
        .add(stage::component(
            "a",
            Busy {
                start_cost: Duration::from_secs(3_600),
                ..busy("a", &log, &[])
            },
        ))
        .expect("a");
    // The `start` hook asks for an hour: the system starts all the same, and no time
    // of the clock passed.
    system.run_all().expect("running");
    clock.settle().expect("settled");
    assert_eq!(a.state(), State::Running);
    assert_eq!(clock.elapsed(), Duration::ZERO);
    assert!(system.shutdown().clean());
}

/// (The compound releases its instances before it commands them `dead`, so that the
/// command is taken at once rather than withdrawn as busy after its timeout; only
/// the time and a warning in the log tell the two apart, and this checks neither.)
#[test]
fn a_compounds_shutdown_ends_its_instance_taking_clock_time_cleanly() {
    let log = Log::default();
    let clock = VirtualClock::new();
    let mut system = System::with_clock(Clock::virtual_clock(&clock));
    let k = CompoundBuilder::new("k", Coordinating)
        .instance(stage::component("a", busy("a", &log, &[3_600_000])))
        .build()
        .expect("build");
    system.add(k).expect("k");
    system.run_all().expect("running");
    clock.settle().expect("settled");
    clock.advance(PERIOD).expect("settled");
    assert_eq!(log.take(), ["a:0"]);
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
    assert_eq!(log.take(), ["a:0 done"]);
}

/// A relay whose entry section takes `cost` of its clock's time.
struct SlowEntry {
    log: Log,
    cost: Duration,
}

impl relay::Behavior for SlowEntry {
    fn relay_entry(&mut self, cx: &mut relay::Cx<'_>) -> SectionResult {
        self.log.push("r:entry".to_owned());
        cx.rt.spend(self.cost);
        self.log.push("r:entry done".to_owned());
        Ok(())
    }
}

#[test]
fn a_command_whose_transition_takes_clock_time_counts_as_taken() {
    let log = Log::default();
    let clock = VirtualClock::new();
    let mut system = System::with_clock(Clock::virtual_clock(&clock));
    let r = system
        .add(relay::component(
            "r",
            SlowEntry {
                log: log.clone(),
                cost: ms(10),
            },
        ))
        .expect("r");
    system.start().expect("started");
    // `run` enters the initial state, whose entry section takes 10 ms of the clock:
    // only an advance can end it, so the command is answered once the section takes
    // that time, whatever its timeout (here an hour, which the command would
    // otherwise wait out: the poll's deadline would fail the test first).
    let patient = r.clone().with_command_timeout(Duration::from_secs(3_600));
    let commanding =
        std::thread::spawn(move || patient.command(Command::SetState(Controllable::Running)));
    let deadline = std::time::Instant::now() + Duration::from_secs(60);
    while !commanding.is_finished() {
        assert!(
            std::time::Instant::now() < deadline,
            "the command waited for the clock"
        );
        std::thread::sleep(ms(1));
    }
    commanding.join().expect("no panic").expect("taken");
    assert_eq!(log.take(), ["r:entry"]);
    clock.advance(ms(10)).expect("settled");
    assert_eq!(log.take(), ["r:entry done"]);
    assert_eq!(r.state(), State::Running);
    assert!(system.shutdown().clean());
}

#[test]
fn a_section_may_take_more_time_than_an_instant_can_hold() {
    let log = Log::default();
    // Two hundred years, past what the clock's instants reach (about a hundred).
    let (system, clock, _) = one_stage(&log, &[200 * 365 * 24 * 3_600 * 1_000]);
    clock
        .advance(Duration::from_secs(150 * 365 * 24 * 3_600))
        .expect("the section is not waited for");
    assert_eq!(log.take(), ["a:0"]);
    assert!(system.shutdown().clean());
}

/// A supervisor with the shape of `CmpCounting` (a periodic section every 2 ms),
/// whose first periodic section past 11 ms commands its instances as `act` does
/// (which may log as it goes) and logs what `act` returns with the clock's time
/// after it.
struct CommandsOnce {
    log: Log,
    clock: Arc<VirtualClock>,
    act: Act,
    commanded: bool,
}

/// What a `CommandsOnce` does: its commands, with the log and the clock.
type Act = fn(&mut SupervisorCx<'_>, &Log, &VirtualClock) -> String;

impl CommandsOnce {
    fn new(log: &Log, clock: &Arc<VirtualClock>, act: Act) -> CommandsOnce {
        CommandsOnce {
            log: log.clone(),
            clock: Arc::clone(clock),
            act,
            commanded: false,
        }
    }
}

impl Supervisor for CommandsOnce {
    fn spec(&self) -> &'static Spec {
        &cmp_counting::SPEC
    }

    fn get(&self, _variable: usize) -> Value {
        Value::UInt(0)
    }

    fn section(
        &mut self,
        _state: usize,
        section: Section,
        cx: &mut SupervisorCx<'_>,
    ) -> SectionResult {
        if section != Section::Periodic || self.commanded || self.clock.elapsed() < ms(11) {
            return Ok(());
        }
        self.commanded = true;
        let did = (self.act)(cx, &self.log, &self.clock);
        self.log
            .push(format!("k: {did} at {:?}", self.clock.elapsed()));
        Ok(())
    }
}

/// A `CommandsOnce` act: suspend `a` (at 12 ms: `a`'s first period, from 10 ms,
/// takes the clock's time then), logging when it asks; the answer.
fn suspends_a(cx: &mut SupervisorCx<'_>, log: &Log, clock: &VirtualClock) -> String {
    log.push(format!("k: suspend a at {:?}", clock.elapsed()));
    match cx.instances.state("a", Controllable::Suspended) {
        Ok(()) => "taken".to_owned(),
        Err(refused) => refused.reason.to_string(),
    }
}

/// A compound `k` over `a`, whose first period (from 10 ms) takes `cost` ms of the
/// clock's time, its supervisor's commands waiting at most `timeout`: what they did
/// over the clock's first `until` ms, in 1 ms steps, and a clean shutdown.
fn commanding_a_spender(cost: u64, timeout: Duration, until: u64) -> Vec<String> {
    let log = Log::default();
    let clock = VirtualClock::new();
    let mut system = System::with_clock(Clock::virtual_clock(&clock));
    let supervisor = CommandsOnce::new(&log, &clock, suspends_a);
    let k = CompoundBuilder::new("k", supervisor)
        .instance(stage::component("a", busy("a", &log, &[cost])))
        .command_timeout(timeout)
        .build()
        .expect("build");
    system.add(k).expect("k");
    system.run_all().expect("running");
    clock.settle().expect("settled");
    for _ in 0..until {
        clock.advance(ms(1)).expect("settled");
    }
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
    log.take()
}

/// A supervisor's command to an instance whose section takes the clock's time waits
/// for it in the clock's time: the instance takes it once its section returned, at
/// the time the clock reached, and `advance` never waits for the supervisor
/// meanwhile.
#[test]
fn a_supervisor_commanding_an_instance_taking_clock_time_waits_in_the_clocks_time() {
    assert_eq!(
        commanding_a_spender(4, Duration::from_millis(250), 16),
        [
            "a:0",
            "k: suspend a at 12ms",
            "a:0 done",
            "k: taken at 14ms"
        ]
    );
}

/// Its timeout is counted in the clock's time too: one the section outlasts ends at
/// the advance that reaches it, and the command, never taken, is withdrawn.
#[test]
fn a_supervisor_command_an_instance_taking_clock_time_outlasts_is_withdrawn_in_the_clocks_time() {
    assert_eq!(
        commanding_a_spender(4, Duration::from_millis(1), 16),
        [
            "a:0",
            "k: suspend a at 12ms",
            "k: the instance did not take the command within 1ms (busy in a section); withdrawn at 13ms",
            "a:0 done",
        ]
    );
}

/// A supervisor's command to an instance at rest is taken within the advance that ran
/// the supervisor's section: the instance counts as busy from the command's post, so
/// the advance does not return while the supervisor waits for it.
#[test]
fn an_advance_returns_once_a_supervisors_command_to_an_instance_at_rest_is_taken() {
    assert_eq!(
        commanding_a_spender(0, Duration::from_millis(250), 12),
        [
            "a:0",
            "a:0 done",
            "k: suspend a at 12ms",
            "k: taken at 12ms"
        ]
    );
}

/// A relay whose entries after the first take `cost` of the clock's time each.
struct SlowReentry {
    log: Log,
    cost: Duration,
    entries: usize,
}

impl relay::Behavior for SlowReentry {
    fn relay_entry(&mut self, cx: &mut relay::Cx<'_>) -> SectionResult {
        self.entries += 1;
        if self.entries > 1 {
            self.log.push("r:entry".to_owned());
            cx.rt.spend(self.cost);
            self.log.push("r:entry done".to_owned());
        }
        Ok(())
    }
}

/// A `CommandsOnce` act: take `r` to `ready` and back to `running` (whose entry then
/// takes the clock's time); both answers.
fn restarts_r(cx: &mut SupervisorCx<'_>, _log: &Log, _clock: &VirtualClock) -> String {
    let ready = cx.instances.state("r", Controllable::Ready);
    let run = cx.instances.state("r", Controllable::Running);
    format!("{ready:?} {run:?}")
}

/// A supervisor's section whose command's transition takes the clock's time is done
/// before the advance that ran it returns: the instance is busy with the command
/// before the supervisor leaves the settled wait, and the answer that the transition
/// takes the clock's time makes the supervisor busy again before the instance leaves
/// it. (Each round races the two threads against the advance.)
#[test]
fn a_supervisor_told_its_command_takes_clock_time_settles_within_the_advance() {
    let mut bad = Vec::new();
    for round in 0..100 {
        let log = Log::default();
        let clock = VirtualClock::new();
        let mut system = System::with_clock(Clock::virtual_clock(&clock));
        let supervisor = CommandsOnce::new(&log, &clock, restarts_r);
        let k = CompoundBuilder::new("k", supervisor)
            .instance(relay::component(
                "r",
                SlowReentry {
                    log: log.clone(),
                    cost: ms(4),
                    entries: 0,
                },
            ))
            .command_timeout(Duration::from_millis(250))
            .build()
            .expect("build");
        system.add(k).expect("k");
        system.run_all().expect("running");
        clock.settle().expect("settled");
        for step in 1..=14 {
            clock.advance(ms(1)).expect("settled");
            log.push(format!("advanced to {step}ms"));
        }
        let report = system.shutdown();
        assert!(report.clean(), "{report:?}");
        let lines = log.take();
        let lines: Vec<&str> = lines
            .iter()
            .map(String::as_str)
            .filter(|line| !line.starts_with("advanced") || *line == "advanced to 12ms")
            .collect();
        if lines
            != [
                "r:entry",
                "k: Ok(()) Ok(()) at 12ms",
                "advanced to 12ms",
                "r:entry done",
            ]
        {
            bad.push(format!("round {round}: {lines:?}"));
        }
    }
    assert!(bad.is_empty(), "{} of 100 rounds: {bad:#?}", bad.len());
}

/// A system shut down while a supervisor's section waits in the clock's time for an
/// instance whose section takes the clock's time: the supervisor is released (its
/// wait goes on in real time), and so is the instance it waits for, which takes the
/// command at once instead of the section waiting out its command timeout.
#[test]
fn shutting_down_while_a_supervisor_waits_for_an_instance_taking_clock_time_is_clean() {
    let log = Log::default();
    let clock = VirtualClock::new();
    let mut system = System::with_clock(Clock::virtual_clock(&clock));
    let supervisor = CommandsOnce::new(&log, &clock, suspends_a);
    let k = CompoundBuilder::new("k", supervisor)
        .instance(stage::component("a", busy("a", &log, &[4])))
        .command_timeout(Duration::from_secs(8))
        .build()
        .expect("build");
    system.add(k).expect("k");
    system.run_all().expect("running");
    clock.settle().expect("settled");
    for _ in 0..12 {
        clock.advance(ms(1)).expect("settled");
    }
    assert_eq!(log.take(), ["a:0", "k: suspend a at 12ms"]);
    // (The command timeout outlasts the shutdown's: a supervisor waiting it out
    // would leave its thread unjoined.)
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}
