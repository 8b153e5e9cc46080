//! Filled-in converters.

use crate::generated::types::{Twist, Wheels};

/// Implements the generated `Converters` trait.
#[derive(Debug, Default)]
pub struct Convert;

impl crate::generated::types::Converters for Convert {
    fn twist_to_wheels(from: &Twist) -> Wheels {
        Wheels {
            left: from.linear - from.angular,
            right: from.linear + from.angular,
        }
    }
}
