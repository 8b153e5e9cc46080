//! The example robot's integration tests, one module a former test file, in one binary
//! (one link of the dependency graph instead of one per file). Files of their own in
//! `tests/`: the robot's tests (they install a panic hook), the hostile peer's (its
//! `fuzz` module is shared with a bench) and the ROS 2 tests (their Python helper
//! module is the network layer's).

mod distributed;
mod docs;
mod drivers;
mod finite;
mod process;
mod ranges;
mod replay;
mod supervisor;
mod support;
mod teleop;
mod top;
