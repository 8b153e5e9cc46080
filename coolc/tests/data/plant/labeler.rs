//! Filled-in `Labeler`: `Label` is an extern packet (`std::string::String`).

use crate::generated::labeler::*;
use crate::generated::types::Label;

/// Sends `label 1`, `label 2`, ...
#[derive(Debug, Default)]
pub struct Labeler {}

impl Behavior for Labeler {
    fn labeling_periodic(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        cx.vars.sent += 1;
        let label: Label = format!("label {}", cx.vars.sent);
        cx.outputs.out.send(label);
        Ok(())
    }
}
