//! The code of component `{{ c.type_name }}`, filled in by `coolc new` as an example.
//!
//! `coolc` wrote this file once and never overwrites it: when the description gains
//! a state, section, exception or pull output, `coolc compile` adds the new stubs at
//! the end of the `impl Behavior` block and leaves everything else as you wrote it.

use crate::generated::{{ c.module }}::*;

/// What `{{ c.type_name }}` keeps between sections.
#[derive(Debug, Default)]
pub struct {{ c.user_struct }} {}

impl Behavior for {{ c.user_struct }} {
    fn counting_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        // Count from zero each time the state is entered.
        cx.vars.count = 0;
        Ok(())
    }

    fn counting_periodic(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        cx.vars.count += 1;
        cx.outputs.beat.emit();
        Ok(())
    }

    fn counting_choose(&mut self, cx: &mut Cx<'_>) -> Option<CountingMay> {
        // Leave for `done` once the configured number of periods has elapsed.
        (cx.vars.count >= cx.config.limit).then_some(CountingMay::Done)
    }

    fn done_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        let summary = format!("counted {} periods", cx.vars.count);
        cx.rt.set_result(coolbot::TaskResult::Success(summary));
        Ok(())
    }
}
