//! What an outlet and an inlet of one host say to each other: the question, the
//! answer, and the addresses they carry.

use std::sync::OnceLock;

use coolbot::BellAddress;
use serde::{Deserialize, Serialize};

/// The keys an outlet asks its inlets for a ring on.
pub(super) fn ask_key(key: &str) -> String {
    format!("{key}/@ring/**")
}

/// This host's identity: its boot id (two processes with the same one share the
/// host's memory, if each may read the other's `/proc`).
pub(super) fn host() -> Option<&'static str> {
    static HOST: OnceLock<Option<String>> = OnceLock::new();
    HOST.get_or_init(|| {
        std::fs::read_to_string("/proc/sys/kernel/random/boot_id")
            .ok()
            .map(|id| id.trim().to_owned())
    })
    .as_deref()
}

/// A doorbell's address on the wire.
pub(super) type BellAt = (u32, i32, u64, u32);
/// A ring's address on the wire.
pub(super) type RingAt = (u32, i32, u64, u64);

pub(super) fn bell_at(a: BellAddress) -> BellAt {
    (a.pid, a.fd, a.nonce, a.pair)
}

pub(super) fn bell_address((pid, fd, nonce, pair): BellAt) -> BellAddress {
    BellAddress {
        pid,
        fd,
        nonce,
        pair,
    }
}

/// An outlet's question.
#[derive(Serialize, Deserialize)]
pub(super) struct Ask {
    pub(super) host: String,
    pub(super) epoch: u64,
    /// The number the outlet had sent on the key when it asked.
    pub(super) sent: u64,
    /// The outlet's own doorbell (rung when it waits for room).
    pub(super) bell: BellAt,
    /// The outlet (`node/name`): a second question of the same outlet replaces its
    /// ring.
    pub(super) outlet: String,
}

/// An inlet's answer.
#[derive(Serialize, Deserialize)]
pub(super) enum Answer {
    Ring {
        ring: RingAt,
        bell: BellAt,
    },
    /// Not on this host, or it cannot take a ring now (the reason).
    No(String),
}
