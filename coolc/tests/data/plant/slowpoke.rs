//! Filled-in `Slowpoke` supervisor: its periodic sections stall as long as
//! `stall_ms` says, once.

use crate::generated::slowpoke::*;

/// No state of its own.
#[derive(Debug, Default)]
pub struct SlowpokeSupervisor {}

impl SlowpokeSupervisor {
    /// Slow code, as a supervisor's section may be: longer than `max_response`.
    fn stall(cx: &mut Cx<'_>) {
        let stall = std::mem::take(&mut cx.vars.stall_ms);
        if stall > 0 {
            std::thread::sleep(std::time::Duration::from_millis(stall));
        }
    }
}

impl Supervisor for SlowpokeSupervisor {
    fn watching_periodic(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        Self::stall(cx);
        Ok(())
    }

    fn leaning_periodic(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        Self::stall(cx);
        Ok(())
    }
}

/// The gauge runs this crate's `Gauge`.
#[derive(Debug, Default)]
pub struct SlowpokeParts {}

impl Parts for SlowpokeParts {
    fn supervisor(&mut self) -> impl Supervisor {
        SlowpokeSupervisor::default()
    }

    fn g(&mut self) -> impl crate::generated::gauge::Behavior {
        crate::gauge::Gauge::default()
    }
}
