//! Same host: a bridge between two processes passes its large messages through shared
//! memory (`docs/distribution.md`, "Same host: shared memory"). The other process is
//! `shm-peer-under-test`; the test waits on the lines it prints, with a deadline.

use std::collections::BTreeSet;
use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};

use coolbot::crossbeam_channel::{self, Receiver};
use coolbot::port::DataOut;
use coolbot::{InputKind, OverflowPolicy, System};
use coolbot_zenoh::{Node, SHARED_THRESHOLD};
use coolbot_zenoh_tests::generated::types::{Chunk, Picture};
use coolbot_zenoh_tests::generated::{picture_source, shm_source};
use coolbot_zenoh_tests::support::{self, Hand, PATIENCE};
use zenoh::Wait;

/// A frame large enough for shared memory.
const LARGE: usize = 256 << 10;

/// The other process, killed (`kill -9`) when dropped; its stdout's lines on a channel.
struct Peer {
    child: Child,
    lines: Receiver<String>,
}

impl Peer {
    /// The peer, once it said `ready`.
    fn start(args: &[&str]) -> Peer {
        let peer = Peer::start_quiet(args);
        peer.next_matching(|line| line == "ready");
        peer
    }

    /// The peer, started.
    fn start_quiet(args: &[&str]) -> Peer {
        let mut child = Command::new(env!("CARGO_BIN_EXE_shm-peer-under-test"))
            .args(args)
            .stdout(Stdio::piped())
            .spawn()
            .expect("the peer starts");
        let stdout = child.stdout.take().expect("its stdout");
        let (send, lines) = crossbeam_channel::unbounded();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                if send.send(line).is_err() {
                    break;
                }
            }
        });
        Peer { child, lines }
    }

    /// The next line `accept` takes, within the patience.
    fn next_matching(&self, mut accept: impl FnMut(&str) -> bool) -> String {
        let deadline = std::time::Instant::now() + PATIENCE;
        loop {
            let left = deadline.saturating_duration_since(std::time::Instant::now());
            match self.lines.recv_timeout(left) {
                Ok(line) if accept(&line) => return line,
                Ok(_) => {}
                Err(_) => panic!("the peer did not print the line awaited within {PATIENCE:?}"),
            }
        }
    }

    fn kill(mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Drop for Peer {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A fifo of 64 that blocks its producer when full.
const QUEUE: InputKind = InputKind::Fifo {
    capacity: 64,
    policy: OverflowPolicy::Block,
};

/// A node listening on loopback, keeping no tallies; `config` adjusts its
/// configuration. The node and its endpoint.
fn listening(name: &str, config: impl FnOnce(&mut zenoh::Config)) -> (Node, String) {
    let endpoint = format!("tcp/127.0.0.1:{}", support::free_port());
    let mut zenoh_config =
        coolbot_zenoh::peer_config(std::slice::from_ref(&endpoint), &[], false).expect("config");
    config(&mut zenoh_config);
    let node = Node::open(name, zenoh_config)
        .expect("the node opens")
        .with_state_directory(None);
    (node, endpoint)
}

/// A producer node listening on loopback, with a frame source connected to an outlet
/// on `key` standing for an input of `kind`; `config` adjusts its configuration.
fn producer_of(
    name: &str,
    key: &str,
    kind: InputKind,
    config: impl FnOnce(&mut zenoh::Config),
) -> (Node, String, System, DataOut<Chunk>) {
    let (node, endpoint) = listening(name, config);
    let (hand, handed) = crossbeam_channel::bounded(1);
    let source = shm_source::component("source", Hand(hand));
    let (system, out) = support::outlet_fed(&node, key, kind, source, &handed);
    (node, endpoint, system, out)
}

/// A producer node listening on loopback, with a frame source connected to an outlet
/// on `key` (a fifo); `config` adjusts its configuration.
fn producer(
    name: &str,
    key: &str,
    config: impl FnOnce(&mut zenoh::Config),
) -> (Node, String, System, DataOut<Chunk>) {
    producer_of(name, key, QUEUE, config)
}

/// Waits until `node` knows `count` inlets on `key` (their liveliness tokens). Asked
/// after the consumers said `ready`: the answer comes over each link after their
/// subscribers' declarations.
fn wait_inlets(node: &Node, key: &str, count: usize) {
    let inlets = || {
        node.session()
            .liveliness()
            .get(format!("{key}/@in/**"))
            .wait()
            .map_or(0, |replies| {
                replies
                    .iter()
                    .filter(|reply| reply.result().is_ok())
                    .count()
            })
    };
    assert!(
        support::wait_until(PATIENCE, || inlets() == count),
        "{count} inlets on `{key}`: {}",
        inlets()
    );
}

fn frame(number: u64, size: usize) -> Chunk {
    Chunk {
        number,
        bytes: (0..size).map(|i| (number as usize + i) as u8).collect(),
    }
}

/// A consumer's line `frame <number> <ok|bad> <received in shared memory>`.
fn parse_frame(line: &str) -> Option<(u64, bool, u64)> {
    let mut fields = line.strip_prefix("frame ")?.split(' ');
    let number = fields.next()?.parse().ok()?;
    let ok = fields.next()? == "ok";
    let shared = fields.next()?.parse().ok()?;
    Some((number, ok, shared))
}

/// Send `count` large frames (and as many small ones between them) to a consumer
/// process; what it received, in order, and how many arrived in shared memory.
fn stream_to(consumer_memory: &str, key: &str, name: &str) -> (Node, Vec<u64>, u64) {
    let (node, endpoint, system, out) = producer(&format!("{name}-producer"), key, |_| {});
    let consumer = Peer::start(&[
        "consume",
        &format!("{name}-consumer"),
        &endpoint,
        key,
        consumer_memory,
    ]);
    support::wait_subscribed(&node, key);
    let count = 20u64;
    for number in 1..=2 * count {
        let size = if number % 2 == 0 { LARGE } else { 16 };
        out.send(frame(number, size));
    }
    let mut received = Vec::new();
    let mut shared = 0;
    while received.len() < 2 * count as usize {
        let line = consumer.next_matching(|line| line.starts_with("frame "));
        let (number, ok, in_shared) = parse_frame(&line).expect("a frame line");
        assert!(ok, "frame {number} arrived with other bytes than were sent");
        received.push(number);
        shared = in_shared;
    }
    assert!(system.shutdown().clean(), "unclean shutdown");
    (node, received, shared)
}

#[test]
fn large_packets_to_a_process_on_this_host_are_written_once_into_shared_memory() {
    let (node, received, shared) = stream_to("on", "test/shm/same_host", "shm-same");
    assert_eq!(
        received,
        (1..=40).collect::<Vec<_>>(),
        "every frame, in order"
    );
    // The 20 large frames went into shared memory, and crossed as such; the 20 small
    // ones (under the threshold) did not.
    const { assert!(16 < SHARED_THRESHOLD && LARGE > SHARED_THRESHOLD) };
    let counts = node.shared_memory();
    assert_eq!((counts.shared, counts.copied), (20, 0), "{counts:?}");
    assert_eq!(shared, 20, "received in shared memory");
}

/// The next 20 `image` lines of a `read-in-place` consumer, checked: image `n`
/// intact, its pixels read as `large` when `n` is even and copied when odd. The
/// consumer's count of messages received in shared memory after the last.
fn read_images(consumer: &Peer, large: &str) -> String {
    let mut received = String::new();
    for number in 1..=20u64 {
        let line = consumer.next_matching(|line| line.starts_with("image "));
        let expected = if number % 2 == 0 { large } else { "copied" };
        let (image, count) = line.rsplit_once(' ').expect("a count");
        assert_eq!(image, format!("image {number} ok {expected}"));
        received = count.to_owned();
    }
    received
}

#[test]
fn bytes_from_a_process_on_this_host_are_read_in_place() {
    // An image's pixels are a `coolbot::Bytes`: the consumer's inlet decodes the large
    // ones where they arrived, in the producer's buffer of shared memory (no copy),
    // and copies the small ones, which cross the link.
    let key = "test/shm/in_place";
    let (node, endpoint) = listening("shm-in-place-producer", |_| {});
    let (hand, handed) = crossbeam_channel::bounded(1);
    let source = picture_source::component("source", Hand(hand));
    let (system, out) = support::outlet_fed(&node, key, QUEUE, source, &handed);
    let consumer = Peer::start(&["read-in-place", "shm-in-place-consumer", &endpoint, key]);
    support::wait_subscribed(&node, key);
    for number in 1..=20u64 {
        let size = if number % 2 == 0 { LARGE } else { 16 };
        out.send(Picture {
            number,
            pixels: (0..size)
                .map(|i| (number as usize + i) as u8)
                .collect::<Vec<_>>()
                .into(),
        });
    }
    assert_eq!(
        read_images(&consumer, "lent"),
        "10",
        "received in shared memory"
    );
    assert_eq!(
        node.shared_memory().shared,
        10,
        "{:?}",
        node.shared_memory()
    );
    assert!(system.shutdown().clean(), "unclean shutdown");
}

/// A producer process sends 20 images whose pixels it fills in buffers of
/// `Bytes::loan` (the even-numbered ones large) to a consumer process with shared
/// memory `consumer_memory`; checks what the producer loaned and each image the
/// consumer read, `large` being how the consumer read the large ones and `received`
/// how many it counted received in shared memory.
fn loaned_to(consumer_memory: &str, key: &str, name: &str, large: &str, received: &str) {
    let endpoint = format!("tcp/127.0.0.1:{}", support::free_port());
    let producer = Peer::start(&[
        "send-loaned",
        &format!("{name}-producer"),
        &endpoint,
        key,
        "20",
    ]);
    let consumer = Peer::start(&[
        "read-in-place",
        &format!("{name}-consumer"),
        &endpoint,
        key,
        consumer_memory,
    ]);
    for number in 1..=20u64 {
        let line = producer.next_matching(|line| line.starts_with("loaned "));
        let loaned = if number % 2 == 0 { "yes" } else { "no" };
        assert_eq!(line, format!("loaned {loaned}"), "image {number}");
    }
    assert_eq!(
        read_images(&consumer, large),
        received,
        "received in shared memory"
    );
    // Ten buffers lent by the pool, each sent in place (a message in shared memory),
    // none copied.
    let line = producer.next_matching(|line| line.starts_with("sent "));
    assert_eq!(line, "sent 10 10 10 0", "loaned, in place, shared, copied");
}

#[test]
fn bytes_loaned_from_the_pool_reach_a_process_on_this_host_without_a_copy() {
    // The large pixels come from the producer node's pool, and its outlet sends that
    // buffer as it is (no copy); the consumer reads them where they are. The small
    // ones come from the heap and cross the link, copied.
    loaned_to("on", "test/shm/loaned", "shm-loan", "lent", "10");
}

#[test]
fn bytes_loaned_from_the_pool_reach_a_consumer_without_shared_memory_over_the_link() {
    // A consumer that does not map shared memory (another host, or shared memory
    // off): Zenoh sends the loaned buffer's bytes over the link, and the consumer
    // reads every image intact, in memory of its own.
    loaned_to("off", "test/shm/loaned_off", "shm-loan-off", "copied", "0");
}

#[test]
fn a_loaned_packet_on_three_fifo_connections_to_three_processes_is_copied_by_none() {
    // Where an outlet of each connection writes its own copy of a packet of `[u8]`
    // (`one_output_to_three_fifo_connections_...`, below), a loaned buffer is sent as
    // it is by all three.
    let endpoint = format!("tcp/127.0.0.1:{}", support::free_port());
    let keys: Vec<String> = (1..=3)
        .map(|i| format!("test/shm/loaned_fifo_{i}"))
        .collect();
    let producer = Peer::start(&[
        "send-loaned",
        "shm-loan-fifos-producer",
        &endpoint,
        &keys.join(","),
        "20",
    ]);
    let consumers: Vec<Peer> = keys
        .iter()
        .enumerate()
        .map(|(i, key)| {
            Peer::start(&[
                "read-in-place",
                &format!("shm-loan-fifos-{i}"),
                &endpoint,
                key,
            ])
        })
        .collect();
    for consumer in &consumers {
        assert_eq!(
            read_images(consumer, "lent"),
            "10",
            "received in shared memory"
        );
    }
    // Ten buffers lent, each sent in place by the three outlets: thirty messages in
    // shared memory, no copy.
    let line = producer.next_matching(|line| line.starts_with("sent "));
    assert_eq!(line, "sent 10 30 30 0", "loaned, in place, shared, copied");
}

#[test]
fn the_latest_node_with_shared_memory_open_lends() {
    // In a process of its own (the lender is the process's).
    let peer = Peer::start_quiet(&["lenders"]);
    for expected in [
        "a lends true",
        "a lends with b open true",
        "c lends true",
        "a lends once c is dropped true",
        "a loan once a is dropped is loaned false",
    ] {
        assert_eq!(peer.next_matching(|_| true), expected);
    }
}

/// Sends `count` large frames on `out`, one at a time: each once every consumer has
/// printed the one before (so that a `last` outlet publishes every one). Checks that
/// each consumer got every frame, intact and in order; how many each received in
/// shared memory.
fn fan_out(out: &DataOut<Chunk>, consumers: &[Peer], count: u64) -> Vec<u64> {
    let mut shared = vec![0; consumers.len()];
    for number in 1..=count {
        out.send(frame(number, LARGE));
        for (consumer, shared) in consumers.iter().zip(&mut shared) {
            let line = consumer.next_matching(|line| line.starts_with("frame "));
            let (got, ok, in_shared) = parse_frame(&line).expect("a frame line");
            assert_eq!((got, ok), (number, true), "frame {number}, intact");
            *shared = in_shared;
        }
    }
    shared
}

#[test]
fn a_packet_to_three_consumer_processes_is_written_into_shared_memory_once() {
    // One `last` connection to three processes: one outlet, one key, three inlets.
    let key = "test/shm/fan_out";
    let (node, endpoint, system, out) =
        producer_of("shm-fan-producer", key, InputKind::Last, |_| {});
    let consumers: Vec<Peer> = (1..=3)
        .map(|i| Peer::start(&["consume", &format!("shm-fan-{i}"), &endpoint, key, "on"]))
        .collect();
    wait_inlets(&node, key, 3);
    let count = 20;
    let received = fan_out(&out, &consumers, count);
    // Each frame was written into shared memory once, and each consumer mapped that
    // one buffer: no copy of the payload per consumer.
    let counts = node.shared_memory();
    assert_eq!((counts.shared, counts.copied), (count, 0), "{counts:?}");
    assert_eq!(received, [count; 3], "received in shared memory by each");
    assert!(system.shutdown().clean(), "unclean shutdown");
}

#[test]
fn one_output_to_three_fifo_connections_in_three_processes_writes_a_copy_for_each() {
    // A fifo connection is N outputs to 1 input: three consumer processes are three
    // keys, three outlets on one output, and each outlet writes its own copy.
    let (node, endpoint) = listening("shm-fifos-producer", |_| {});
    let (hand, handed) = crossbeam_channel::bounded(1);
    let keys = ["test/shm/fifo_1", "test/shm/fifo_2", "test/shm/fifo_3"];
    let source = shm_source::component("source", Hand(hand));
    let (system, out) = support::outlets_fed(&node, &keys, QUEUE, source, &handed);
    let consumers: Vec<Peer> = keys
        .iter()
        .enumerate()
        .map(|(i, key)| Peer::start(&["consume", &format!("shm-fifos-{i}"), &endpoint, key, "on"]))
        .collect();
    for key in keys {
        wait_inlets(&node, key, 1);
        support::wait_subscribed(&node, key);
    }
    let count = 10;
    let received = fan_out(&out, &consumers, count);
    // Every outlet of the node writes into the node's one pool: none goes on the heap.
    let counts = node.shared_memory();
    assert_eq!((counts.shared, counts.copied), (3 * count, 0), "{counts:?}");
    assert_eq!(received, [count; 3], "received in shared memory by each");
    assert!(system.shutdown().clean(), "unclean shutdown");
}

#[test]
fn a_consumer_that_cannot_map_shared_memory_gets_every_packet_over_the_link() {
    // A consumer with shared memory off stands for one on another host: the link
    // carries the bytes of what the outlet wrote into shared memory.
    let (node, received, shared) = stream_to("off", "test/shm/link", "shm-link");
    assert_eq!(
        received,
        (1..=40).collect::<Vec<_>>(),
        "every frame, in order"
    );
    assert_eq!(shared, 0, "nothing arrived in shared memory");
    assert_eq!(node.shared_memory().shared, 20);
}

#[test]
fn a_consumer_that_holds_packets_does_not_block_the_producer() {
    let key = "test/shm/held";
    // A pool of 1 MiB: four of these frames fill it.
    let (node, endpoint, system, out) = producer("shm-held-producer", key, |config| {
        config
            .insert_json5(
                "transport/shared_memory/transport_optimization/pool_size",
                "1048576",
            )
            .expect("the pool's size");
    });
    let holder = Peer::start(&["hold", &endpoint, key]);
    support::wait_subscribed(&node, key);
    let count = 24u64;
    for number in 1..=count {
        out.send(frame(number, LARGE));
    }
    // Every frame reaches the holder, which keeps them all: those that found no room
    // in the pool went over the link, counted as copied.
    let line = holder.next_matching(|line| line.starts_with(&format!("held {count} ")));
    let in_shared: u64 = line
        .rsplit(' ')
        .next()
        .and_then(|n| n.parse().ok())
        .expect("a count");
    let counts = node.shared_memory();
    assert_eq!(counts.shared + counts.copied, count, "{counts:?}");
    assert!(counts.copied > 0, "the pool never filled: {counts:?}");
    assert!(counts.shared > 0, "{counts:?}");
    assert_eq!(in_shared, counts.shared, "{counts:?}");
    let outlet = system.handle("outlet").expect("the outlet");
    assert_eq!(outlet.snapshot().overflows, 0, "nothing was lost");
    assert!(system.shutdown().clean(), "unclean shutdown");
}

/// The shared-memory segments `pid` has open.
fn segments_of(pid: u32) -> BTreeSet<PathBuf> {
    std::fs::read_dir(format!("/proc/{pid}/fd"))
        .expect("the peer's descriptors")
        .filter_map(|entry| std::fs::read_link(entry.ok()?.path()).ok())
        .filter(|target| {
            target.starts_with("/dev/shm") && target.extension().is_some_and(|e| e == "zenoh")
        })
        .collect()
}

#[test]
fn a_segment_left_by_a_killed_process_is_reclaimed_when_a_node_opens() {
    let producer = Peer::start(&["produce", "shm-killed-producer", "test/shm/killed"]);
    let segments = segments_of(producer.child.id());
    assert!(!segments.is_empty(), "the producer maps no segment");
    // A node opening anywhere on this host (another test's, in parallel) reclaims a
    // segment that no process holds a lock on: until the reclaimer below opens, this
    // test holds one on each, as a process that maps it does.
    let held: Vec<std::fs::File> = segments
        .iter()
        .map(|segment| {
            let file = std::fs::File::open(segment).expect("the segment opens");
            file.lock_shared().expect("a shared lock on the segment");
            file
        })
        .collect();
    producer.kill();
    // Left behind: the killed process removed nothing.
    assert!(segments.iter().all(|segment| segment.exists()));
    drop(held);
    // With shared memory off, its session makes no segment of its own, so Zenoh's
    // sweep (at a process's first segment) does not run: what removes them is the
    // node's.
    let mut config = coolbot_zenoh::peer_config(&[], &[], false).expect("config");
    config
        .insert_json5("transport/shared_memory/enabled", "false")
        .expect("shared memory off");
    let _node = Node::open("shm-reclaimer", config).expect("the node opens");
    let left: Vec<_> = segments.iter().filter(|s| s.exists()).collect();
    assert!(left.is_empty(), "not reclaimed: {left:?}");
}
