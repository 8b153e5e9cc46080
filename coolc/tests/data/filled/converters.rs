//! Filled-in converters.

use crate::generated::types::{Path, Twist};

/// Implements the generated `Converters` trait.
#[derive(Debug, Default)]
pub struct Convert;

impl crate::generated::types::Converters for Convert {
    fn path_to_twist(from: &Path) -> Twist {
        // Head for the last pose at one metre per second.
        match from.poses.last() {
            Some(goal) if goal.x != 0.0 || goal.y != 0.0 => Twist {
                linear: 1.0,
                angular: goal.y.atan2(goal.x),
            },
            _ => Twist::default(),
        }
    }
}
