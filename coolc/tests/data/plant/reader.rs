//! Filled-in `Reader`: counts the labels (an extern packet) and keeps the last one
//! and its length.

use crate::generated::reader::*;

/// No state of its own.
#[derive(Debug, Default)]
pub struct Reader {}

impl Behavior for Reader {
    fn reading_periodic(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        while let Some(label) = cx.inputs.input.recv() {
            cx.vars.got += 1;
            cx.vars.last_len = label.len() as u64;
            cx.vars.last = Some(label);
        }
        Ok(())
    }
}
