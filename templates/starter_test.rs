//! A test of component `{{ c.type_name }}` alone, in its generated harness
//! (`generated::{{ c.module }}::Harness`): built with in-memory ports on a virtual
//! clock, driven on the test's thread exactly as its component thread would run it,
//! so the test is deterministic and waits for no real time.
//!
//! `coolc new` wrote this file once and never changes it: it is yours.

use std::time::Duration;

use ::{{ lib }}::generated::{{ c.module }}::{Harness, UserState};
use ::{{ lib }}::{{ c.module }}::{{ c.user_struct }};

#[test]
fn counts_its_periods_then_finishes() {
    let mut harness = Harness::running({{ c.user_struct }}::default()).unwrap();
    assert_eq!(harness.user_state(), Some(UserState::Counting));
    // Period 100ms: nine periodic sections by 950ms, each with a beat.
    harness.advance(Duration::from_millis(950)).unwrap();
    assert_eq!(harness.vars().count, 9);
    assert_eq!(harness.ticks_beat().unwrap(), 9);
    assert_eq!(harness.user_state(), Some(UserState::Counting));
    // The tenth reaches `limit`: `counting` chooses `done`, whose entry sets the result.
    harness.advance(Duration::from_millis(50)).unwrap();
    assert_eq!(harness.user_state(), Some(UserState::Done));
    let counted = coolbot::TaskResult::Success("counted 10 periods".to_owned());
    assert_eq!(harness.result(), counted);
}
