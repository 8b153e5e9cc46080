//! Filled-in `Warehouse`: no supervisor sections.

use crate::generated::warehouse::*;

/// Keeps nothing.
#[derive(Debug, Default)]
pub struct WarehouseSupervisor {}

impl Supervisor for WarehouseSupervisor {}

/// The crate's perception and navigation.
#[derive(Debug, Default)]
pub struct WarehouseParts {}

impl Parts for WarehouseParts {
    fn supervisor(&mut self) -> impl Supervisor {
        WarehouseSupervisor::default()
    }

    fn perception(&mut self) -> impl crate::generated::perception::Parts {
        crate::perception::PerceptionParts::default()
    }

    fn navigation(&mut self) -> impl crate::generated::navigation::Parts {
        crate::navigation::NavigationParts::default()
    }
}
