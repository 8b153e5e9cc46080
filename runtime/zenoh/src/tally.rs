//! An outlet's count of what it sent, kept in a file so that a process started again
//! after a kill can tell the inlets where its killed outlet stopped
//! (`docs/distribution.md`, "What happens when the network fails").
//!
//! A node's outlets on a key share up to [`SLOTS`] files
//! `<state dir>/<node>/<hash of the key>.<slot>.tally`, one held by each live outlet
//! (an exclusive `flock`, which the kernel releases when the process dies). A file
//! holds its outlet's epoch and the number of its newest message, written before the
//! message goes to Zenoh (a store to a shared mapping of the file: the page cache,
//! which outlives the process), and
//! the epochs killed before it with their newest numbers, [`KEPT`] at most. An outlet
//! that claims a slot takes over what every slot nobody holds says (a killed outlet's
//! epoch, and what it had not reported yet) and reports it all with its questions;
//! a report counts once at an inlet, so a report repeated after another kill costs
//! nothing. A clean stop marks its own epoch reported.
//!
//! The state directory is `COOLBOT_STATE_DIR` (empty: no tally), else `coolbot` in
//! `XDG_RUNTIME_DIR`, else `coolbot-<uid>` in `/dev/shm` (memory, like the runtime
//! directory) or the temporary directory; it is made private (mode 0700) and must
//! belong to the user; files are opened without following links.

use std::fs::{DirBuilder, File, OpenOptions};
use std::os::unix::fs::{DirBuilderExt, FileExt, MetadataExt, OpenOptionsExt};
use std::path::{Path, PathBuf};

use rustix::fs::{FlockOperation, OFlags, flock};

/// How many outlets of one node on one key keep a tally at once.
pub(crate) const SLOTS: usize = 4;

/// How many killed epochs a tally keeps to report.
pub(crate) const KEPT: usize = 16;

/// The size of a tally: the outlet's epoch and newest number, then [`KEPT`] ended
/// epochs with theirs.
const SIZE: usize = 16 * (1 + KEPT);

/// An epoch that ended by a kill and the newest number it handed to Zenoh.
pub(crate) type Ended = (u64, u64);

/// The state directory, or None when tallies are off.
fn state_directory() -> Option<PathBuf> {
    match std::env::var_os("COOLBOT_STATE_DIR") {
        Some(directory) if directory.is_empty() => None,
        Some(directory) => Some(PathBuf::from(directory)),
        None => {
            if let Some(run) = std::env::var_os("XDG_RUNTIME_DIR").filter(|d| !d.is_empty()) {
                return Some(PathBuf::from(run).join("coolbot"));
            }
            let memory = Path::new("/dev/shm");
            let base = if memory.is_dir() {
                memory.to_path_buf()
            } else {
                std::env::temp_dir()
            };
            Some(base.join(format!("coolbot-{}", rustix::process::getuid().as_raw())))
        }
    }
}

/// `directory`, made private if it is new; an error unless it is a directory (not a
/// link) of this user.
fn private_directory(directory: &Path) -> std::io::Result<()> {
    DirBuilder::new()
        .recursive(true)
        .mode(0o700)
        .create(directory)?;
    let metadata = std::fs::symlink_metadata(directory)?;
    if !metadata.is_dir() || metadata.uid() != rustix::process::getuid().as_raw() {
        return Err(std::io::Error::other(format!(
            "{} is not a directory of this user",
            directory.display()
        )));
    }
    Ok(())
}

/// FNV-1a, 64 bits: a file name for a key (stable across Rust releases, unlike the
/// standard hasher).
fn fnv(text: &str) -> u64 {
    text.bytes().fold(0xcbf2_9ce4_8422_2325, |hash, byte| {
        (hash ^ u64::from(byte)).wrapping_mul(0x0100_0000_01b3)
    })
}

fn open(path: &Path, create: bool) -> std::io::Result<File> {
    OpenOptions::new()
        .read(true)
        .write(true)
        .create(create)
        .truncate(false)
        .mode(0o600)
        .custom_flags(OFlags::NOFOLLOW.bits() as i32)
        .open(path)
}

/// What a tally file says, oldest first: the ended epochs it kept, then its own
/// epoch and newest number unless a clean stop marked them reported (a killed
/// outlet's).
fn read(file: &File) -> Vec<Ended> {
    let mut bytes = vec![0u8; SIZE];
    let length = file.read_at(&mut bytes, 0).unwrap_or(0);
    let mut pairs: Vec<Ended> = bytes[..length]
        .chunks_exact(16)
        .map(|pair| {
            let word = |at: usize| u64::from_le_bytes(pair[at..at + 8].try_into().expect("8"));
            (word(0), word(8))
        })
        .collect();
    if !pairs.is_empty() {
        let own = pairs.remove(0);
        pairs.push(own);
    }
    pairs.retain(|&(epoch, newest)| epoch != 0 && newest > 0);
    pairs
}

/// `current` then `ended`, as a file holds them.
fn layout(current: Ended, ended: &[Ended]) -> Vec<u8> {
    let mut bytes = vec![0u8; SIZE];
    for (at, (epoch, newest)) in std::iter::once(current)
        .chain(ended.iter().copied())
        .enumerate()
    {
        bytes[16 * at..16 * at + 8].copy_from_slice(&epoch.to_le_bytes());
        bytes[16 * at + 8..16 * at + 16].copy_from_slice(&newest.to_le_bytes());
    }
    bytes
}

/// An outlet's tally, held while it lives: the locked file, mapped.
pub(crate) struct Tally {
    /// Held for its lock.
    _file: File,
    map: std::sync::Mutex<memmap2::MmapMut>,
}

/// A shared, writable mapping of a tally `file` of [`SIZE`] bytes.
#[allow(unsafe_code)]
fn map(file: &File) -> std::io::Result<memmap2::MmapMut> {
    // SAFETY: `file` is in a private directory of this user and this outlet holds its
    // exclusive `flock` for as long as the mapping lives: no other outlet maps or
    // writes it (they open a slot only after taking its lock), and the file is never
    // truncated while mapped (its length is set before). The mapping is only written
    // here, never read back.
    unsafe { memmap2::MmapMut::map_mut(file) }
}

impl Tally {
    /// Claim a tally for `node`'s outlet of `epoch` on `key`, with the killed epochs
    /// to report (from every slot nobody holds, which it takes over). None (with a
    /// warning) when tallies are off or cannot be kept: the directory cannot be
    /// used, or [`SLOTS`] outlets of this node on the key hold theirs.
    pub(crate) fn claim(node: &str, key: &str, epoch: u64) -> Option<(Tally, Vec<Ended>)> {
        let directory = state_directory()?.join(node);
        let made = state_directory()
            .as_deref()
            .map_or(Ok(()), private_directory)
            .and_then(|()| private_directory(&directory));
        if let Err(error) = made {
            tracing::warn!(%key, "no tally of what the outlet sends: {error}");
            return None;
        }
        let hash = fnv(key);
        let path = |slot: usize| directory.join(format!("{hash:016x}.{slot}.tally"));
        let mut mine = None;
        for slot in 0..SLOTS {
            match open(&path(slot), true) {
                Ok(file) if flock(&file, FlockOperation::NonBlockingLockExclusive).is_ok() => {
                    mine = Some((slot, file));
                    break;
                }
                Ok(_) => {}
                Err(error) => {
                    tracing::warn!(%key, "no tally of what the outlet sends ({}): {error}", path(slot).display());
                    return None;
                }
            }
        }
        let Some((slot, file)) = mine else {
            tracing::warn!(%key, "no tally of what the outlet sends: {SLOTS} outlets of this node on the key hold theirs");
            return None;
        };
        let mut ended = read(&file);
        // What the other slots' killed outlets left, taken over.
        for other in (0..SLOTS).filter(|&other| other != slot) {
            if let Ok(file) = open(&path(other), false)
                && flock(&file, FlockOperation::NonBlockingLockExclusive).is_ok()
            {
                let left = read(&file);
                if !left.is_empty() && file.write_all_at(&[0u8; SIZE], 0).is_ok() {
                    ended.extend(left);
                }
            }
        }
        let mut kept: Vec<Ended> = Vec::new();
        for entry in ended.into_iter().rev() {
            if kept.len() < KEPT && !kept.contains(&entry) {
                kept.push(entry);
            }
        }
        kept.reverse();
        let mapped = file
            .set_len(SIZE as u64)
            .and_then(|()| file.write_all_at(&layout((epoch, 0), &kept), 0))
            .and_then(|()| map(&file));
        match mapped {
            Ok(map) => Some((
                Tally {
                    _file: file,
                    map: std::sync::Mutex::new(map),
                },
                kept,
            )),
            Err(error) => {
                tracing::warn!(%key, "no tally of what the outlet sends: {error}");
                None
            }
        }
    }

    /// Message `number` is about to go to Zenoh (a store to the mapped page).
    pub(crate) fn record(&self, number: u64) {
        self.write(8, number);
    }

    fn write(&self, at: usize, word: u64) {
        let mut map = self
            .map
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        map[at..at + 8].copy_from_slice(&word.to_le_bytes());
    }
}

impl Drop for Tally {
    /// A clean stop: its own epoch has nothing to report (what it kept stays, for the
    /// next outlet to report again).
    fn drop(&mut self) {
        self.write(0, 0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    impl Tally {
        /// What a kill leaves: the file closed (its lock released) and unmapped, its
        /// epoch in it.
        fn crash(self) {
            // Not its clean stop: its fields swapped for harmless ones (leaked).
            let mut this = std::mem::ManuallyDrop::new(self);
            let anonymous = memmap2::MmapMut::map_anon(SIZE).expect("a mapping");
            let map = std::mem::replace(&mut this.map, std::sync::Mutex::new(anonymous));
            let null = File::open("/dev/null").expect("/dev/null");
            let file = std::mem::replace(&mut this._file, null);
            drop((map, file));
        }
    }

    #[test]
    fn a_killed_epoch_is_reported_by_the_next_outlets_and_slots_are_shared() {
        let node = format!("tally-test-{}", std::process::id());
        let key = "test/tally";
        let (first, ended) = Tally::claim(&node, key, 11).expect("claimed");
        assert_eq!(ended, []);
        first.record(42);
        // A second outlet of the node on the key takes another slot.
        let (second, ended) = Tally::claim(&node, key, 12).expect("a second slot");
        assert_eq!(ended, [], "the first holds its own");
        second.record(7);
        drop(second); // a clean stop: nothing to report of epoch 12
        first.record(43);
        first.crash();
        let (third, ended) = Tally::claim(&node, key, 13).expect("claimed");
        assert_eq!(ended, [(11, 43)]);
        // Killed before any answer: the next outlet reports epoch 11 again.
        third.crash();
        let (fourth, ended) = Tally::claim(&node, key, 14).expect("claimed");
        assert_eq!(ended, [(11, 43)]);
        fourth.record(3);
        fourth.crash();
        let (fifth, ended) = Tally::claim(&node, key, 15).expect("claimed");
        assert_eq!(ended, [(11, 43), (14, 3)]);
        drop(fifth);
        let _ = std::fs::remove_dir_all(state_directory().expect("on").join(&node));
    }
}
