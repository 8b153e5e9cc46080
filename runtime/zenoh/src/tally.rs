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
//! nothing. Once every inlet has heard it (`crate::ledger`), the outlet retires it:
//! clears it from its tally. A clean stop marks its own epoch reported. A claim removes the node's
//! files that nobody holds and that have nothing to report; the keys of a remote
//! placement (`coolbot-link/...`), new at every placement, have no tally (no process
//! started again would ever read it).
//!
//! The state directory is `COOLBOT_STATE_DIR` (empty: no tally), else `coolbot` in
//! `XDG_RUNTIME_DIR`, else `coolbot-<uid>` in `/dev/shm` (memory, like the runtime
//! directory) or the temporary directory, unless the node was given one
//! (`Node::with_state_directory`); it must belong to the user and is made private
//! (mode 0700); files are opened without following links and used only if they are
//! regular files of the user with one name.

use std::fs::{DirBuilder, File, OpenOptions, Permissions};
use std::os::unix::fs::{DirBuilderExt, FileExt, MetadataExt, OpenOptionsExt, PermissionsExt};
use std::path::{Path, PathBuf};

use coolbot::Chain;
use rustix::fs::{FlockOperation, OFlags, flock};

/// How many outlets of one node on one key keep a tally at once.
pub(crate) const SLOTS: usize = 4;

/// How many killed epochs a tally keeps to report.
pub(crate) const KEPT: usize = 16;

/// The size of a tally: the outlet's epoch and newest number, then [`KEPT`] ended
/// epochs with theirs, then [`MARK`].
const SIZE: usize = 16 * (1 + KEPT) + 8;

/// The last word of a tally: a file without it (not a tally, one of another layout,
/// one whose outlet was killed while making it, one taken over) has nothing to report.
const MARK: u64 = u64::from_le_bytes(*b"tally-1\n");

/// How many times a claim opens a slot again when a sweep removed the file it had
/// opened (between its open and its lock).
const REOPENS: usize = 4;

/// An epoch that ended by a kill and the newest number it handed to Zenoh.
pub(crate) type Ended = (u64, u64);

/// The state directory the environment names, or None when tallies are off.
pub(crate) fn state_directory() -> Option<PathBuf> {
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

/// `directory`, made if it is missing and made private (mode 0700) if others may use
/// it; an error unless it is a directory (not a link) of this user.
fn private_directory(directory: &Path) -> std::io::Result<()> {
    DirBuilder::new()
        .recursive(true)
        .mode(0o700)
        .create(directory)?;
    // Opened without following a link, then checked and changed through the open
    // descriptor: what is checked is what is changed.
    let opened = OpenOptions::new()
        .read(true)
        .custom_flags((OFlags::NOFOLLOW | OFlags::DIRECTORY).bits() as i32)
        .open(directory)?;
    let metadata = opened.metadata()?;
    if !metadata.is_dir() || metadata.uid() != rustix::process::getuid().as_raw() {
        return Err(std::io::Error::other(format!(
            "{} is not a directory of this user",
            directory.display()
        )));
    }
    if metadata.mode() & 0o077 != 0 {
        opened
            .set_permissions(Permissions::from_mode(0o700))
            .map_err(|source| {
                std::io::Error::other(NotPrivate {
                    directory: directory.to_owned(),
                    mode: metadata.mode() & 0o7777,
                    source,
                })
            })?;
    }
    Ok(())
}

/// A state directory open to others that could not be made private.
#[derive(Debug, thiserror::Error)]
#[error("{} is open to others (mode {mode:o}) and cannot be made private", .directory.display())]
struct NotPrivate {
    directory: PathBuf,
    mode: u32,
    #[source]
    source: std::io::Error,
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

/// Whether `file`, opened at `path`, is still the file there (false: it was removed,
/// or another took its name); an error unless it is a regular file of this user with
/// one name. Asked with the file's lock held, which a sweep needs to remove it.
fn still_there(file: &File, path: &Path) -> std::io::Result<bool> {
    let own = file.metadata()?;
    let named = match std::fs::symlink_metadata(path) {
        Ok(named) => named,
        Err(error) if error.kind() == std::io::ErrorKind::NotFound => return Ok(false),
        Err(error) => return Err(error),
    };
    if (named.dev(), named.ino()) != (own.dev(), own.ino()) {
        return Ok(false);
    }
    if !own.is_file() || own.uid() != rustix::process::getuid().as_raw() || own.nlink() != 1 {
        return Err(std::io::Error::other(format!(
            "{} is not a regular file of this user with one name",
            path.display()
        )));
    }
    Ok(true)
}

/// `file` locked (exclusive, without waiting) and still the usable file at `path`.
fn locked(file: &File, path: &Path) -> bool {
    flock(file, FlockOperation::NonBlockingLockExclusive).is_ok()
        && matches!(still_there(file, path), Ok(true))
}

/// What a tally file says, oldest first: the ended epochs it kept, then its own
/// epoch and newest number unless a clean stop marked them reported (a killed
/// outlet's). Nothing from a file shorter than a tally or without its [`MARK`];
/// the numbers of one damaged after it are only compared and saturated (at the
/// inlets), never trusted to be in any range.
fn read(file: &File) -> Vec<Ended> {
    let mut bytes = [0u8; SIZE];
    if file.read_exact_at(&mut bytes, 0).is_err() {
        return Vec::new();
    }
    let word = |at: usize| {
        let mut word = [0u8; 8];
        word.copy_from_slice(&bytes[at..at + 8]);
        u64::from_le_bytes(word)
    };
    if word(SIZE - 8) != MARK {
        return Vec::new();
    }
    let mut pairs: Vec<Ended> = (1..=KEPT)
        .chain([0])
        .map(|pair| (word(16 * pair), word(16 * pair + 8)))
        .collect();
    pairs.retain(|&(epoch, newest)| epoch != 0 && newest > 0);
    pairs
}

/// `current` then `ended`, as a file holds them, and the mark.
fn layout(current: Ended, ended: &[Ended]) -> Vec<u8> {
    let mut bytes = vec![0u8; SIZE];
    bytes[SIZE - 8..].copy_from_slice(&MARK.to_le_bytes());
    for (at, (epoch, newest)) in std::iter::once(current)
        .chain(ended.iter().copied())
        .take(1 + KEPT)
        .enumerate()
    {
        bytes[16 * at..16 * at + 8].copy_from_slice(&epoch.to_le_bytes());
        bytes[16 * at + 8..16 * at + 16].copy_from_slice(&newest.to_le_bytes());
    }
    bytes
}

/// Remove the tally files of a node's `directory` that have nothing to report and
/// that no outlet holds (the keys of remote placements before they had none, keys
/// no longer used). Each is locked first and removed only if it is still the file at
/// its name: an outlet that opened the same name meanwhile finds its file gone once
/// it holds the lock, and opens the name again.
fn sweep(directory: &Path) {
    let Ok(entries) = std::fs::read_dir(directory) else {
        return;
    };
    for entry in entries.flatten() {
        let path = entry.path();
        if path
            .extension()
            .is_none_or(|extension| extension != "tally")
        {
            continue;
        }
        if let Ok(file) = open(&path, false)
            && locked(&file, &path)
            && read(&file).is_empty()
        {
            let _ = std::fs::remove_file(&path);
        }
    }
}

/// An outlet's tally, held while it lives: the locked file, mapped.
pub(crate) struct Tally {
    /// Declared (so dropped) before the file: unmapped before the lock goes.
    map: std::sync::Mutex<memmap2::MmapMut>,
    /// Held for its lock.
    _file: File,
}

/// A shared, writable mapping of a tally `file` of [`SIZE`] bytes.
#[allow(unsafe_code)]
fn map(file: &File) -> std::io::Result<memmap2::MmapMut> {
    // SAFETY: `file` is a regular file with one name in a private directory of this
    // user, and this outlet holds its exclusive `flock` for as long as the mapping
    // lives (the `Tally` drops its mapping before its file): no other outlet maps,
    // writes or removes it (they do so only after taking its lock), and the file is
    // never truncated while mapped (its length is set before). The mapping is only
    // written here, never read back.
    unsafe { memmap2::MmapMut::map_mut(file) }
}

impl Tally {
    /// Claim a tally in `state` (the state directory) for `node`'s outlet of `epoch`
    /// on `key`, with the killed epochs to report (from every slot nobody holds,
    /// which it takes over). None (with a warning) when tallies cannot be kept: the
    /// directory cannot be used, or [`SLOTS`] outlets of this node on the key hold
    /// theirs.
    pub(crate) fn claim(
        state: &Path,
        node: &str,
        key: &str,
        epoch: u64,
    ) -> Option<(Tally, Vec<Ended>)> {
        let directory = state.join(node);
        let made = private_directory(state).and_then(|()| private_directory(&directory));
        if let Err(error) = made {
            tracing::warn!(%key, "no tally of what the outlet sends: {}", Chain(&error));
            return None;
        }
        sweep(&directory);
        let hash = fnv(key);
        let path = |slot: usize| directory.join(format!("{hash:016x}.{slot}.tally"));
        let mut mine = None;
        'slots: for slot in 0..SLOTS {
            for _ in 0..REOPENS {
                let file = match open(&path(slot), true) {
                    Ok(file) => file,
                    Err(error) => {
                        tracing::warn!(%key, "no tally of what the outlet sends ({}): {}", path(slot).display(), Chain(&error));
                        return None;
                    }
                };
                if flock(&file, FlockOperation::NonBlockingLockExclusive).is_err() {
                    continue 'slots; // another outlet's
                }
                match still_there(&file, &path(slot)) {
                    Ok(true) => {
                        mine = Some((slot, file));
                        break 'slots;
                    }
                    Ok(false) => {} // removed by a sweep: opened again
                    Err(error) => {
                        tracing::warn!(%key, "no tally of what the outlet sends: {}", Chain(&error));
                        return None;
                    }
                }
            }
        }
        let Some((slot, file)) = mine else {
            tracing::warn!(%key, "no tally of what the outlet sends: {SLOTS} outlets of this node on the key hold theirs");
            return None;
        };
        let mut ended = read(&file);
        // What the other slots' killed outlets left, taken over: written to this
        // slot's file before theirs are cleared, so that a kill in between repeats a
        // report (counted once at an inlet) rather than losing it.
        let mut taken = Vec::new();
        for other in (0..SLOTS).filter(|&other| other != slot) {
            if let Ok(file) = open(&path(other), false)
                && locked(&file, &path(other))
            {
                let left = read(&file);
                if !left.is_empty() {
                    ended.extend(left);
                    taken.push(file);
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
        let written = file
            .set_len(SIZE as u64)
            .and_then(|()| file.write_all_at(&layout((epoch, 0), &kept), 0));
        if let Err(error) = written {
            tracing::warn!(%key, "no tally of what the outlet sends: {}", Chain(&error));
            return None;
        }
        for other in taken {
            let _ = other.write_all_at(&[0u8; SIZE], 0);
        }
        match map(&file) {
            Ok(map) => Some((
                Tally {
                    map: std::sync::Mutex::new(map),
                    _file: file,
                },
                kept,
            )),
            Err(error) => {
                tracing::warn!(%key, "no tally of what the outlet sends: {}", Chain(&error));
                None
            }
        }
    }

    /// The killed epochs this outlet took over were reported to every inlet: clear
    /// them, so that the next outlet on the key does not report them again.
    pub(crate) fn retire(&self) {
        for pair in 1..=KEPT {
            self.write(16 * pair, 0);
            self.write(16 * pair + 8, 0);
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

    /// A state directory of the test's own (the environment is not read).
    fn state() -> tempfile::TempDir {
        tempfile::tempdir().expect("a temporary directory")
    }

    fn slot(state: &Path, node: &str, key: &str, slot: usize) -> PathBuf {
        state
            .join(node)
            .join(format!("{:016x}.{slot}.tally", fnv(key)))
    }

    #[test]
    fn a_retired_report_is_not_taken_over_again() {
        let state = tempfile::tempdir().unwrap();
        let (first, _) = Tally::claim(state.path(), "node", "k/retire", 1).unwrap();
        first.record(7);
        first.crash();
        let (second, ended) = Tally::claim(state.path(), "node", "k/retire", 2).unwrap();
        assert_eq!(ended, [(1, 7)]);
        second.retire();
        second.record(3);
        second.crash();
        let (_third, ended) = Tally::claim(state.path(), "node", "k/retire", 3).unwrap();
        assert_eq!(ended, [(2, 3)], "epoch 1 was retired, epoch 2 was killed");
    }

    #[test]
    fn a_killed_epoch_is_reported_by_the_next_outlets_and_slots_are_shared() {
        let state = state();
        let state = state.path();
        let (node, key) = ("node", "test/tally");
        let (first, ended) = Tally::claim(state, node, key, 11).expect("claimed");
        assert_eq!(ended, []);
        first.record(42);
        // A second outlet of the node on the key takes another slot.
        let (second, ended) = Tally::claim(state, node, key, 12).expect("a second slot");
        assert_eq!(ended, [], "the first holds its own");
        second.record(7);
        drop(second); // a clean stop: nothing to report of epoch 12
        first.record(43);
        first.crash();
        let (third, ended) = Tally::claim(state, node, key, 13).expect("claimed");
        assert_eq!(ended, [(11, 43)]);
        // Killed before any answer: the next outlet reports epoch 11 again.
        third.crash();
        let (fourth, ended) = Tally::claim(state, node, key, 14).expect("claimed");
        assert_eq!(ended, [(11, 43)]);
        fourth.record(3);
        fourth.crash();
        let (fifth, ended) = Tally::claim(state, node, key, 15).expect("claimed");
        assert_eq!(ended, [(11, 43), (14, 3)]);
        drop(fifth);
    }

    #[test]
    fn what_another_slot_left_moves_to_the_claimers_file() {
        let state = state();
        let state = state.path();
        let (node, key) = ("node", "test/takeover");
        let (first, _) = Tally::claim(state, node, key, 21).expect("claimed");
        let (second, _) = Tally::claim(state, node, key, 22).expect("a second slot");
        second.record(5);
        second.crash(); // slot 1 says (22, 5)
        drop(first); // slot 0: nothing to report
        let (third, ended) = Tally::claim(state, node, key, 23).expect("claimed");
        assert_eq!(ended, [(22, 5)]);
        let read_slot =
            |slot| read(&open(&self::slot(state, node, key, slot), false).expect("a slot"));
        assert_eq!(read_slot(0), [(22, 5)], "the claimer's, slot 0");
        assert_eq!(read_slot(1), [], "cleared");
        drop(third);
    }

    #[test]
    fn a_claim_removes_the_files_nobody_holds_that_have_nothing_to_report() {
        let state = state();
        let state = state.path();
        let node = "node";
        let (stopped, _) = Tally::claim(state, node, "test/stopped", 1).expect("claimed");
        drop(stopped); // a clean stop: nothing to report
        let (killed, _) = Tally::claim(state, node, "test/killed", 2).expect("claimed");
        killed.record(9);
        killed.crash(); // something to report
        let (held, _) = Tally::claim(state, node, "test/held", 3).expect("claimed");
        let short = slot(state, node, "test/short", 0);
        std::fs::write(&short, [1u8; 20]).expect("a short file");
        let (_other, _) = Tally::claim(state, node, "test/other", 4).expect("claimed");
        assert!(!slot(state, node, "test/stopped", 0).exists(), "removed");
        assert!(!short.exists(), "removed");
        assert!(
            slot(state, node, "test/killed", 0).exists(),
            "kept to report"
        );
        assert!(slot(state, node, "test/held", 0).exists(), "held");
        let (_, ended) = Tally::claim(state, node, "test/killed", 5).expect("claimed");
        assert_eq!(ended, [(2, 9)]);
        drop(held);
    }

    #[test]
    fn a_short_or_garbled_file_reports_nothing_and_a_damaged_one_never_panics() {
        let state = state();
        let state = state.path();
        let (node, key) = ("node", "test/garbage");
        private_directory(&state.join(node)).expect("the node's directory");
        std::fs::write(slot(state, node, key, 0), [0xa5u8; 40]).expect("short");
        std::fs::write(slot(state, node, key, 1), [0xffu8; SIZE]).expect("no mark");
        std::fs::write(slot(state, node, key, 2), [0x5au8; 3 * SIZE]).expect("long");
        let mut damaged = vec![0xffu8; SIZE];
        damaged[SIZE - 8..].copy_from_slice(&MARK.to_le_bytes());
        std::fs::write(slot(state, node, key, 3), &damaged).expect("marked, damaged");
        let (tally, ended) = Tally::claim(state, node, key, 31).expect("claimed");
        assert_eq!(ended, [(u64::MAX, u64::MAX)], "the marked one only, once");
        tally.record(1);
        tally.crash();
        let (_, ended) = Tally::claim(state, node, key, 32).expect("claimed");
        assert_eq!(ended, [(u64::MAX, u64::MAX), (31, 1)]);
    }

    #[test]
    fn an_existing_state_directory_is_made_private_and_odd_files_are_not_used() {
        let state = state();
        let state = state.path();
        std::fs::set_permissions(state, Permissions::from_mode(0o755)).expect("chmod");
        let (tally, _) = Tally::claim(state, "node", "test/private", 1).expect("claimed");
        drop(tally);
        let mode = std::fs::metadata(state).expect("the directory").mode();
        assert_eq!(mode & 0o777, 0o700);
        let file = slot(state, "node", "test/private", 0);
        assert_eq!(
            std::fs::metadata(&file).expect("kept").mode() & 0o777,
            0o600
        );
        // A second name for the slot's file: not used.
        let (killed, _) = Tally::claim(state, "node", "test/linked", 1).expect("claimed");
        killed.record(4);
        killed.crash();
        let linked = slot(state, "node", "test/linked", 0);
        std::fs::hard_link(&linked, state.join("elsewhere")).expect("a hard link");
        assert!(Tally::claim(state, "node", "test/linked", 2).is_none());
        // A link at the slot's name: not followed.
        let target = state.join("target");
        std::fs::write(&target, []).expect("a file");
        std::os::unix::fs::symlink(&target, slot(state, "node", "test/symlink", 0))
            .expect("a link");
        assert!(Tally::claim(state, "node", "test/symlink", 3).is_none());
        // The state directory a link: refused.
        let link = state.join("link");
        std::os::unix::fs::symlink(state.join("node"), &link).expect("a link");
        assert!(private_directory(&link).is_err());
    }
}
