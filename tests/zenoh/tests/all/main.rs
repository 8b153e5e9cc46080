//! The network layer's integration tests, one module a former test file, in one binary
//! (one link of the dependency graph instead of one per file). Files of their own in
//! `tests/`: the tests that install a process-wide tracing subscriber, the snapshot
//! tests (`insta` names a snapshot after its file) and the ROS 2 tests (their Python
//! helper module is shared with the example robot's).

mod bridges;
mod foxglove;
mod hostile;
mod isolation;
mod limits;
mod placement;
mod remote_death;
mod security;
mod shm;
