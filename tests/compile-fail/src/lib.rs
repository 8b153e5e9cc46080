//! The generated code the compile-fail cases (`tests/ui/*.rs`) implement, and a
//! correct implementation of it that builds (so a case fails for its own reason only).

/// The code `coolc` generated from `gate.cool`, checked in (`src/cool.rs`): a build
/// script running `coolc` would make the build of the cases compile `coolc` and
/// everything it depends on. coolc's tests check that it is what `coolc` generates
/// today (`generated_code_of_the_compile_fail_cases_is_current`).
#[allow(missing_docs, unused_qualifications)]
pub mod generated {
    include!("cool.rs");
}

use generated::gate::{Behavior, Cx, OpenMay};

/// A gate that closes again after one period open.
#[derive(Debug, Default)]
pub struct Gate {
    /// Periods spent open since it opened.
    periods: u32,
}

impl Behavior for Gate {
    fn closed_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        let _ = cx;
        Ok(())
    }

    fn open_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        cx.vars.openings += 1;
        self.periods = 0;
        Ok(())
    }

    fn open_periodic(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        let _ = cx;
        self.periods += 1;
        Ok(())
    }

    fn open_choose(&mut self, cx: &mut Cx<'_>) -> Option<OpenMay> {
        let _ = cx;
        (self.periods > 0).then_some(OpenMay::Closed)
    }

    fn jammed_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        let _ = cx;
        Ok(())
    }

    fn on_stuck(&mut self, cx: &mut Cx<'_>, message: &str) {
        let _ = (cx, message);
    }
}
