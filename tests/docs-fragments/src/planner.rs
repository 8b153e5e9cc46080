//! The code of component `Planner`: fill in the stubs.
//!
//! `coolc` wrote this file once and never overwrites it: when the description gains a
//! state, section, exception or pull output, `coolc compile` adds the new stubs at the
//! end of the `impl Behavior` block and leaves everything else as you wrote it. A
//! panic in a stub is caught by the runtime and takes the component to
//! `running_error`.

use crate::generated::planner::*;

/// What a `Planner` keeps between sections.
#[derive(Debug, Default)]
pub struct Planner {}

impl Behavior for Planner {}
