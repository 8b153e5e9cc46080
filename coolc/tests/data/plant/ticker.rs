//! Filled-in `Ticker` supervisor: counts its periodic sections in the local `ticks`.

use crate::generated::ticker::*;

/// No state of its own: the count is the compound's local variable.
#[derive(Debug, Default)]
pub struct TickerSupervisor {}

impl Supervisor for TickerSupervisor {
    fn counting_periodic(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        cx.vars.ticks += 1;
        Ok(())
    }

    fn counted_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        let _ = cx;
        Ok(())
    }
}

/// The gauge runs this crate's `Gauge`.
#[derive(Debug, Default)]
pub struct TickerParts {}

impl Parts for TickerParts {
    fn supervisor(&mut self) -> impl Supervisor {
        TickerSupervisor::default()
    }

    fn g(&mut self) -> impl crate::generated::gauge::Behavior {
        crate::gauge::Gauge::default()
    }
}
