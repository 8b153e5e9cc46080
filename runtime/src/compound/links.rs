//! A declared connection between instances (with its converter, if any), and a
//! redundant group's data output merged into one stream.

use std::sync::Arc;

use crate::port::{ErasedInput, ErasedOutput, MergeEnd};
use crate::system::{ConnectError, System};

/// How a converted connection is made, with the converter's packet types and function
/// captured: `System::connect_via` (no old connection), or in place of the connection
/// `Some((from, to))` in one step (`System::replace_link`).
pub(super) type Via = Arc<
    dyn Fn(&mut System, Option<(&str, &str)>, &str, &str) -> Result<(), ConnectError> + Send + Sync,
>;

/// A converter's connection made between two erased ports directly (a redundant
/// group's merged output, which is no port of the inner system, to a consumer): in
/// place of its connection to the old input, if given, in one step with the packets
/// queued there (`port::relink_converted`).
pub(super) type LinkVia =
    Arc<dyn Fn(&ErasedOutput, Option<&ErasedInput>, &ErasedInput) -> bool + Send + Sync>;

/// A declared connection (`instance.port` ends), through a converter or not.
#[derive(Clone)]
pub(super) struct Link {
    pub(super) from: String,
    pub(super) to: String,
    pub(super) via: Option<Via>,
    pub(super) link_via: Option<LinkVia>,
}

impl Link {
    pub(super) fn ends(&self) -> (&str, &str) {
        (&self.from, &self.to)
    }
}

/// A redundant group's data output merged into one stream (`port::MergeEnd`).
pub(super) struct MergedPort {
    pub(super) group: usize,
    pub(super) port: String,
    pub(super) merge: Arc<dyn MergeEnd>,
}
