//! The code of component `SimRangeServer`: fill in the stubs.
//!
//! `coolc` wrote this file once and never overwrites it: when the description gains a
//! state, section, exception or pull output, `coolc compile` adds the new stubs at the
//! end of the `impl Behavior` block and leaves everything else as you wrote it. A
//! panic in a stub is caught by the runtime and takes the component to
//! `running_error`.

use crate::generated::sim_range_server::*;

/// What a `SimRangeServer` keeps between sections.
#[derive(Debug, Default)]
pub struct SimRangeServer {}

impl Behavior for SimRangeServer {
    fn streaming_periodic(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        // State `streaming`, periodic section: runs once per period while in the state.
        let _ = cx;
        Ok(())
    }
}
