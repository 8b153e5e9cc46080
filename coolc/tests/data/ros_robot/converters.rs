//! Filled-in converters: a ROS 2 scan to the project's own packet.

use crate::generated::types::{LaserScan, Ranges};

/// Implements the generated `Converters` trait.
#[derive(Debug, Default)]
pub struct Convert;

impl crate::generated::types::Converters for Convert {
    fn scan_to_ranges(from: &LaserScan) -> Ranges {
        Ranges {
            stamp: from.header.stamp.sec,
            frame: from.header.frame_id.clone(),
            ranges: from.ranges.clone(),
            nearest: from.ranges.iter().copied().fold(f32::INFINITY, f32::min),
        }
    }
}
