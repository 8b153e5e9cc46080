//! A generated compound whose supervisor controls its instance (`tests/data/command`):
//! the crate builds clippy-clean and rustfmt-clean, and its run tests show the
//! supervisor suspending, resuming and slowing its drive through the typed handles
//! of the generated `Cx`, choosing a `may` target, and rules reading the compound's
//! own result, error and CPU time and the drive's controllable speed and elapsed
//! time.

use crate::common;

use common::{compile, data, fill_check_and_run};

#[test]
fn a_generated_supervisor_commands_its_instances() {
    let dir = tempfile::tempdir().unwrap();
    let description = dir.path().join("command.cool");
    std::fs::copy(data("command/command.cool"), &description).unwrap();
    let krate = dir.path().join("command");
    compile(&description, &krate, "command");
    fill_check_and_run(
        &krate,
        "command",
        &["drive.rs", "base.rs"],
        &[
            "the_supervisor_suspends_slows_and_resumes_its_drive",
            "a_may_choice_and_rules_over_the_compounds_own_result_and_times_move_the_supervisor",
        ],
    );
}
