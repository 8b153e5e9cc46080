//! A controllable variable's range (`controllable max_speed: f64 = 0.5 in 0.0..=1.0;`):
//! a set outside it is refused by the runtime, with the range in the reason, whoever
//! asks (the component's control port, a compound that maps the variable); the value
//! stays what it was. NaN lies in no range.

use coolbot::harness::HarnessError;
use coolbot::{Command, State, System, Value, VarRange};
use coolbot_runtime_tests::generated::{governor, throttle};
use coolbot_runtime_tests::support::WAIT;

#[derive(Debug, Default)]
struct Throttle;

impl throttle::Behavior for Throttle {
    fn idle_entry(&mut self, cx: &mut throttle::Cx<'_>) -> coolbot::SectionResult {
        let _ = cx;
        Ok(())
    }
}

#[derive(Debug, Default)]
struct Quiet;

impl governor::Supervisor for Quiet {}

#[derive(Debug, Default)]
struct Parts;

impl governor::Parts for Parts {
    fn supervisor(&mut self) -> impl governor::Supervisor {
        Quiet
    }

    fn throttle(&mut self) -> impl throttle::Behavior {
        Throttle
    }
}

/// The reason a harness gives for refusing to set `name` to `value`.
fn refusal(harness: &mut throttle::Harness<Throttle>, name: &str, value: Value) -> String {
    match harness.inner().set(name, value.clone()) {
        Err(HarnessError::Rejected { reason, .. }) => reason,
        other => panic!("`{name}` = {value:?} was not refused: {other:?}"),
    }
}

#[test]
fn the_spec_carries_each_declared_range() {
    let ranges: Vec<(&str, Option<VarRange>)> = throttle::SPEC
        .variables
        .iter()
        .map(|v| (v.name, v.range))
        .collect();
    assert_eq!(
        ranges,
        [
            ("max_speed", Some(VarRange::Float(0.0, 1.0))),
            ("gear", Some(VarRange::Int(-1, 5))),
            ("gain", Some(VarRange::F32(0.7, 1.0))),
        ]
    );
    // A compound that maps `max_speed` carries its range.
    let compound = governor::component("governor", Parts).expect("the compound builds");
    let mapped: Vec<(&str, Option<VarRange>)> = compound
        .spec()
        .variables
        .iter()
        .map(|v| (v.name, v.range))
        .collect();
    assert_eq!(mapped, [("max_speed", Some(VarRange::Float(0.0, 1.0)))]);
}

#[test]
fn numbers_are_judged_however_they_come_and_anything_else_is_refused() {
    let mut harness = throttle::Harness::running(Throttle).unwrap();
    // A JSON number (what a command decoded from JSON may carry) is a number too.
    assert_eq!(
        refusal(&mut harness, "gear", Value::Json(serde_json::json!(100))),
        "invalid value for `gear`: 100 is outside its range -1..=5"
    );
    assert!(
        refusal(
            &mut harness,
            "max_speed",
            Value::Json(serde_json::json!(100.0))
        )
        .contains("100.0 is outside its range 0.0..=1.0")
    );
    harness
        .inner()
        .set("max_speed", Value::Json(serde_json::json!(0.75)))
        .unwrap();
    assert_eq!(harness.vars().max_speed, 0.75);
    // Not a number at all: refused by the range, which takes numbers only.
    assert!(
        refusal(&mut harness, "max_speed", Value::Str("fast".to_owned()))
            .contains("is not a number, and the variable takes numbers in 0.0..=1.0")
    );
    // An f32 is judged as the f32 it is stored as: 0.7 is its low end, and the value
    // read back (0.699999988...) can be set again.
    harness.inner().set("gain", Value::Float(0.7)).unwrap();
    let stored = harness.inner().variable("gain").expect("gain");
    harness.inner().set("gain", stored).unwrap();
    assert!(
        refusal(&mut harness, "gain", Value::Float(0.69))
            .contains("is outside its range 0.7..=1.0")
    );
}

#[test]
fn a_component_built_with_a_value_outside_its_range_does_not_start() {
    let vars = throttle::Vars {
        max_speed: 3.0,
        ..throttle::Vars::default()
    };
    let harness = throttle::Harness::with(Throttle, throttle::Config::default(), vars).unwrap();
    assert_eq!(harness.state(), State::StartingError);
    assert_eq!(
        harness.error().as_deref(),
        Some("the initial value of `max_speed`: 3.0 is outside its range 0.0..=1.0")
    );
}

#[test]
fn a_set_outside_the_range_is_refused_with_the_range_and_the_value_stays() {
    let mut harness = throttle::Harness::running(Throttle).unwrap();
    // Inside, both ends included.
    for speed in [0.0, 0.8, 1.0] {
        harness
            .inner()
            .set("max_speed", Value::Float(speed))
            .unwrap();
        assert_eq!(harness.vars().max_speed, speed);
    }
    assert_eq!(
        refusal(&mut harness, "max_speed", Value::Float(1.5)),
        "invalid value for `max_speed`: 1.5 is outside its range 0.0..=1.0"
    );
    assert_eq!(
        refusal(&mut harness, "max_speed", Value::Float(-0.1)),
        "invalid value for `max_speed`: -0.1 is outside its range 0.0..=1.0"
    );
    assert!(
        refusal(&mut harness, "max_speed", Value::Float(f64::NAN)).contains("NaN is outside"),
        "NaN lies in no range"
    );
    // An integer given for a float variable is judged by its value too.
    assert!(refusal(&mut harness, "max_speed", Value::UInt(100)).contains("100.0 is outside"));
    assert_eq!(
        harness.vars().max_speed,
        1.0,
        "the last value accepted stays"
    );

    // Integers, signed and unsigned, compared exactly.
    harness.inner().set("gear", Value::Int(-1)).unwrap();
    harness.inner().set("gear", Value::UInt(5)).unwrap();
    assert_eq!(harness.vars().gear, 5);
    assert_eq!(
        refusal(&mut harness, "gear", Value::Int(-2)),
        "invalid value for `gear`: -2 is outside its range -1..=5"
    );
    assert!(refusal(&mut harness, "gear", Value::UInt(u64::MAX)).contains("is outside its range"));
    assert_eq!(harness.vars().gear, 5);
    assert_eq!(harness.state(), State::Running, "a refusal is no fault");
}

#[test]
fn a_compound_mapping_the_variable_meets_the_same_range() {
    let mut system = System::new();
    let governor = system
        .add(governor::component("governor", Parts).expect("the compound builds"))
        .unwrap();
    system.run_all().unwrap();
    let throttle = governor.instance("throttle").expect("its instance");

    let refused = governor
        .command(Command::Set("max_speed".to_owned(), Value::Float(2.0)))
        .expect_err("2.0 is outside 0.0..=1.0");
    assert_eq!(
        refused.reason, "invalid value for `max_speed`: 2.0 is outside its range 0.0..=1.0",
        "refused by the compound itself, which carries the range of what it maps"
    );
    // The instance itself refuses it too, and keeps its default.
    let refused = throttle
        .command(Command::Set("max_speed".to_owned(), Value::Float(2.0)))
        .expect_err("2.0 is outside 0.0..=1.0");
    assert!(
        refused.reason.contains("outside its range"),
        "{}",
        refused.reason
    );
    assert_eq!(
        throttle.snapshot().variables[0],
        ("max_speed".to_owned(), Value::Float(0.5))
    );

    // Inside: set through the compound, seen on the instance.
    governor
        .command(Command::Set("max_speed".to_owned(), Value::Float(0.25)))
        .expect("0.25 is inside");
    throttle
        .wait_for(|m| m.variables[0].1 == Value::Float(0.25), WAIT)
        .expect("the instance's max_speed becomes 0.25");
    assert!(system.shutdown().clean());
}
