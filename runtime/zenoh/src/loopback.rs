//! Ports on loopback for tests that start nodes: [`free_loopback_port`].

use std::net::{Ipv4Addr, TcpListener, UdpSocket};
use std::sync::atomic::{AtomicU32, Ordering};

/// The ports [`free_loopback_port`] draws from: below Linux's default ephemeral range
/// (32768-60999), which the kernel hands to outgoing connections and to sockets bound
/// to port 0.
const DRAWN: std::ops::Range<u32> = 20_000..32_000;

/// A port on 127.0.0.1 that no TCP or UDP socket holds now, for a node to listen on
/// (`tcp/127.0.0.1:PORT`, `quic/127.0.0.1:PORT`) that others on this host are told
/// of: a test's, or the example's robot for its drivers process.
///
/// A port the kernel gave a socket bound to port 0 and then released is taken from
/// the ephemeral range, and any outgoing connection (another node's, in a test
/// running beside this one) may be given it before the node listens: the node then
/// fails with "Address already in use". The ports here are drawn below that range,
/// each at most once per process (from a start that depends on the process id, so
/// that test processes running at once draw different ones), and checked free.
pub fn free_loopback_port() -> u16 {
    static NEXT: AtomicU32 = AtomicU32::new(0);
    let span = DRAWN.end - DRAWN.start;
    let start = std::process::id().wrapping_mul(7919) % span;
    for _ in 0..span {
        let drawn = NEXT.fetch_add(1, Ordering::Relaxed);
        let port = DRAWN.start + (start + drawn) % span;
        let port = u16::try_from(port).expect("the drawn range is below 65536");
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
            ports.iter().all(|port| DRAWN.contains(&u32::from(*port))),
            "{ports:?}"
        );
    }
}
