//! Ports on loopback for nodes that others on this host are told of:
//! [`free_loopback_port`].

use std::fs::{File, Permissions};
use std::net::{Ipv4Addr, TcpListener, UdpSocket};
use std::os::unix::fs::PermissionsExt;
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Mutex, PoisonError};

use rustix::fs::{FlockOperation, flock};

/// The ports [`free_loopback_port`] draws from: below Linux's default ephemeral range
/// (32768-60999), which the kernel hands to outgoing connections and to sockets bound
/// to port 0.
const DRAWN: std::ops::Range<u64> = 20_000..32_000;

/// The lock files of the ports this process drew, held until it ends.
static HELD: Mutex<Vec<File>> = Mutex::new(Vec::new());

/// A port on 127.0.0.1 that no TCP or UDP socket holds now, for a node to listen on
/// (`tcp/127.0.0.1:PORT`, `quic/127.0.0.1:PORT`) that others on this host are told
/// of: a test's, or the example's robot for its drivers process.
///
/// A port the kernel gave a socket bound to port 0 and then released is taken from
/// the ephemeral range, and any outgoing connection (another node's, in a test
/// running beside this one) may be given it before the node listens: the node then
/// fails with "Address already in use". The ports here are drawn below that range,
/// checked free, and reserved for this process until it ends by a lock on a file of
/// the port's (in the temporary directory, `coolbot-loopback-ports/`): no other
/// process drawing ports this way gets the same one, even before the node listens.
/// Each is drawn at most once per process.
pub fn free_loopback_port() -> u16 {
    static NEXT: AtomicU64 = AtomicU64::new(0);
    let span = DRAWN.end - DRAWN.start;
    let start = u64::from(std::process::id()).wrapping_mul(7919) % span;
    let directory = std::env::temp_dir().join("coolbot-loopback-ports");
    if std::fs::create_dir_all(&directory).is_ok() {
        // Shared by every user of this host, as the ports are (sticky: each removes
        // only their own files; the files themselves are never removed).
        let _ = std::fs::set_permissions(&directory, Permissions::from_mode(0o1777));
    }
    for _ in 0..span {
        let drawn = NEXT.fetch_add(1, Ordering::Relaxed);
        let port = DRAWN.start + (start + drawn) % span;
        let port = u16::try_from(port).expect("the drawn range is below 65536");
        if !reserve(directory.join(port.to_string())) {
            continue;
        }
        let address = (Ipv4Addr::LOCALHOST, port);
        if TcpListener::bind(address).is_ok() && UdpSocket::bind(address).is_ok() {
            return port;
        }
    }
    // Every port of the range held: one of the ephemeral range, as a last resort.
    TcpListener::bind((Ipv4Addr::LOCALHOST, 0))
        .and_then(|listener| listener.local_addr())
        .map(|address| address.port())
        .expect("a free loopback port")
}

/// Whether this process now holds the lock on `file` (created if need be, readable
/// and writable by every user), kept until it ends; false only if another process
/// holds it. A file that cannot be opened (a read-only temporary directory) or locked
/// (a file system without `flock`) reserves nothing and does not stop the draw.
fn reserve(file: PathBuf) -> bool {
    let created = File::options()
        .create(true)
        .truncate(false)
        .write(true)
        .open(&file);
    let opened = match created {
        Ok(opened) => {
            let _ = opened.set_permissions(Permissions::from_mode(0o666));
            opened
        }
        // Another user's file: a read-only descriptor takes the lock as well.
        Err(_) => match File::open(&file) {
            Ok(opened) => opened,
            Err(_) => return true,
        },
    };
    match flock(&opened, FlockOperation::NonBlockingLockExclusive) {
        Ok(()) => {}
        Err(rustix::io::Errno::WOULDBLOCK) => return false,
        Err(_) => return true,
    }
    HELD.lock()
        .unwrap_or_else(PoisonError::into_inner)
        .push(opened);
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ports_are_drawn_below_the_ephemeral_range_and_never_twice() {
        let ports: Vec<u16> = (0..50).map(|_| free_loopback_port()).collect();
        let mut distinct = ports.clone();
        distinct.sort_unstable();
        distinct.dedup();
        assert_eq!(distinct.len(), ports.len(), "{ports:?}");
        assert!(
            ports.iter().all(|port| DRAWN.contains(&u64::from(*port))),
            "{ports:?}"
        );
    }

    #[test]
    fn a_port_another_holder_reserved_is_not_drawn() {
        let directory = std::env::temp_dir().join("coolbot-loopback-ports");
        let port = free_loopback_port();
        // As another process's lock would: a second open file description of the
        // same file cannot take the lock this process holds.
        assert!(!reserve(directory.join(port.to_string())));
    }
}
