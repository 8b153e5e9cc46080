//! An outlet's count of what it sent, kept in a file so that a process started again
//! after a kill can tell the inlets where its killed outlet stopped
//! (`docs/distribution.md`, "What happens when the network fails").
//!
//! The file is `<state dir>/<node>/<hash of the key>.tally`: the outlet's epoch and
//! the number of its newest message, written before each message goes to Zenoh (a
//! write to the page cache, which outlives the process). One outlet of a node holds it
//! at a time (an exclusive `flock`, which the kernel releases when the process dies);
//! a clean stop removes it. The state directory is `COOLBOT_STATE_DIR`, else
//! `coolbot` in the system's temporary directory.

use std::fs::{File, OpenOptions};
use std::io::Read;
use std::os::unix::fs::FileExt;
use std::path::PathBuf;

use rustix::fs::{FlockOperation, flock};

/// The directory of node `node`'s tallies.
fn directory(node: &str) -> PathBuf {
    std::env::var_os("COOLBOT_STATE_DIR")
        .map_or_else(|| std::env::temp_dir().join("coolbot"), PathBuf::from)
        .join(node)
}

/// FNV-1a, 64 bits: a file name for a key (stable across Rust releases, unlike the
/// standard hasher).
fn fnv(text: &str) -> u64 {
    text.bytes().fold(0xcbf2_9ce4_8422_2325, |hash, byte| {
        (hash ^ u64::from(byte)).wrapping_mul(0x0100_0000_01b3)
    })
}

/// An outlet's tally, held while it lives.
pub(crate) struct Tally {
    file: File,
    path: PathBuf,
}

/// What a previous outlet of the same node on the same key left: its epoch and the
/// number of the newest message it handed to Zenoh.
pub(crate) type Ended = (u64, u64);

impl Tally {
    /// Claim the tally of `node`'s outlet of `epoch` on `key`, with what a previous
    /// run left in it. None (with a warning) when it cannot be used: another outlet of
    /// this node holds it, or the directory cannot be written.
    pub(crate) fn claim(node: &str, key: &str, epoch: u64) -> Option<(Tally, Option<Ended>)> {
        let directory = directory(node);
        let path = directory.join(format!("{:016x}.tally", fnv(key)));
        let opened = std::fs::create_dir_all(&directory).and_then(|()| {
            OpenOptions::new()
                .read(true)
                .write(true)
                .create(true)
                .truncate(false)
                .open(&path)
        });
        let mut file = match opened {
            Ok(file) => file,
            Err(error) => {
                tracing::warn!(%key, "no tally of what the outlet sends ({}): {error}", path.display());
                return None;
            }
        };
        if flock(&file, FlockOperation::NonBlockingLockExclusive).is_err() {
            tracing::debug!(%key, "another outlet of this node on the key holds the tally");
            return None;
        }
        let mut bytes = Vec::new();
        let ended = match file.read_to_end(&mut bytes) {
            Ok(_) if bytes.len() >= 16 => {
                let word =
                    |at: usize| u64::from_le_bytes(bytes[at..at + 8].try_into().expect("8 bytes"));
                let (old, sent) = (word(0), word(8));
                (old != 0 && old != epoch && sent > 0).then_some((old, sent))
            }
            _ => None,
        };
        let mut fresh = [0u8; 16];
        fresh[..8].copy_from_slice(&epoch.to_le_bytes());
        if let Err(error) = file.write_all_at(&fresh, 0) {
            tracing::warn!(%key, "no tally of what the outlet sends: {error}");
            return None;
        }
        Some((Tally { file, path }, ended))
    }

    /// Message `number` is about to go to Zenoh (or, after a refusal, the newest is
    /// `number` again).
    pub(crate) fn record(&self, number: u64) {
        // A failure here loses only the report a restarted process would make.
        let _ = self.file.write_all_at(&number.to_le_bytes(), 8);
    }
}

impl Drop for Tally {
    /// A clean stop: nothing to report to a successor.
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.path);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    impl Tally {
        /// What a kill leaves: the file closed (the lock released), not removed.
        fn crash(mut self) -> PathBuf {
            std::mem::take(&mut self.path)
        }
    }

    #[test]
    fn a_tally_left_by_a_killed_run_is_read_once_and_one_outlet_holds_it() {
        let node = format!("tally-test-{}", std::process::id());
        let key = "test/tally";
        let (first, ended) = Tally::claim(&node, key, 11).expect("claimed");
        assert_eq!(ended, None);
        first.record(41);
        first.record(42);
        assert!(
            Tally::claim(&node, key, 12).is_none(),
            "held by the first outlet"
        );
        let path = first.crash();
        let (second, ended) = Tally::claim(&node, key, 12).expect("claimed again");
        assert_eq!(ended, Some((11, 42)));
        drop(second);
        assert!(!path.exists(), "a clean stop removes the tally");
        let (_, ended) = Tally::claim(&node, key, 13).expect("claimed");
        assert_eq!(ended, None);
    }
}
