//! When a compound's supervisor rules are evaluated although nothing they read sent
//! an event and no supervisor section ran: a mapped variable once another instance
//! stands in, an instance's time every supervisor period, the compound's own
//! `quality` set through its control port. The compounds are
//! `cool/compound_rules.cool`'s, on a virtual clock; their supervisors have no
//! section (a section would make every rule of the state evaluated).

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use coolbot::crossbeam_channel::Receiver;
use coolbot::{Command, Component, CompoundError, State, Step, Value};
use coolbot_runtime_tests::generated::{
    feeder, rules_own_quality, rules_spender, rules_substituted, rules_timed, worker,
};
use coolbot_runtime_tests::support::compound::{CompoundRig, Scripts, wait_state, wait_user};
use coolbot_runtime_tests::support::{Feeder, Tap, WAIT, quiet_component_panics};

/// The supervisors have nothing to do: rules only.
struct RulesOnly;

impl rules_substituted::Supervisor for RulesOnly {}
impl rules_timed::Supervisor for RulesOnly {}
impl rules_own_quality::Supervisor for RulesOnly {}

/// A `RulesSpender`'s behaviour: its next periodic section takes `cost` milliseconds
/// of its clock's time (then none again until the test sets it).
struct Spender(Arc<AtomicU64>);

impl rules_spender::Behavior for Spender {
    fn working_periodic(&mut self, cx: &mut rules_spender::Cx<'_>) -> coolbot::SectionResult {
        let cost = self.0.swap(0, Ordering::SeqCst);
        cx.rt.spend(Duration::from_millis(cost));
        Ok(())
    }
}

/// The parts of the compounds: scripted workers, the feeder handing its ports to
/// the test, a spender taking the time the test says.
struct Parts {
    scripts: Scripts,
    tap: Option<Tap>,
    cost: Arc<AtomicU64>,
}

impl rules_substituted::Parts for Parts {
    fn supervisor(&mut self) -> impl rules_substituted::Supervisor {
        RulesOnly
    }
    fn w(&mut self) -> impl worker::Behavior {
        self.scripts.scripted("w")
    }
    fn b(&mut self) -> impl worker::Behavior {
        self.scripts.scripted("b")
    }
    fn f(&mut self) -> impl feeder::Behavior {
        self.tap.take().expect("one feeder")
    }
}

impl rules_timed::Parts for Parts {
    fn supervisor(&mut self) -> impl rules_timed::Supervisor {
        RulesOnly
    }
    fn s(&mut self) -> impl rules_spender::Behavior {
        Spender(Arc::clone(&self.cost))
    }
}

impl rules_own_quality::Parts for Parts {
    fn supervisor(&mut self) -> impl rules_own_quality::Supervisor {
        RulesOnly
    }
    fn s(&mut self) -> impl rules_spender::Behavior {
        Spender(Arc::clone(&self.cost))
    }
}

/// Compound `base` running on a virtual clock, with what the test reaches of its
/// parts: the workers' scripts, the spender's cost, where the feeder hands its ports
/// over (if the compound has one).
struct Running {
    rig: CompoundRig,
    scripts: Scripts,
    cost: Arc<AtomicU64>,
    fed: Receiver<Feeder>,
}

/// Compound `base`, which `build` makes from the parts, run on a virtual clock.
fn running(build: impl FnOnce(Parts) -> Result<Component, CompoundError>) -> Running {
    let (tap, fed) = Tap::new();
    let parts = Parts {
        scripts: Scripts::new(),
        tap: Some(tap),
        cost: Arc::default(),
    };
    let (scripts, cost) = (parts.scripts.clone(), Arc::clone(&parts.cost));
    let mut rig = CompoundRig::on_virtual_clock(build(parts));
    rig.run();
    Running {
        rig,
        scripts,
        cost,
        fed,
    }
}

/// Settle every component on the rig's clock at its current time.
fn settle(rig: &CompoundRig) {
    rig.clock
        .as_ref()
        .expect("a virtual clock")
        .settle()
        .expect("the components settle");
}

/// The compound's supervisor state.
fn user_state(rig: &CompoundRig) -> Option<String> {
    rig.compound.snapshot().user_state
}

/// The compound's mapped `gain`.
fn gain(rig: &CompoundRig) -> Value {
    let monitor = rig.compound.snapshot();
    let (_, value) = monitor
        .variables
        .iter()
        .find(|(name, _)| name == "gain")
        .expect("the compound publishes `gain`");
    value.clone()
}

#[test]
fn a_rule_over_a_mapped_variable_is_evaluated_when_a_substitute_starts_standing_in() {
    quiet_component_panics();
    // `when gain == 5 -> switched;`, `gain` being `w.gain` (`RulesSubstituted`).
    let Running {
        rig, scripts, fed, ..
    } = running(|parts| rules_substituted::component("base", parts));
    let feed = fed.recv_timeout(WAIT).expect("the feeder started");
    let (w, b) = (rig.instance("w"), rig.instance("b"));
    wait_user(&w, "idle");
    wait_state(&b, State::Ready);
    wait_user(&rig.compound, "operating");
    // The substitute, standing by, holds the value that makes the rule true already:
    // its event is not the mapped variable's while `w` stands for itself.
    b.command(Command::Set("gain".to_owned(), Value::from(5_i64)))
        .expect("b takes its gain");
    b.wait_for(
        |m| {
            m.variables
                .iter()
                .any(|(n, v)| n == "gain" && *v == Value::from(5_i64))
        },
        WAIT,
    )
    .expect("b publishes its gain");
    // The compound takes b's event in the turn of a command given after it (which
    // the settling waits for), before `w` fails: that event cannot count later.
    rig.compound.command(Command::SetPriority(0)).expect("sync");
    settle(&rig);
    rig.advance(Duration::from_millis(1));
    assert_eq!(gain(&rig), Value::from(1_i64), "w's gain");
    assert_eq!(user_state(&rig).as_deref(), Some("operating"));
    // `w` fails in `busy`'s entry and cannot start again: `b` stands in, and sends
    // no event about its gain, which does not change.
    let w_script = scripts.of("w");
    w_script.start_fails.store(true, Ordering::SeqCst);
    w_script.panic_in(Some("busy.entry"));
    feed.kick.emit();
    rig.wait_steps(
        "w",
        1,
        |step| matches!(step, Step::Substituted { by } if by == "b"),
    );
    wait_state(&b, State::Running);
    // A round trip through the compound's control port: answered after the turn of
    // the substitution, whose rule evaluation it follows.
    rig.compound.command(Command::SetPriority(0)).expect("sync");
    settle(&rig);
    assert_eq!(gain(&rig), Value::from(5_i64), "b's gain, standing in");
    assert_eq!(
        user_state(&rig).as_deref(),
        Some("switched"),
        "the rule over `gain` was evaluated when b started standing in"
    );
    assert!(rig.shutdown().clean());
}

#[test]
fn a_rule_over_an_instance_time_reads_it_afresh_every_supervisor_period() {
    // `when s.elapsed_time >= 2ms -> late;`, supervisor period 10 ms (`RulesTimed`):
    // its first period began at 0, when the compound entered `watching`.
    let Running { rig, cost, .. } = running(|parts| rules_timed::component("base", parts));
    let s = rig.instance("s");
    wait_state(&s, State::Running);
    wait_user(&rig.compound, "watching");
    settle(&rig);
    // `s`'s periodic section at 5 ms takes 2 ms of the clock: its elapsed time is 2 ms
    // from 7 ms on, and `s` sends no event meanwhile (nothing refreshes the
    // supervisor's view of it by itself).
    cost.store(2, Ordering::SeqCst);
    let events = s.subscribe();
    rig.advance(Duration::from_millis(5));
    rig.advance(Duration::from_millis(2));
    assert_eq!(s.snapshot().elapsed_time, Duration::from_millis(2));
    rig.advance(Duration::from_millis(2));
    assert_eq!(
        user_state(&rig).as_deref(),
        Some("watching"),
        "no supervisor period since 0"
    );
    assert_eq!(events.try_iter().collect::<Vec<_>>(), [], "s sent no event");
    // At 10 ms, the supervisor's period: the rule reads `s`'s time now.
    rig.advance(Duration::from_millis(1));
    assert_eq!(user_state(&rig).as_deref(), Some("late"));
    assert!(rig.shutdown().clean());
}

#[test]
fn a_rule_over_the_compounds_own_quality_is_evaluated_when_its_control_port_sets_it() {
    // `when quality == lean -> leaning;` (`RulesOwnQuality`), no section.
    let Running { rig, .. } = running(|parts| rules_own_quality::component("base", parts));
    wait_user(&rig.compound, "operating");
    rig.advance(Duration::from_millis(20));
    assert_eq!(user_state(&rig).as_deref(), Some("operating"));
    // The command is handled in a turn of the compound, which the settling waits
    // for: its supervision sees its own quality changed.
    rig.compound
        .command(Command::SetQuality(1))
        .expect("the compound takes its quality");
    settle(&rig);
    let monitor = rig.compound.snapshot();
    assert_eq!(monitor.quality, 1);
    assert_eq!(monitor.user_state.as_deref(), Some("leaning"));
    assert!(rig.shutdown().clean());
}
