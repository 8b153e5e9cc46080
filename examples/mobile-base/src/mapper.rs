//! `Mapper`: marks the cells of the room the base's odometry goes through, one pose
//! per transition. At quality `full` a cell is 0.1 m wide and mapping a pose costs
//! twelve units of the platform's processing ([`Platform::processing_cost`]: nothing
//! normally, 7 ms a unit while `--load` makes the processor short), at `coarse` a
//! cell is 0.5 m wide and a pose costs one unit. The runtime picks the quality from
//! the mapper's response times (`Context::quality()`): under the shortage, 84 ms a
//! pose at `full` is slower than the 20 to 40 ms between poses, so they queue and the
//! responses pass `max_response` (150 ms; no one section comes near it, so the
//! watchdog stays quiet); 7 ms at `coarse` keeps up.

use std::collections::HashSet;
use std::sync::Arc;

use crate::finite::Rejected;
use crate::generated::mapper::*;
use crate::world::Platform;

/// The mapper's code.
#[derive(Debug)]
pub struct Mapper {
    platform: Arc<Platform>,
    /// Cells visited, with the cell width (mm) they were mapped at.
    visited: HashSet<(u32, i64, i64)>,
    rejected: Rejected,
}

impl Mapper {
    /// A mapper on the shared platform.
    pub fn new(platform: Arc<Platform>) -> Mapper {
        Mapper {
            platform,
            visited: HashSet::new(),
            rejected: Rejected::default(),
        }
    }

    /// The poses dropped for a value that is not finite (`crate::finite`).
    pub fn rejected(&self) -> u64 {
        self.rejected.count()
    }
}

impl Behavior for Mapper {
    /// Maps one queued pose (the transition `on pose -> mapping` runs this).
    fn mapping_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        let pose = cx.inputs.pose.recv();
        let Some(pose) = self.rejected.check(pose, cx.rt.component_name(), "pose") else {
            return Ok(());
        };
        let (width_mm, units) = if cx.rt.quality() > 0 {
            (500, 1)
        } else {
            (100, 12)
        };
        let cost = self.platform.processing_cost(units);
        cx.rt.spend(cost);
        let cell = |metres: f64| (metres * 1000.0 / f64::from(width_mm)).floor() as i64;
        self.visited.insert((width_mm, cell(pose.x), cell(pose.y)));
        cx.vars.cells = u32::try_from(self.visited.len()).unwrap_or(u32::MAX);
        cx.vars.poses += 1;
        Ok(())
    }
}
