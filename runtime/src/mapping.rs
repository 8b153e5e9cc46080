//! Shared memory another process on this host maps: a sealed memfd made by one
//! process ([`Mapping::create`]) and opened by another through
//! `/proc/<pid>/fd/<fd>` ([`Mapping::open`]). The memory is seen only as atomic
//! words: two processes read and write it at once, and neither trusts what the other
//! wrote beyond its being words. Linux only; elsewhere both constructors fail.

use std::sync::atomic::{AtomicU32, AtomicU64};

/// One shared mapping, unmapped when dropped (its memory outlives it while another
/// process maps it).
pub(crate) struct Mapping {
    base: std::ptr::NonNull<AtomicU64>,
    bytes: usize,
    /// The memfd, kept open by its maker: other processes open it by its number.
    #[cfg(target_os = "linux")]
    fd: Option<std::os::fd::OwnedFd>,
}

// The mapping is atomics only, shared by design.
#[allow(unsafe_code, reason = "the mapping is atomics, shared by design")]
unsafe impl Send for Mapping {}
#[allow(unsafe_code, reason = "the mapping is atomics, shared by design")]
unsafe impl Sync for Mapping {}

#[cfg(not(target_os = "linux"))]
fn unsupported() -> std::io::Error {
    std::io::Error::new(
        std::io::ErrorKind::Unsupported,
        "memory shared with another process is made on Linux only",
    )
}

impl Mapping {
    /// A new memfd named `name` of `bytes` bytes (a multiple of 8), zeroed, sealed at
    /// its size (no process can shrink it under another's mapping), and mapped.
    pub(crate) fn create(name: &str, bytes: usize) -> std::io::Result<Mapping> {
        #[cfg(target_os = "linux")]
        {
            use rustix::fs::{MemfdFlags, SealFlags, fcntl_add_seals, ftruncate, memfd_create};
            let fd = memfd_create(name, MemfdFlags::CLOEXEC | MemfdFlags::ALLOW_SEALING)?;
            ftruncate(&fd, bytes as u64)?;
            fcntl_add_seals(&fd, SealFlags::SHRINK | SealFlags::GROW | SealFlags::SEAL)?;
            let mut mapping = Mapping::map(&fd, bytes)?;
            mapping.fd = Some(fd);
            Ok(mapping)
        }
        #[cfg(not(target_os = "linux"))]
        {
            let _ = (name, bytes);
            Err(unsupported())
        }
    }

    /// Map the memfd `fd` of process `pid`, which must be `bytes` long and sealed
    /// against shrinking: an error if the process is gone, does not let this one map
    /// its memory (another user), or the descriptor is something else.
    pub(crate) fn open(pid: u32, fd: i32, bytes: usize) -> std::io::Result<Mapping> {
        #[cfg(target_os = "linux")]
        {
            use std::os::unix::fs::OpenOptionsExt;
            let path = format!("/proc/{pid}/fd/{fd}");
            // What the descriptor is, before it is opened (opening a device can do
            // something): only a regular file (a memfd is one) is.
            if !std::fs::metadata(&path)?.is_file() {
                return Err(std::io::Error::new(
                    std::io::ErrorKind::InvalidData,
                    format!("{path} is not shared memory"),
                ));
            }
            // Never blocks nor takes a terminal, whatever the descriptor turns out to
            // be (a number from another process).
            let file = std::fs::OpenOptions::new()
                .read(true)
                .write(true)
                .custom_flags(
                    (rustix::fs::OFlags::NONBLOCK | rustix::fs::OFlags::NOCTTY).bits() as i32,
                )
                .open(&path)?;
            // Sealed against shrinking before its size is read: the size then holds
            // for as long as it is mapped.
            let sealed = rustix::fs::fcntl_get_seals(&file)
                .is_ok_and(|seals| seals.contains(rustix::fs::SealFlags::SHRINK));
            let metadata = file.metadata()?;
            let size = metadata.len();
            if !sealed || !metadata.is_file() || size != bytes as u64 {
                return Err(std::io::Error::new(
                    std::io::ErrorKind::InvalidData,
                    format!("{path} is not the shared memory it was said to be ({size} bytes)"),
                ));
            }
            Mapping::map(&file, bytes)
        }
        #[cfg(not(target_os = "linux"))]
        {
            let _ = (pid, fd, bytes);
            Err(unsupported())
        }
    }

    #[cfg(target_os = "linux")]
    fn map(fd: impl std::os::fd::AsFd, bytes: usize) -> std::io::Result<Mapping> {
        use rustix::mm::{MapFlags, ProtFlags, mmap};
        // A fresh shared mapping of `bytes`, unmapped by `Drop` only.
        #[allow(unsafe_code, reason = "a fresh shared mapping, unmapped by Drop")]
        let base = unsafe {
            mmap(
                std::ptr::null_mut(),
                bytes,
                ProtFlags::READ | ProtFlags::WRITE,
                MapFlags::SHARED,
                fd,
                0,
            )?
        };
        Ok(Mapping {
            base: std::ptr::NonNull::new(base.cast::<AtomicU64>())
                .ok_or_else(|| std::io::Error::other("mmap gave a null mapping"))?,
            bytes,
            fd: None,
        })
    }

    /// Its descriptor in this process, if this process made it.
    pub(crate) fn fd(&self) -> Option<i32> {
        #[cfg(target_os = "linux")]
        {
            use std::os::fd::AsRawFd;
            self.fd.as_ref().map(AsRawFd::as_raw_fd)
        }
        #[cfg(not(target_os = "linux"))]
        None
    }

    /// The memory as 64-bit words.
    pub(crate) fn u64s(&self) -> &[AtomicU64] {
        // Mapped with `bytes` (page-aligned) until `Drop`; atomics have no invalid
        // bit patterns.
        #[allow(unsafe_code, reason = "the mapping made in `map`")]
        unsafe {
            std::slice::from_raw_parts(self.base.as_ptr(), self.bytes / 8)
        }
    }

    /// The memory as 32-bit words.
    pub(crate) fn u32s(&self) -> &[AtomicU32] {
        // As `u64s`: the same memory, at the same lifetime.
        #[allow(unsafe_code, reason = "the mapping made in `map`")]
        unsafe {
            std::slice::from_raw_parts(self.base.as_ptr().cast::<AtomicU32>(), self.bytes / 4)
        }
    }
}

impl Drop for Mapping {
    fn drop(&mut self) {
        #[cfg(target_os = "linux")]
        // Mapped in `map` with `bytes`; nothing refers to it past `self`.
        #[allow(unsafe_code, reason = "the mapping made in `map`")]
        unsafe {
            let _ = rustix::mm::munmap(self.base.as_ptr().cast(), self.bytes);
        }
    }
}

/// A number a mapping's header carries so that an opener can tell it from another
/// mapping at the same place (a descriptor reused after the maker's process ended
/// and another took its pid): drawn from the standard library's random hasher keys,
/// the process and the time.
pub(crate) fn nonce() -> u64 {
    use std::hash::BuildHasher;
    std::collections::hash_map::RandomState::new()
        .hash_one((std::process::id(), std::time::SystemTime::now()))
}
