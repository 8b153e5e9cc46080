//! The cost of `coolctl foxglove`. One node in this process runs 20 components, each
//! sending a packet on its output at 100 Hz, all echoed (`Node::echo`); the real
//! `coolctl` binary, a process of its own, serves them (`coolctl foxglove`) to one
//! WebSocket client in this process (tungstenite) that subscribes to every channel
//! and reads every message.
//!
//! - **CPU**: the server's CPU per second of wall time (every thread of the `coolctl`
//!   process, from `/proc/<pid>/task/*/schedstat`) against recording the same 20
//!   outputs to MCAP with `coolbot::record` at the same time (the recorder's thread,
//!   `cool:recorder`, from `/proc/self/task/<tid>/schedstat`). Goal: <= 1.5x.
//! - **Latency**: one-way latency of a ping-pong between two components (fifo
//!   connections, a round trip kicked every millisecond) whose outputs are echoed and
//!   served, the client subscribed to both, against the same ping-pong on two
//!   components nothing is attached to, in the same system, rounds alternated. Goal:
//!   p50 <= 1.05x. Reported beside it: a third pair whose outputs are echoed but
//!   served to nobody (the echo's own share).
//!
//! `cargo bench -p coolbot-zenoh --bench foxglove` (add `-- --quick` for a smoke run).

#[path = "../../benches/common/mod.rs"]
#[macro_use]
mod common;
mod setup;

use std::collections::HashMap;
use std::io::{BufRead, BufReader};
use std::net::TcpStream;
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use coolbot::port::DataOut;
use coolbot::{Component, OutputKind, PortSet, System};
use crossbeam_channel::{Sender, bounded};
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

use common::{Figure, Glue, Goal, Mode, Samples, Table};
use setup::pingpong::{KICK, Pace, pair, stamp};

/// Channels served, and their rate.
const CHANNELS: usize = 20;
const HZ: u64 = 100;
/// Round trips discarded at the start of every latency round.
const WARMUP: usize = 50;
/// Latency rounds of project and baseline, alternated.
const ROUNDS: usize = 10;

/// What each of the 20 components sends: a robot-sized packet.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct Reading {
    seq: u64,
    stamp: f64,
    values: [f64; 8],
    label: String,
}

one_state_spec! {
    static SOURCE_SPEC = "Source",
    inputs: [],
    outputs: [("out", OutputKind::Data)],
    on: [],
    periodic: None,
}

/// A source: its output handed to the test's sending thread.
fn source(name: &str) -> (Component, DataOut<Reading>) {
    let out = DataOut::<Reading>::new();
    let ports = PortSet::new().output(&out);
    let component = Component::new(
        name,
        Glue::boxed(&SOURCE_SPEC, Box::new(|_, _| Ok(()))),
        ports,
    );
    (component, out)
}

/// CPU time of a thread or a process's threads, from `schedstat` (nanoseconds on a
/// CPU, as the scheduler counts them).
fn schedstat(path: &std::path::Path) -> Duration {
    std::fs::read_to_string(path)
        .ok()
        .and_then(|text| text.split_whitespace().next()?.parse::<u64>().ok())
        .map_or(Duration::ZERO, Duration::from_nanos)
}

/// The CPU time of every thread of process `pid` so far.
fn process_cpu(pid: u32) -> Duration {
    let Ok(tasks) = std::fs::read_dir(format!("/proc/{pid}/task")) else {
        return Duration::ZERO;
    };
    tasks
        .filter_map(Result::ok)
        .map(|task| schedstat(&task.path().join("schedstat")))
        .sum()
}

/// The CPU time of this process's threads named `name` so far.
fn threads_cpu(name: &str) -> Duration {
    let Ok(tasks) = std::fs::read_dir("/proc/self/task") else {
        return Duration::ZERO;
    };
    tasks
        .filter_map(Result::ok)
        .filter(|task| {
            std::fs::read_to_string(task.path().join("comm")).is_ok_and(|comm| comm.trim() == name)
        })
        .map(|task| schedstat(&task.path().join("schedstat")))
        .sum()
}

/// `coolctl foxglove` serving every echoed output of the node at `endpoint`; killed
/// when dropped.
struct Server {
    child: Child,
    url: String,
}

impl Server {
    fn start(endpoint: &str) -> Server {
        let mut child = Command::new(env!("CARGO_BIN_EXE_coolctl"))
            .args(["--connect", endpoint, "--no-multicast", "--timeout", "2s"])
            .args(["foxglove", "--bind", "127.0.0.1:0", "--port", "*"])
            .stdout(Stdio::piped())
            .spawn()
            .expect("coolctl starts");
        let stdout = child.stdout.take().expect("piped stdout");
        let mut line = String::new();
        BufReader::new(stdout)
            .read_line(&mut line)
            .expect("coolctl prints its URL");
        let url = line
            .trim()
            .strip_prefix("serving ")
            .unwrap_or_else(|| panic!("coolctl foxglove said `{line}`"))
            .to_owned();
        Server { child, url }
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The WebSocket client: subscribes to every channel of `topics` once advertised,
/// counts the messages of each; `subscribed` gets the subscriptions' count when all
/// are sent.
struct Client {
    received: Arc<HashMap<String, AtomicU64>>,
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Client {
    fn start(url: &str, topics: Vec<String>, subscribed: Sender<usize>) -> Client {
        use tungstenite::client::IntoClientRequest;
        let mut request = url.into_client_request().expect("a WebSocket request");
        request.headers_mut().insert(
            "Sec-WebSocket-Protocol",
            "foxglove.sdk.v1".parse().expect("a header value"),
        );
        let address = url.trim_start_matches("ws://");
        let stream = TcpStream::connect(address).expect("the server accepts");
        stream.set_nodelay(true).expect("no delay");
        let (mut socket, _) = tungstenite::client(request, stream).expect("the handshake");
        socket
            .get_ref()
            .set_read_timeout(Some(Duration::from_millis(100)))
            .expect("a read timeout");
        let received: Arc<HashMap<String, AtomicU64>> = Arc::new(
            topics
                .iter()
                .map(|topic| (topic.clone(), AtomicU64::new(0)))
                .collect(),
        );
        let stop = Arc::new(AtomicBool::new(false));
        let (counts, stopped) = (Arc::clone(&received), Arc::clone(&stop));
        let thread = std::thread::spawn(move || {
            // Subscription id -> topic.
            let mut subscriptions: HashMap<u32, String> = HashMap::new();
            while !stopped.load(Ordering::Acquire) {
                let message = match socket.read() {
                    Ok(message) => message,
                    Err(tungstenite::Error::Io(error))
                        if matches!(
                            error.kind(),
                            std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                        ) =>
                    {
                        continue;
                    }
                    Err(error) => panic!("the WebSocket client: {error}"),
                };
                match message {
                    tungstenite::Message::Text(text) => {
                        let value: Value = serde_json::from_str(text.as_str()).expect("JSON");
                        if value["op"] != "advertise" {
                            continue;
                        }
                        let mut wanted = Vec::new();
                        for channel in value["channels"].as_array().expect("channels") {
                            let topic = channel["topic"].as_str().expect("a topic");
                            if counts.contains_key(topic) {
                                let id = subscriptions.len() as u32 + 1;
                                subscriptions.insert(id, topic.to_owned());
                                wanted.push(json!({ "id": id, "channelId": channel["id"] }));
                            }
                        }
                        if !wanted.is_empty() {
                            let order = json!({ "op": "subscribe", "subscriptions": wanted });
                            socket
                                .send(tungstenite::Message::text(order.to_string()))
                                .expect("subscribe");
                            if subscriptions.len() == counts.len() {
                                let _ = subscribed.send(subscriptions.len());
                            }
                        }
                    }
                    // Message data: op 1, subscription id (u32), receive time (u64),
                    // the message.
                    tungstenite::Message::Binary(data) if data.first() == Some(&1) => {
                        let id = u32::from_le_bytes(data[1..5].try_into().expect("an id"));
                        let _: Value = serde_json::from_slice(&data[13..]).expect("a message");
                        if let Some(count) = subscriptions.get(&id).and_then(|t| counts.get(t)) {
                            count.fetch_add(1, Ordering::Relaxed);
                        }
                    }
                    _ => {}
                }
            }
        });
        Client {
            received,
            stop,
            thread: Some(thread),
        }
    }

    /// The messages received on `topic` so far.
    fn count(&self, topic: &str) -> u64 {
        self.received
            .get(topic)
            .map_or(0, |count| count.load(Ordering::Relaxed))
    }
}

impl Drop for Client {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

/// Sends a [`Reading`] on every output at [`HZ`] until dropped.
struct Sender20 {
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Sender20 {
    fn start(outputs: Vec<DataOut<Reading>>) -> Sender20 {
        let stop = Arc::new(AtomicBool::new(false));
        let stopped = Arc::clone(&stop);
        let thread = std::thread::spawn(move || {
            let period = Duration::from_nanos(1_000_000_000 / HZ);
            let mut next = Instant::now();
            let mut seq = 0u64;
            while !stopped.load(Ordering::Acquire) {
                for (n, out) in outputs.iter().enumerate() {
                    out.send(Reading {
                        seq,
                        stamp: stamp() as f64 * 1e-9,
                        values: [n as f64; 8],
                        label: format!("reading {seq}"),
                    });
                }
                seq += 1;
                next += period;
                std::thread::sleep(next.saturating_duration_since(Instant::now()));
            }
        });
        Sender20 {
            stop,
            thread: Some(thread),
        }
    }
}

impl Drop for Sender20 {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

fn main() {
    let mode = Mode::from_env();
    let mut table = Table::new(
        "coolctl foxglove: 20 channels at 100 Hz to one client, against recording them to MCAP",
        mode,
    );
    // Declared first, removed last.
    let state = setup::state_directory();
    let endpoint = setup::endpoint();
    let node = setup::node("bench", setup::config(&endpoint, &[], false), state.path());

    // Samples per latency round: 5000 per side in a full run.
    let per_round = mode.scale(500, 100);
    let mut system = System::new();
    let mut outputs = Vec::new();
    let mut names = Vec::new();
    for n in 0..CHANNELS {
        let name = format!("s{n:02}");
        let (component, out) = source(&name);
        system.add(component).expect("source");
        outputs.push(out);
        names.push(name);
    }
    let [served, bare, echoed] = ["served_", "bare_", "echoed_"]
        .map(|prefix| pair::<u64>(&mut system, prefix, Pace::PerKick, per_round, WARMUP));
    system.run_all().expect("run");
    node.expose_system(&system).expect("expose");
    for name in &names {
        node.echo::<Reading>(&system, &format!("{name}.out"))
            .expect("echo");
    }
    for port in [
        "served_ping.output",
        "served_pong.output",
        "echoed_ping.output",
        "echoed_pong.output",
    ] {
        node.echo::<u64>(&system, port).expect("echo");
    }

    let dir = tempfile::tempdir().expect("a directory for the recording");
    let mut recorder = coolbot::record::Recorder::new();
    for name in &names {
        recorder
            .tap::<Reading>(&system, &format!("{name}.out"))
            .expect("tap");
    }
    let recording = recorder
        .start(dir.path().join("bench.mcap"))
        .expect("the recording starts");

    let server = Server::start(&endpoint);
    let mut topics: Vec<String> = names
        .iter()
        .map(|name| format!("/bench/{name}.out"))
        .collect();
    topics.extend([
        "/bench/served_ping.output".to_owned(),
        "/bench/served_pong.output".to_owned(),
    ]);
    let (subscribed, all_subscribed) = bounded(1);
    let client = Client::start(&server.url, topics.clone(), subscribed);
    common::expect(
        &all_subscribed,
        Duration::from_secs(60),
        "the client's subscriptions",
    );
    let sending = Sender20::start(outputs);
    // Every source channel flows to the client before anything is measured.
    let flowing = Instant::now() + Duration::from_secs(60);
    while !topics[..CHANNELS]
        .iter()
        .all(|topic| client.count(topic) > 0)
    {
        assert!(
            Instant::now() < flowing,
            "benchmark stalled: no messages on some channel"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    std::thread::sleep(Duration::from_secs(1));

    // CPU: both consumers at once, over the same windows.
    let window = match mode {
        Mode::Full => Duration::from_secs(30),
        Mode::Quick => Duration::from_secs(5),
    };
    let pid = server.child.id();
    let received_before: u64 = topics[..CHANNELS].iter().map(|t| client.count(t)).sum();
    let (server_before, recorder_before) = (process_cpu(pid), threads_cpu("cool:recorder"));
    let started = Instant::now();
    std::thread::sleep(window);
    let wall = started.elapsed();
    let (server_cpu, recorder_cpu) = (
        process_cpu(pid).saturating_sub(server_before),
        threads_cpu("cool:recorder").saturating_sub(recorder_before),
    );
    let received: u64 = topics[..CHANNELS]
        .iter()
        .map(|t| client.count(t))
        .sum::<u64>()
        - received_before;
    let per_second = |cpu: Duration| cpu.div_f64(wall.as_secs_f64());
    table.row(
        "cpu per second",
        Figure::Time(per_second(server_cpu)),
        Figure::Time(per_second(recorder_cpu)),
        Goal::AtMost(1.5),
    );
    table.note(&format!(
        "cpu: {wall:.1?} of wall; the client read {:.0} messages/s of the {} sent/s",
        received as f64 / wall.as_secs_f64(),
        CHANNELS as u64 * HZ
    ));

    // Latency: the served and the echoed pair against the bare one, rounds
    // alternated.
    let (mut project, mut baseline, mut echo_only) = (Vec::new(), Vec::new(), Vec::new());
    for _ in 0..ROUNDS {
        baseline.extend(bare.round("bare ping-pong"));
        project.extend(served.round("served ping-pong"));
        echo_only.extend(echoed.round("echoed ping-pong"));
    }
    let (project, baseline, echo_only) = (
        Samples::new(project),
        Samples::new(baseline),
        Samples::new(echo_only),
    );
    table.row(
        "ping-pong p50, served",
        Figure::Time(project.p50()),
        Figure::Time(baseline.p50()),
        Goal::AtMost(1.05),
    );
    table.row(
        "ping-pong p99, served",
        Figure::Time(project.p99()),
        Figure::Time(baseline.p99()),
        Goal::None,
    );
    table.row(
        "ping-pong p50, echoed only",
        Figure::Time(echo_only.p50()),
        Figure::Time(baseline.p50()),
        Goal::None,
    );
    table.note(&format!(
        "latency: {} samples per side, a round trip every {KICK:?}; the client read {} and {} of the served pair's packets",
        project.len(),
        client.count("/bench/served_ping.output"),
        client.count("/bench/served_pong.output"),
    ));
    drop(sending);
    drop(client);
    drop(server);
    let summary = recording.finish().expect("the recording finishes");
    let (recorded, lost): (u64, u64) = summary
        .ports
        .iter()
        .fold((0, 0), |(r, l), port| (r + port.recorded, l + port.lost));
    table.note(&format!(
        "recording: {recorded} packets recorded, {lost} lost"
    ));
    table.print();
    assert!(system.shutdown().clean(), "unclean shutdown");
}
