//! Filled-in `Probe` supervisor: counts how often it saw the gauge right.

use crate::generated::probe::*;

/// No state of its own.
#[derive(Debug, Default)]
pub struct ProbeSupervisor {}

impl Supervisor for ProbeSupervisor {
    fn seen_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        cx.vars.count += 1;
        cx.vars.opt = Some(3);
        cx.vars.pkt = Some(crate::generated::types::Count { n: 3 });
        Ok(())
    }

    fn done_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        let _ = cx;
        Ok(())
    }

    fn lowered_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        let _ = cx;
        Ok(())
    }

    fn paced_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        let _ = cx;
        Ok(())
    }

    fn retimed_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        let _ = cx;
        Ok(())
    }

    fn failed_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        let _ = cx;
        Ok(())
    }
}

/// The gauge runs this crate's `Gauge`.
#[derive(Debug, Default)]
pub struct ProbeParts {}

impl Parts for ProbeParts {
    fn supervisor(&mut self) -> impl Supervisor {
        ProbeSupervisor::default()
    }

    fn g(&mut self) -> impl crate::generated::gauge::Behavior {
        crate::gauge::Gauge::default()
    }

    fn spare(&mut self) -> impl crate::generated::gauge::Behavior {
        crate::gauge::Gauge::default()
    }
}
