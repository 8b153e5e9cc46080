//! An implementation without `open_periodic`: the error names the missing stub.

use coolbot_compile_fail::generated::gate::{Behavior, Cx, OpenMay};

struct Gate;

impl Behavior for Gate {
    fn closed_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        let _ = cx;
        Ok(())
    }

    fn open_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        let _ = cx;
        Ok(())
    }

    fn open_choose(&mut self, cx: &mut Cx<'_>) -> Option<OpenMay> {
        let _ = cx;
        None
    }

    fn jammed_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        let _ = cx;
        Ok(())
    }

    fn on_stuck(&mut self, cx: &mut Cx<'_>, message: &str) {
        let _ = (cx, message);
    }
}

fn main() {
    let _ = Gate;
}
