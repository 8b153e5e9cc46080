//! The converters the descriptions under `cool/` declare: one `Converters` trait for
//! the crate, so one implementation for every test.

use std::sync::atomic::{AtomicU64, Ordering};

use crate::generated::types::Converters;

/// Implements every converter of `cool/*.cool`.
pub struct Convert;

/// How many times `CountedCopy` ran (`compound.rs` reads it).
pub static COPIES: AtomicU64 = AtomicU64::new(0);

impl Converters for Convert {
    /// `compound.cool`'s `NumberText`.
    fn number_text(from: &u64) -> String {
        format!("#{from}")
    }
    /// `compound.cool`'s `CountedCopy`.
    fn counted_copy(from: &u64) -> u64 {
        COPIES.fetch_add(1, Ordering::SeqCst);
        *from
    }
    /// `compound.cool`'s `PlusOne`.
    fn plus_one(from: &u64) -> u64 {
        from + 1
    }
    /// `compound.cool`'s `PlusTen`.
    fn plus_ten(from: &u64) -> u64 {
        from + 10
    }
    /// `redundancy.cool`'s `RedTimesTen`.
    fn red_times_ten(from: &u64) -> u64 {
        from * 10
    }
}
