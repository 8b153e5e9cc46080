//! Filled-in converters.

use crate::generated::types::{Twist, Wheels};

/// The crate's converters.
#[derive(Debug, Default)]
pub struct Convert;

impl crate::generated::types::Converters for Convert {
    fn twist_to_wheels(from: &Twist) -> Wheels {
        // A differential drive 0.5 m wide.
        Wheels {
            left: from.linear - from.angular * 0.25,
            right: from.linear + from.angular * 0.25,
        }
    }
}
