//! The other process of `tests/all/shm.rs`, on the same host as the test:
//!
//! - `consume NAME ENDPOINT KEY on|off`: node NAME, connected to ENDPOINT with shared
//!   memory on or off, reads frames on KEY through an inlet into a queue, and prints
//!   `frame <number> <ok|bad> <received in shared memory>` for each (`ok`: every byte
//!   is what the test wrote);
//! - `hold ENDPOINT KEY`: a raw Zenoh subscriber on KEY that keeps every sample it gets
//!   (a consumer that holds packets), and prints `held <count> <in shared memory>`;
//! - `read-in-place NAME ENDPOINT KEY [on|off]`: node NAME, connected to ENDPOINT
//!   with shared memory on (the default) or off, reads images
//!   on KEY through an inlet into a queue, and prints `image <number> <ok|bad>
//!   <lent|copied> <received in shared memory>` for each (`lent`: its pixels, a
//!   `coolbot::Bytes`, were decoded in place);
//! - `produce NAME KEY`: node NAME, alone, sends large frames through an outlet on KEY
//!   until one was written into shared memory, then prints `ready`;
//! - `send-loaned NAME ENDPOINT KEYS COUNT`: node NAME, listening on ENDPOINT, once a
//!   subscriber matches each of KEYS (separated by commas) sends COUNT images through
//!   an outlet on each key (a fifo connection each, fed by one output), the
//!   even-numbered ones large, each one's pixels a buffer of `coolbot::Bytes::loan`,
//!   filled as `read-in-place` checks; prints `loaned <yes|no>` for each, then `sent
//!   <loaned> <in place> <shared> <copied>` (the node's counts);
//! - `lenders`: opens and drops nodes with shared memory on and off, and prints which
//!   one `coolbot::Bytes::loan` takes its buffers from at each step.
//!
//! It prints `ready` once it listens (consume, hold), and runs until it is killed; its
//! warnings go to stderr.

use std::io::Write;

use coolbot::crossbeam_channel;
use coolbot::port::FifoIn;
use coolbot::{Component, InputKind, OutputKind, OverflowPolicy, Packet, System};
use coolbot_zenoh::Node;
use coolbot_zenoh_tests::generated::picture_source;
use coolbot_zenoh_tests::generated::types::{Chunk, Picture};
use coolbot_zenoh_tests::generated::{picture_queue, shm_queue, shm_source};
use coolbot_zenoh_tests::support::{Hand, outlet_fed, outlets_fed, wait_subscribed};
use zenoh::Wait;

fn config(connect: &[String], shared_memory: bool) -> zenoh::Config {
    let mut config = coolbot_zenoh::peer_config(&[], connect, false).expect("a configuration");
    config
        .insert_json5(
            "transport/shared_memory/enabled",
            if shared_memory { "true" } else { "false" },
        )
        .expect("the shared-memory setting");
    config
}

/// Whether every byte of `frame` is the one the test wrote.
fn intact(frame: &Chunk) -> bool {
    frame
        .bytes
        .iter()
        .enumerate()
        .all(|(i, byte)| *byte == (frame.number as usize + i) as u8)
}

fn say(line: &str) {
    let mut out = std::io::stdout().lock();
    let _ = writeln!(out, "{line}");
    let _ = out.flush();
}

/// Node `name`, connected to `endpoint`, running an inlet of `P` on `key` into the
/// queue `queue` makes (its behaviour hands over its input): the queue's input, the
/// node and the system (both kept by the caller as long as it reads).
fn inlet_into_queue<P>(
    name: &str,
    endpoint: String,
    key: &str,
    shared_memory: bool,
    queue: impl FnOnce(Hand<FifoIn<P>>) -> Component,
) -> (FifoIn<P>, Node, System)
where
    P: Packet + serde::Serialize + serde::de::DeserializeOwned,
{
    let node = Node::open(name, config(&[endpoint], shared_memory)).expect("the node opens");
    let mut system = System::new();
    system
        .add(
            node.inlet::<P>("inlet", key, OutputKind::Data)
                .build()
                .expect("the inlet"),
        )
        .expect("added");
    let (hand, handed) = crossbeam_channel::bounded(1);
    system.add(queue(Hand(hand))).expect("added");
    system
        .connect("inlet.output", "queue.input")
        .expect("connected");
    system.run_all().expect("runs");
    let input = handed.recv().expect("the queue's input");
    say("ready");
    (input, node, system)
}

/// Each packet `input` gets, to `report`; polls, as a peer does (the test waits on
/// the lines it prints, not on this).
fn each<P: Packet>(input: &FifoIn<P>, mut report: impl FnMut(P)) -> ! {
    loop {
        match input.recv() {
            Some(packet) => report(packet),
            None => std::thread::sleep(std::time::Duration::from_millis(1)),
        }
    }
}

fn consume(name: &str, endpoint: String, key: &str, shared_memory: bool) -> ! {
    let (input, node, _system) =
        inlet_into_queue::<Chunk>(name, endpoint, key, shared_memory, |hand| {
            shm_queue::component("queue", hand)
        });
    each(&input, |frame| {
        let verdict = if intact(&frame) { "ok" } else { "bad" };
        say(&format!(
            "frame {} {verdict} {}",
            frame.number,
            node.shared_memory().received
        ));
    })
}

fn read_in_place(name: &str, endpoint: String, key: &str, shared_memory: bool) -> ! {
    let (input, node, _system) =
        inlet_into_queue::<Picture>(name, endpoint, key, shared_memory, |hand| {
            picture_queue::component("queue", hand)
        });
    each(&input, |image| {
        let ok = image
            .pixels
            .iter()
            .enumerate()
            .all(|(i, byte)| *byte == (image.number as usize + i) as u8);
        say(&format!(
            "image {} {} {} {}",
            image.number,
            if ok { "ok" } else { "bad" },
            if image.pixels.is_lent() {
                "lent"
            } else {
                "copied"
            },
            node.shared_memory().received
        ));
    })
}

fn hold(endpoint: String, key: &str) -> ! {
    let session = zenoh::open(config(&[endpoint], true))
        .wait()
        .expect("the session opens");
    let subscriber = session
        .declare_subscriber(key)
        .wait()
        .expect("the subscriber");
    say("ready");
    let mut held = Vec::new();
    let mut shared = 0;
    while let Ok(sample) = subscriber.recv() {
        if sample.payload().as_shm().is_some() {
            shared += 1;
        }
        held.push(sample);
        say(&format!("held {} {shared}", held.len()));
    }
    panic!("the session closed");
}

fn produce(name: &str, key: &str) -> ! {
    let node = Node::open(name, config(&[], true)).expect("the node opens");
    let kind = InputKind::Fifo {
        capacity: 4,
        policy: OverflowPolicy::Block,
    };
    let (hand, handed) = crossbeam_channel::bounded(1);
    let producer = shm_source::component("producer", Hand(hand));
    let (_system, out) = outlet_fed(&node, key, kind, producer, &handed);
    let mut number = 0;
    while node.shared_memory().shared == 0 {
        number += 1;
        out.send(Chunk {
            number,
            bytes: vec![0; 64 << 10],
        });
        std::thread::sleep(std::time::Duration::from_millis(1));
    }
    say("ready");
    loop {
        std::thread::park();
    }
}

fn send_loaned(name: &str, endpoint: String, key: &str, count: u64) -> ! {
    let mut config = coolbot_zenoh::peer_config(&[endpoint], &[], false).expect("a configuration");
    config
        .insert_json5("transport/shared_memory/enabled", "true")
        .expect("the shared-memory setting");
    let node = Node::open(name, config).expect("the node opens");
    let kind = InputKind::Fifo {
        capacity: 64,
        policy: OverflowPolicy::Block,
    };
    let (hand, handed) = crossbeam_channel::bounded(1);
    // An outlet (a fifo connection) for each key, all fed by the one output.
    let keys: Vec<&str> = key.split(',').collect();
    let source = picture_source::component("source", Hand(hand));
    let (_system, out) = outlets_fed(&node, &keys, kind, source, &handed);
    say("ready");
    for key in &keys {
        wait_subscribed(&node, key);
    }
    // Loans come from the heap until the pool is made (the first loan asks for it);
    // the counts printed are those of the images.
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(30);
    while !coolbot::Bytes::loan(256 << 10).is_loaned() && std::time::Instant::now() < deadline {
        std::thread::sleep(std::time::Duration::from_millis(1));
    }
    let before = node.shared_memory();
    for number in 1..=count {
        let size = if number % 2 == 0 { 256 << 10 } else { 16 };
        let mut pixels = coolbot::Bytes::loan(size);
        for (i, byte) in pixels.iter_mut().enumerate() {
            *byte = (number as usize + i) as u8;
        }
        say(&format!(
            "loaned {}",
            if pixels.is_loaned() { "yes" } else { "no" }
        ));
        out.send(Picture {
            number,
            pixels: pixels.freeze(),
        });
    }
    // Every image is through the outlet once the node counted each large one.
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(30);
    let large = count / 2 * keys.len() as u64;
    let through = || {
        let counts = node.shared_memory();
        counts.shared + counts.copied - before.shared - before.copied
    };
    // Each outlet counts a message `shared`, then `in_place`: both are waited for.
    let in_place = || node.shared_memory().in_place - before.in_place;
    while (through() < large || in_place() < large) && std::time::Instant::now() < deadline {
        std::thread::sleep(std::time::Duration::from_millis(1));
    }
    let counts = node.shared_memory();
    say(&format!(
        "sent {} {} {} {}",
        counts.loaned - before.loaned,
        counts.in_place - before.in_place,
        counts.shared - before.shared,
        counts.copied - before.copied
    ));
    loop {
        std::thread::park();
    }
}

/// Whether a loan of 256 KiB comes from `node`'s pool (it counts it), waiting at most
/// 30 s for the pool to be made.
fn lends(node: &Node) -> bool {
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(30);
    loop {
        let before = node.shared_memory().loaned;
        let loan = coolbot::Bytes::loan(256 << 10);
        if loan.is_loaned() && node.shared_memory().loaned == before + 1 {
            return true;
        }
        if std::time::Instant::now() >= deadline {
            return false;
        }
        std::thread::sleep(std::time::Duration::from_millis(1));
    }
}

/// Which node lends as nodes open and close in one process.
fn lenders() -> ! {
    let pid = std::process::id();
    let a = Node::open(&format!("lenders-a-{pid}"), config(&[], true)).expect("a opens");
    say(&format!("a lends {}", lends(&a)));
    // Shared memory off: not a lender; `a` still lends.
    let b = Node::open(&format!("lenders-b-{pid}"), config(&[], false)).expect("b opens");
    say(&format!("a lends with b open {}", lends(&a)));
    let c = Node::open(&format!("lenders-c-{pid}"), config(&[], true)).expect("c opens");
    say(&format!("c lends {}", lends(&c)));
    drop(c);
    say(&format!("a lends once c is dropped {}", lends(&a)));
    drop(a);
    say(&format!(
        "a loan once a is dropped is loaned {}",
        coolbot::Bytes::loan(256 << 10).is_loaned()
    ));
    drop(b);
    loop {
        std::thread::park();
    }
}

fn main() {
    // Its warnings (Zenoh's, and a bridge's lost packets) on stderr, which the test's
    // run inherits.
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn")),
        )
        .with_writer(std::io::stderr)
        .with_ansi(false)
        .init();
    let args: Vec<String> = std::env::args().skip(1).collect();
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    match args.as_slice() {
        ["consume", name, endpoint, key, shm] => {
            consume(name, (*endpoint).to_owned(), key, *shm == "on")
        }
        ["read-in-place", name, endpoint, key] => {
            read_in_place(name, (*endpoint).to_owned(), key, true)
        }
        ["read-in-place", name, endpoint, key, shm] => {
            read_in_place(name, (*endpoint).to_owned(), key, *shm == "on")
        }
        ["hold", endpoint, key] => hold((*endpoint).to_owned(), key),
        ["produce", name, key] => produce(name, key),
        ["lenders"] => lenders(),
        ["send-loaned", name, endpoint, key, count] => send_loaned(
            name,
            (*endpoint).to_owned(),
            key,
            count.parse().expect("a count"),
        ),
        _ => {
            eprintln!(
                "usage: shm-peer-under-test consume NAME ENDPOINT KEY on|off | read-in-place NAME ENDPOINT KEY [on|off] | hold ENDPOINT KEY | produce NAME KEY | send-loaned NAME ENDPOINT KEYS COUNT | lenders"
            );
            std::process::exit(2);
        }
    }
}
