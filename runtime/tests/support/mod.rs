//! What `exports_tick_pull.rs` needs beside its test: port-only components over
//! hand-built specs (`shell`), for a `tick` output declared `pull`, which the language
//! refuses and the runtime supports; and the exported-port scenario (`exports`), which
//! `tests/runtime/tests/all/exports.rs` runs on generated components. Every other runtime
//! test runs components coolc generates (`tests/runtime`).

pub mod exports;
pub mod shell;

use std::time::Duration;

/// How long tests wait for anything (generous: the machine is shared).
pub const WAIT: Duration = Duration::from_secs(10);

/// Wait until `condition` holds, checking every millisecond (for conditions on test
/// state that no monitoring event announces); panics with `what` after `WAIT`.
pub fn eventually(condition: impl Fn() -> bool, what: &str) {
    let deadline = std::time::Instant::now() + WAIT;
    while !condition() {
        assert!(
            std::time::Instant::now() < deadline,
            "timed out waiting for: {what}"
        );
        std::thread::sleep(Duration::from_millis(1));
    }
}
