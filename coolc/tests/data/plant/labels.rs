//! Filled-in `Labels`: the labeler and the reader, nothing to supervise.

use crate::generated::labels::*;

/// Nothing to supervise.
#[derive(Debug, Default)]
pub struct LabelsSupervisor {}

impl Supervisor for LabelsSupervisor {}

/// The labeler and the reader run this crate's behaviours.
#[derive(Debug, Default)]
pub struct LabelsParts {}

impl Parts for LabelsParts {
    fn supervisor(&mut self) -> impl Supervisor {
        LabelsSupervisor::default()
    }

    fn labeler(&mut self) -> impl crate::generated::labeler::Behavior {
        crate::labeler::Labeler::default()
    }

    fn reader(&mut self) -> impl crate::generated::reader::Behavior {
        crate::reader::Reader::default()
    }
}
