//! The variables a component publishes after each call: the events of an automaton
//! that reports its changes by comparing typed copies
//! ([`Changes::compare`](crate::Changes::compare), as generated glue does) are those of
//! one left to the default, which reads every variable with `get`.

use super::Harness;
use crate::PortSet;
use crate::automaton::{Automaton, Changes, ValueRefused};
use crate::monitor::MonitorEvent;
use crate::spec::{Spec, StateSpec, VarKind, VarSpec};
use crate::system::Component;
use crate::value::Value;

const fn var(name: &'static str, ty: &'static str) -> VarSpec {
    VarSpec::new(name, VarKind::Controllable, ty)
}

static SPEC: Spec = Spec::new("Published", "")
    .with_states(&[StateSpec::new("idle")])
    .with_variables(&[
        var("count", "u64"),
        var("x", "f64"),
        var("label", "String"),
        var("seen", "[u64]"),
    ]);

/// The variables; setting `count` also appends it to `seen` (a variable changed by
/// the component, not by the command), and `get` panics on label `boom`.
#[derive(Clone, Default)]
struct Vars {
    count: u64,
    x: f64,
    label: String,
    seen: Vec<u64>,
}

impl Vars {
    fn set(&mut self, variable: usize, value: &Value) -> Result<(), ValueRefused> {
        match variable {
            0 => {
                self.count = u64::try_from(value)?;
                self.seen.push(self.count);
            }
            1 => self.x = f64::try_from(value)?,
            2 => self.label = String::try_from(value)?,
            _ => return Err(ValueRefused::not_settable(&SPEC, variable)),
        }
        Ok(())
    }

    fn label(&self) -> Value {
        assert_ne!(self.label, "boom", "a getter that panics");
        Value::from(self.label.clone())
    }

    fn seen(seen: &[u64]) -> Value {
        Value::List(seen.iter().map(|n| Value::from(*n)).collect())
    }

    fn get(&self, variable: usize) -> Value {
        match variable {
            0 => Value::from(self.count),
            1 => Value::from(self.x),
            2 => self.label(),
            3 => Vars::seen(&self.seen),
            _ => Value::Unit,
        }
    }
}

/// Leaves publication to the default: every variable read with `get`.
struct Plain(Vars);

impl Automaton for Plain {
    fn spec(&self) -> &'static Spec {
        &SPEC
    }
    fn set(&mut self, variable: usize, value: &Value) -> Result<(), ValueRefused> {
        self.0.set(variable, value)
    }
    fn get(&self, variable: usize) -> Value {
        self.0.get(variable)
    }
}

/// Reports only what differs from its typed copies (the label left to `get`).
struct Typed {
    vars: Vars,
    count: Option<u64>,
    x: Option<f64>,
    seen: Option<Vec<u64>>,
}

impl Automaton for Typed {
    fn spec(&self) -> &'static Spec {
        &SPEC
    }
    fn set(&mut self, variable: usize, value: &Value) -> Result<(), ValueRefused> {
        self.vars.set(variable, value)
    }
    fn get(&self, variable: usize) -> Value {
        self.vars.get(variable)
    }
    fn changed_variables(&mut self, changes: &mut Changes<'_>) {
        let vars = &self.vars;
        changes.compare(0, &mut self.count, &vars.count, |n| Value::from(*n));
        changes.compare(1, &mut self.x, &vars.x, |x| Value::from(*x));
        changes.read(2);
        changes.compare(3, &mut self.seen, &vars.seen, |seen| Vars::seen(seen));
    }
}

/// Variables by name, in order.
type Variables = Vec<(String, Value)>;

/// Runs the same commands on `automaton`: the monitor's variables after start, and
/// every variable event after.
fn published<A: Automaton>(
    automaton: A,
    vars: impl Fn(&mut A) -> &mut Vars,
) -> (Variables, Variables) {
    let mut h = Harness::new(Component::new("v", Box::new(automaton), PortSet::new())).unwrap();
    let first = h.monitor().variables;
    let events = h.handle.subscribe();
    h.run().unwrap();
    let set = |h: &mut Harness, name: &str, value: Value| h.set(name, value).unwrap();
    set(&mut h, "count", Value::UInt(1));
    // The same count: only `seen` changes.
    set(&mut h, "count", Value::UInt(1));
    // A NaN never equals the published one.
    set(&mut h, "x", Value::Float(f64::NAN));
    set(&mut h, "x", Value::Float(f64::NAN));
    set(&mut h, "x", Value::Float(0.0));
    // -0.0 == 0.0: nothing to publish.
    set(&mut h, "x", Value::Float(-0.0));
    set(&mut h, "label", Value::from("a"));
    // `get` panics: the label stays `a`, the others are published.
    set(&mut h, "label", Value::from("boom"));
    set(&mut h, "count", Value::UInt(2));
    set(&mut h, "label", Value::from("b"));
    // Changed behind the runtime's back (a typed harness's behaviour, say):
    // published after the next call.
    let automaton = h.automaton_mut::<A>().unwrap();
    vars(automaton).x = 7.5;
    vars(automaton).seen.clear();
    set(&mut h, "label", Value::from("b"));
    let events = events
        .try_iter()
        .filter_map(|event| match event {
            MonitorEvent::Variable { name, value } => Some((name, value)),
            _ => None,
        })
        .collect();
    (first, events)
}

#[test]
fn typed_change_detection_publishes_what_reading_every_variable_does() {
    let plain = published(Plain(Vars::default()), |plain| &mut plain.0);
    let typed = published(
        Typed {
            vars: Vars::default(),
            count: None,
            x: None,
            seen: None,
        },
        |typed| &mut typed.vars,
    );
    let named = |name: &str, value: Value| (name.to_owned(), value);
    assert_eq!(
        plain.0,
        [
            named("count", Value::UInt(0)),
            named("x", Value::Float(0.0)),
            named("label", Value::from("")),
            named("seen", Value::List(Vec::new())),
        ],
        "the first publication, before start"
    );
    let list = |seen: &[u64]| Vars::seen(seen);
    let expected = [
        named("count", Value::UInt(1)),
        named("seen", list(&[1])),
        named("seen", list(&[1, 1])),
        named("x", Value::Float(f64::NAN)),
        named("x", Value::Float(f64::NAN)),
        named("x", Value::Float(0.0)),
        named("label", Value::from("a")),
        named("count", Value::UInt(2)),
        named("seen", list(&[1, 1, 2])),
        named("label", Value::from("b")),
        named("x", Value::Float(7.5)),
        named("seen", list(&[])),
    ];
    // (A NaN equals nothing: compared by its text.)
    let text = |events: &[(String, Value)]| format!("{events:?}");
    assert_eq!(text(&plain.1), text(&expected));
    assert_eq!(text(&typed.0), text(&plain.0));
    assert_eq!(text(&typed.1), text(&plain.1));
}

#[test]
fn compare_reports_a_change_once_and_keeps_its_copy_when_the_value_panics() {
    let mut reported = Vec::new();
    let mut changes = Changes {
        reported: &mut reported,
    };
    let mut published = None;
    changes.compare(0, &mut published, &1u64, |_| Value::UInt(1));
    changes.compare(0, &mut published, &1u64, |_| Value::UInt(1));
    assert_eq!(published, Some(1));
    changes.compare(1, &mut published, &2u64, |_| -> Value {
        panic!("a conversion that panics")
    });
    assert_eq!(published, Some(1), "not reported: compared again next time");
    changes.compare(1, &mut published, &2u64, |_| Value::UInt(2));
    assert_eq!(published, Some(2));
    let mut nan = None;
    changes.compare(2, &mut nan, &f64::NAN, |_| Value::Float(f64::NAN));
    changes.compare(2, &mut nan, &f64::NAN, |_| Value::Float(f64::NAN));
    let indices: Vec<usize> = reported.iter().map(|(index, _)| *index).collect();
    assert_eq!(indices, [0, 1, 2, 2]);
}
