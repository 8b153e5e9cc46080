//! The supervisor's adaptation policy (`coolbot::adapt::decide`, Figures 6 and 7) as a
//! pure function: a table of situations with the decision each must give, and
//! properties of the closed loop (the decisions applied to a model of the instances).

use std::time::Duration;

use coolbot::Pressure;
use coolbot::adapt::{
    Decision, FastestCorrection, Levels, Member, ProtectPriority, Reconfiguration, Selector,
    decide, decide_explained,
};
use proptest::prelude::*;

/// A member from `"name:priority:level/max:pressure"`, pressure `v` (violation), `s`
/// (spare) or `-`; a trailing `:z` marks it suspended by adaptation; `level` may be
/// `level>min` for a member whose own settings hold it at `min` or above
/// (`Member::min_level`).
fn member(text: &str) -> Member {
    let parts: Vec<&str> = text.split(':').collect();
    let (level, max) = parts[2].split_once('/').expect("level/max");
    let (level, min) = level.split_once('>').unwrap_or((level, "0"));
    Member {
        name: parts[0].to_owned(),
        priority: parts[1].parse().expect("priority"),
        level: level.parse().expect("level"),
        max_level: max.parse().expect("max"),
        min_level: min.parse().expect("min"),
        pressure: match parts[3] {
            "v" => Pressure::Violation,
            "s" => Pressure::Spare,
            _ => Pressure::Nominal,
        },
        load: parts.get(5).map_or(0.5, |load| load.parse().expect("load")),
        cpu_share: 0.0,
        period: Some(Duration::from_millis(10)),
        suspended: parts.get(4) == Some(&"z"),
    }
}

/// The decision as text, naming the member.
fn render(decision: Decision, members: &[Member]) -> String {
    let name = |i: usize| members[i].name.clone();
    match decision {
        Decision::Hold => "hold".to_owned(),
        Decision::Degrade(i) => format!("degrade {}", name(i)),
        Decision::RaiseCap => "raise cap".to_owned(),
        Decision::NotifyHigher => "notify higher".to_owned(),
        Decision::Suspend(i) => format!("suspend {}", name(i)),
        Decision::Exhausted => "exhausted".to_owned(),
        Decision::Resume(i) => format!("resume {}", name(i)),
        Decision::Promote(i) => format!("promote {}", name(i)),
        Decision::Clamp(i) => format!("clamp {}", name(i)),
        Decision::LowerFloor => "lower floor".to_owned(),
        Decision::ReportSpare => "report spare".to_owned(),
    }
}

fn levels(cap: u32, floor: u32, top: bool) -> Levels {
    Levels {
        cap,
        floor,
        top,
        reconfiguration: Reconfiguration::Report,
        settled: true,
    }
}

#[test]
fn decisions_table() {
    let suspend = Levels {
        reconfiguration: Reconfiguration::SuspendLowestPriority,
        ..levels(4, 3, true)
    };
    let unsettled = Levels {
        settled: false,
        ..levels(2, 1, true)
    };
    #[rustfmt::skip]
    let cases: &[(&str, &[&str], Levels, &str)] = &[
        ("nothing to do", &["a:1:0/4:-", "b:2:0/4:-"], levels(1, 0, true), "hold"),
        ("the violating member first", &["a:1:0/4:-", "b:2:0/4:v"], levels(1, 0, true), "degrade b"),
        ("then the lowest priority below the cap", &["a:1:0/4:-", "b:2:1/4:v", "c:0:0/4:-"], levels(1, 0, true), "degrade c"),
        ("among violators, the lowest priority", &["a:1:0/4:v", "b:0:0/4:v"], levels(1, 0, true), "degrade b"),
        ("equal priority: the higher load", &["a:1:0/4:v::0.4", "b:1:0/4:v::0.9"], levels(1, 0, true), "degrade b"),
        ("a member at its own top is not eligible", &["a:1:0/0:v", "b:0:0/4:-"], levels(1, 0, true), "degrade b"),
        ("all at the cap, top level: raise it", &["a:1:1/4:-", "b:2:1/4:v"], levels(1, 0, true), "raise cap"),
        ("all at the cap, nested: notify higher", &["a:1:1/4:-", "b:2:1/4:v"], levels(1, 0, false), "notify higher"),
        ("nested with nothing granted yet", &["a:1:0/4:v"], levels(0, 0, false), "notify higher"),
        ("the cap at the highest top: exhausted", &["a:1:4/4:v", "b:2:2/2:-"], levels(4, 3, true), "exhausted"),
        ("reconfiguration: suspend the lowest priority below the violators", &["a:5:4/4:v", "b:2:4/4:-", "c:1:4/4:-"], suspend, "suspend c"),
        ("reconfiguration: never a member as urgent as a violator", &["a:1:4/4:v", "b:1:4/4:-"], suspend, "exhausted"),
        ("a suspended member is resumed first when all have spare time", &["a:5:4/4:s", "c:1:4/4:-:z"], suspend, "resume c"),
        ("spare: promote the highest priority above the floor", &["a:1:2/4:s", "b:3:2/4:s"], levels(2, 1, true), "promote b"),
        ("then the most degraded", &["a:1:2/4:s", "b:1:3/4:s"], levels(3, 1, true), "promote b"),
        ("only members with spare time are promoted", &["a:1:2/4:-", "b:3:2/4:-"], levels(2, 1, true), "hold"),
        ("not while anyone violates", &["a:1:2/4:s", "b:3:1/4:v"], levels(2, 1, true), "degrade b"),
        ("not before the violations settled", &["a:1:2/4:s", "b:3:2/4:s"], unsettled, "hold"),
        ("all at the floor, top: lower it", &["a:1:1/4:s", "b:3:1/4:-"], levels(2, 1, true), "lower floor"),
        ("all at the floor, nested: report spare", &["a:1:1/4:s", "b:3:1/4:-"], levels(2, 1, false), "report spare"),
        ("nested, all nominal under a granted level: give it back", &["a:1:0/4:-"], levels(1, 0, false), "report spare"),
        ("nested, nothing granted: nothing to report", &["a:1:0/4:s"], levels(0, 0, false), "hold"),
        ("a member above a lowered cap is brought to it", &["a:1:3/4:-", "b:2:3/4:v"], levels(2, 1, false), "clamp b"),
        ("suspended members do not count as below the cap", &["a:1:1/4:v", "b:0:0/4:-:z"], levels(1, 0, true), "raise cap"),
        // Levels set on a member by other means (a command, its `degrade` plan step).
        ("a member held above the cap by its own settings is not clamped", &["a:1:3>3/4:-", "b:2:1/4:-"], levels(1, 0, true), "hold"),
        ("nor promoted below them", &["a:1:2>2/4:s", "b:2:0/4:s"], levels(2, 1, true), "hold"),
        ("above them it is promoted", &["a:1:3>2/4:s", "b:2:0/4:s"], levels(3, 2, true), "promote a"),
        ("clamped to them, not below", &["a:1:3>2/4:-"], levels(1, 0, false), "clamp a"),
        ("at its own level it counts as at the floor", &["a:1:2>2/4:s", "b:2:1/4:s"], levels(1, 0, true), "promote b"),
        ("and lets the floor come down", &["a:1:2>2/4:-", "b:2:1/4:s"], levels(2, 1, true), "lower floor"),
        ("nested, held by its own settings only: nothing to give back", &["a:1:1>1/4:s"], levels(1, 0, false), "report spare"),
    ];
    let mut failures = Vec::new();
    for (label, members, levels, expected) in cases {
        let members: Vec<Member> = members.iter().map(|m| member(m)).collect();
        let got = render(decide(&members, *levels, &ProtectPriority), &members);
        if got != *expected {
            failures.push(format!("{label}: expected `{expected}`, got `{got}`"));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn the_fastest_correction_selector_degrades_the_urgent_and_loaded_first() {
    let members: Vec<Member> = ["a:1:0/4:v::0.9", "b:5:0/4:v::0.2", "c:9:0/4:-::1.0"]
        .iter()
        .map(|m| member(m))
        .collect();
    let pick =
        |selector: &dyn Selector| render(decide(&members, levels(1, 0, true), selector), &members);
    assert_eq!(pick(&FastestCorrection), "degrade b");
    assert_eq!(pick(&ProtectPriority), "degrade a");
}

/// The model of a supervisor's instances: levels, tops, priorities; a decision is
/// applied as the compound applies it (a level changes by one, the cap and floor move
/// together, width 1).
#[derive(Debug, Clone)]
struct Model {
    members: Vec<Member>,
    cap: u32,
    floor: u32,
}

impl Model {
    fn new(tops: &[(u32, i32)]) -> Model {
        Model {
            members: tops
                .iter()
                .enumerate()
                .map(|(i, (max, priority))| Member {
                    name: format!("m{i}"),
                    priority: *priority,
                    level: 0,
                    max_level: *max,
                    min_level: 0,
                    pressure: Pressure::Nominal,
                    load: 0.5,
                    cpu_share: 0.0,
                    period: Some(Duration::from_millis(10)),
                    suspended: false,
                })
                .collect(),
            cap: 1,
            floor: 0,
        }
    }

    /// Set the verdicts, decide, check the invariants, apply; the decision.
    fn step(&mut self, verdicts: &[Pressure]) -> Decision {
        for (member, verdict) in self.members.iter_mut().zip(verdicts) {
            member.pressure = *verdict;
        }
        let levels = Levels {
            cap: self.cap,
            floor: self.floor,
            top: true,
            reconfiguration: Reconfiguration::Report,
            settled: true,
        };
        let decision = decide(&self.members, levels, &ProtectPriority);
        let violating = self
            .members
            .iter()
            .any(|m| m.pressure == Pressure::Violation);
        match decision {
            Decision::Degrade(i) => {
                let m = &mut self.members[i];
                assert!(violating, "degradation without a violation");
                assert!(
                    m.level < self.cap.min(m.max_level),
                    "{m:?} not below the cap {}",
                    self.cap
                );
                m.level += 1;
            }
            Decision::RaiseCap => {
                assert!(violating);
                assert!(
                    self.members
                        .iter()
                        .all(|m| m.level >= self.cap || m.level == m.max_level),
                    "cap {} raised with a member below it: {:?}",
                    self.cap,
                    self.members
                );
                self.cap += 1;
                self.floor = self.cap - 1;
            }
            Decision::Promote(i) => {
                assert!(!violating, "promotion during a violation");
                let m = &mut self.members[i];
                assert_eq!(m.pressure, Pressure::Spare);
                assert!(m.level > self.floor);
                m.level -= 1;
            }
            Decision::LowerFloor => {
                assert!(!violating);
                assert!(self.members.iter().all(|m| m.level <= self.floor));
                self.floor -= 1;
                self.cap = self.floor + 1;
            }
            Decision::Hold | Decision::Exhausted => {}
            other => panic!("unexpected at the top with Report: {other:?}"),
        }
        // The interval holds after every step.
        assert!(self.members.iter().all(|m| m.level <= self.cap), "{self:?}");
        assert!(self.cap - self.floor <= 1, "{self:?}");
        decision
    }
}

fn tops() -> impl Strategy<Value = Vec<(u32, i32)>> {
    prop::collection::vec((0u32..6, -5i32..5), 1..6)
}

proptest! {
    /// Whatever the pattern of violations, the interval holds, no member goes above
    /// the cap, and the cap rises only when every member is at it.
    #[test]
    fn the_homogeneity_interval_holds_under_any_verdicts(
        tops in tops(),
        rounds in prop::collection::vec(prop::collection::vec(0u8..3, 6), 1..80),
    ) {
        let mut model = Model::new(&tops);
        for round in rounds {
            let verdicts: Vec<Pressure> = round
                .iter()
                .map(|v| [Pressure::Nominal, Pressure::Violation, Pressure::Spare][*v as usize])
                .collect();
            model.step(&verdicts);
        }
    }

    /// A lasting violation degrades every member to its top (each step progresses),
    /// then reports exhaustion; lasting spare time brings every member back to 0 and
    /// the floor to 0.
    #[test]
    fn lasting_pressure_reaches_the_ends_of_the_ladders(tops in tops(), violator in 0usize..6) {
        let mut model = Model::new(&tops);
        let violator = violator % tops.len();
        let mut verdicts = vec![Pressure::Nominal; tops.len()];
        verdicts[violator] = Pressure::Violation;
        let total: u32 = tops.iter().map(|(max, _)| max).sum::<u32>() + 10;
        let mut exhausted = false;
        for _ in 0..total * 2 {
            if model.step(&verdicts) == Decision::Exhausted {
                exhausted = true;
                break;
            }
        }
        prop_assert!(exhausted, "{model:?}");
        prop_assert!(model.members.iter().all(|m| m.level == m.max_level), "{model:?}");

        let spare = vec![Pressure::Spare; tops.len()];
        for _ in 0..total * 3 {
            if model.step(&spare) == Decision::Hold {
                break;
            }
        }
        prop_assert!(model.members.iter().all(|m| m.level == 0), "{model:?}");
        prop_assert_eq!(model.floor, 0);
    }
}

/// A designer's own criterion (paper 3.6.2): here, the instance declared last is
/// degraded first, and promoted first.
struct LastDeclared;

impl Selector for LastDeclared {
    fn degrade(&self, _members: &[Member], candidates: &[usize]) -> usize {
        *candidates.last().expect("never empty")
    }

    fn promote(&self, _members: &[Member], candidates: &[usize]) -> usize {
        *candidates.last().expect("never empty")
    }
}

#[test]
fn the_selection_is_pluggable() {
    let degrade: Vec<Member> = ["a:9:0/4:v", "b:1:0/4:v", "c:5:0/4:-"]
        .iter()
        .map(|m| member(m))
        .collect();
    let decision = decide(&degrade, levels(1, 0, true), &LastDeclared);
    assert_eq!(render(decision, &degrade), "degrade c");
    let promote: Vec<Member> = ["a:9:2/4:s", "b:1:2/4:s", "c:5:1/4:s"]
        .iter()
        .map(|m| member(m))
        .collect();
    let decision = decide(&promote, levels(2, 1, true), &LastDeclared);
    assert_eq!(render(decision, &promote), "promote b");
    // The default promotion order, for comparison: the highest priority first.
    let decision = decide(&promote, levels(2, 1, true), &ProtectPriority);
    assert_eq!(render(decision, &promote), "promote a");
}

/// A selector that answers outside the candidates.
struct Wrong;

impl Selector for Wrong {
    fn degrade(&self, members: &[Member], _candidates: &[usize]) -> usize {
        members.len() + 7
    }

    fn promote(&self, _members: &[Member], candidates: &[usize]) -> usize {
        // A member, but not a candidate (the one before the first candidate).
        candidates[0].wrapping_sub(1)
    }
}

#[test]
fn a_selector_answer_outside_the_candidates_is_ignored_with_a_note() {
    let degrade: Vec<Member> = ["a:9:0/4:v", "b:1:0/4:-"]
        .iter()
        .map(|m| member(m))
        .collect();
    let (decision, note) = decide_explained(&degrade, levels(1, 0, true), &Wrong);
    assert_eq!(
        render(decision, &degrade),
        "degrade a",
        "the default choice"
    );
    let note = note.expect("a note");
    assert!(note.contains("chose 9 to degrade"), "{note}");
    let promote: Vec<Member> = ["a:9:2/4:-", "b:1:2/4:s"]
        .iter()
        .map(|m| member(m))
        .collect();
    let (decision, note) = decide_explained(&promote, levels(2, 1, true), &Wrong);
    assert_eq!(render(decision, &promote), "promote b");
    assert!(note.expect("a note").contains("to promote"));
    // `decide` gives the same decision; a good answer has no note.
    assert_eq!(decide(&promote, levels(2, 1, true), &Wrong), decision);
    assert_eq!(
        decide_explained(&promote, levels(2, 1, true), &ProtectPriority).1,
        None
    );
}
