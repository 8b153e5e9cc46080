//! The type guarantees of generated code, pinned by cases that must not compile
//! (`tests/ui/*.rs`, each with the compiler's message in `*.stderr`): a `may` choice
//! of a state outside the `may` list is unrepresentable, a missing stub is a
//! compile error that names the stub, and setting an instance's observable variable
//! through its typed handle is a compile error that says why. The correct implementation in `src/lib.rs`
//! builds, and runs in its harness here.

#[test]
fn misuse_of_generated_code_does_not_compile() {
    let cases = trybuild::TestCases::new();
    cases.compile_fail("tests/ui/*.rs");
}

#[test]
fn the_correct_implementation_builds_and_runs() {
    use coolbot_compile_fail::generated::gate::{Harness, UserState};
    let mut gate = Harness::running(coolbot_compile_fail::Gate::default()).unwrap();
    assert_eq!(gate.user_state(), Some(UserState::Closed));
    gate.tick_push().unwrap();
    gate.settle().unwrap();
    assert_eq!(gate.user_state(), Some(UserState::Open));
    gate.advance(std::time::Duration::from_millis(99)).unwrap();
    assert_eq!(gate.user_state(), Some(UserState::Open));
    // The first periodic section, then `open`'s choice: back to `closed`.
    gate.advance(std::time::Duration::from_millis(1)).unwrap();
    assert_eq!(gate.user_state(), Some(UserState::Closed));
    assert_eq!(gate.vars().openings, 1);
}
