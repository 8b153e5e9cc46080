//! A hostile peer against the example's two processes (`tests/hostile.rs`, and the
//! longer run `benches/hostile.rs`): a station (`--node station --serve`) running the
//! robot's wanderer, and the robot (`--node robot`), both listening on loopback. A
//! third Zenoh session puts and asks, from a seeded generator, bad bytes on every
//! key kind a node serves (`docs/distribution.md`, "Key expressions"): the bridges'
//! data keys both ways, their acknowledgment questions, pull and value queries,
//! liveliness tokens, the remote instance's monitoring key, control ports and agents.
//! It keeps what each node must have counted, so that the caller can check it.
//!
//! What it sends, per kind:
//! - **bridges** (the wanderer's scan and pose inlets on the station, the robot's
//!   proxy output `command`): random bytes, a valid message cut short, a valid
//!   message followed by a byte, another type's message, a message over the inlet's
//!   bound (64 MiB), a message of an epoch never seen (one each, extreme numbers), a
//!   number of the live epoch that jumps out of the window, and a number 0 (a pull
//!   answer, not numbered). Each bad one is one at the inlet's `network` input (the
//!   proxy's `@network`), each jump one reset (`resets`; the proxy's `@network`).
//! - **acknowledgments**: questions on `K/@ack/**` with random or truncated reports,
//!   reports over the bound, epochs never seen, and the live epoch reported ended far
//!   beyond the window (one reset each at the inlet that has the epoch).
//! - **answers** to the outlets' acknowledgment questions from a made-up inlet:
//!   random bytes, answers cut short, extreme numbers.
//! - **queries** on `K` and `K/@pull` with random payloads, and on shape keys.
//! - **liveliness**: tokens of inlets and outlets under made-up names on the
//!   bridges' keys, and of made-up nodes; each withdrawn again.
//! - **monitoring**: events that do not decode on the instance's monitoring key
//!   (counted at the proxy's `@network`), and on the robot's own; bytes on an echoed
//!   output's key.
//! - **control**: commands that do not decode, are over `COMMAND`, are of another
//!   type, or are out of range, to every component of both nodes: each refused.
//! - **agent**: requests that do not decode, are over `REQUEST`, are of another type
//!   or over a limit, to both nodes' agents: each refused.

#![allow(dead_code)]

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use coolbot::Time;
use coolbot::{Command as ControlCommand, Controllable, Monitor, MonitorEvent, Value};
use coolbot_zenoh::agent::{Instantiate, RemoteInput, Wire};
use coolbot_zenoh::ctl::Ctl;
use coolbot_zenoh::zenoh::qos::CongestionControl;
use coolbot_zenoh::zenoh::{self, Wait};
use coolbot_zenoh::{ControlReply, DEFAULT_MAX_PAYLOAD};
use mobile_base::generated::types::{Pose2D, RangeScan, Twist};
use serde::Serialize;
use serde::de::DeserializeOwned;

/// Generous: the machine is shared and may be loaded.
pub const PATIENCE: Duration = Duration::from_secs(60);

/// The seed of the test's and the bench's runs.
pub const SEED: u64 = 0xc001_b07f;

/// The session lease both processes run with: far longer than the fuzz can stall
/// either on a loaded machine.
const LEASE: &str = "30s";

/// How long the wanderer may leave its monitoring unanswered before the robot's
/// proxy fails and places it again (`--silence`).
const SILENCE: &str = "60s";

/// The ledger's window (`runtime/zenoh/src/ledger.rs`): a jump further is a reset.
const WINDOW: u64 = 1 << 20;

/// How long a question whose answer the counts depend on waits (a reset the fuzzer
/// expects, a command that must be refused): an answer comes at once unless the
/// machine is loaded, and one that comes late must still be counted.
const ANSWER: Duration = Duration::from_secs(30);

/// A deterministic generator (splitmix64): the same seed, the same packets.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Rng {
        Rng(seed)
    }

    pub fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    pub fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }

    pub fn index(&mut self, len: usize) -> usize {
        self.below(len as u64) as usize
    }

    pub fn bytes(&mut self, len: usize) -> Vec<u8> {
        (0..len).map(|_| self.next() as u8).collect()
    }

    /// A number, often an extreme one.
    pub fn extreme(&mut self) -> u64 {
        const EXTREMES: [u64; 8] = [
            0,
            1,
            u64::MAX,
            u64::MAX - 1,
            1 << 63,
            (1 << 63) - 1,
            u32::MAX as u64,
            1 << 20,
        ];
        if self.below(2) == 0 {
            EXTREMES[self.index(EXTREMES.len())]
        } else {
            self.next()
        }
    }

    /// A float, often one a component must refuse or clamp.
    pub fn float(&mut self) -> f64 {
        const FLOATS: [f64; 7] = [
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::MAX,
            f64::MIN,
            f64::MIN_POSITIVE,
            -0.0,
        ];
        if self.below(2) == 0 {
            FLOATS[self.index(FLOATS.len())]
        } else {
            f64::from_bits(self.next())
        }
    }
}

// ---------------------------------------------------------------- the processes

fn free_port() -> u16 {
    coolbot_zenoh::free_loopback_port()
}

/// Starts the example with `args`; its stdout and stderr lines go to `lines` tagged
/// `who: `; its stdout is returned whole when it ends.
fn spawn(
    who: &'static str,
    args: &[&str],
    lines: &mpsc::Sender<String>,
) -> (Child, JoinHandle<String>) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_mobile-base"))
        .args(args)
        .env("RUST_LOG", "warn")
        .env("COOLBOT_STATE_DIR", "")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the example starts");
    let stderr = child.stderr.take().expect("piped");
    let errors = lines.clone();
    std::thread::spawn(move || {
        for line in BufReader::new(stderr).lines() {
            let Ok(line) = line else { break };
            let _ = errors.send(format!("{who} stderr: {line}"));
        }
    });
    let stdout = child.stdout.take().expect("piped");
    let lines = lines.clone();
    let reader = std::thread::spawn(move || {
        let mut all = String::new();
        for line in BufReader::new(stdout).lines() {
            let Ok(line) = line else { break };
            all.push_str(&line);
            all.push('\n');
            let _ = lines.send(format!("{who}: {line}"));
        }
        all
    });
    (child, reader)
}

/// The station and the robot, running, each listening on its own loopback port.
pub struct Processes {
    pub station: Child,
    pub robot: Child,
    robot_out: Option<JoinHandle<String>>,
    lines: mpsc::Receiver<String>,
    /// Every line read so far (printed when a wait fails).
    pub seen: Vec<String>,
    pub endpoints: [String; 2],
}

impl Processes {
    /// Starts the station, then the robot (for `duration`), with the lease and
    /// silence bounds [`LEASE`] and [`SILENCE`], and waits until the robot's status
    /// shows the wanderer running on the station.
    pub fn start(duration: &str) -> Processes {
        let station = format!("tcp/127.0.0.1:{}", free_port());
        let robot = format!("tcp/127.0.0.1:{}", free_port());
        let (sender, lines) = mpsc::channel();
        let (station_child, _) = spawn(
            "station",
            &[
                "--node",
                "station",
                "--serve",
                "--listen",
                &station,
                "--no-multicast",
                // Counting is tested here, not liveness: a loaded machine must not
                // make either side declare the other lost.
                "--lease",
                LEASE,
            ],
            &sender,
        );
        let mut processes = Processes {
            station: station_child,
            // Replaced below, once the station serves.
            robot: Command::new("true").spawn().expect("a placeholder"),
            robot_out: None,
            lines,
            seen: Vec::new(),
            endpoints: [station.clone(), robot.clone()],
        };
        let _ = processes.robot.wait();
        processes.wait_line("of the station serving", |l| {
            l.starts_with("station: node `station` on the network")
        });
        let (robot_child, robot_out) = spawn(
            "robot",
            &[
                "--node",
                "robot",
                "--listen",
                &robot,
                "--connect",
                &station,
                "--no-multicast",
                "--lease",
                LEASE,
                // Nor the wanderer placed again after a slow answer: its counts would
                // start over under a new name.
                "--silence",
                SILENCE,
                "--duration",
                duration,
                "--output",
                "lines",
            ],
            &sender,
        );
        processes.robot = robot_child;
        processes.robot_out = Some(robot_out);
        processes.wait_line("with the remote wanderer running", |l| {
            l.starts_with("robot: [") && l.contains(" wanderer=running/")
        });
        processes
    }

    /// Waits for a line for which `wanted` holds.
    pub fn wait_line(&mut self, what: &str, wanted: impl Fn(&str) -> bool) -> String {
        let deadline = Instant::now() + PATIENCE;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.lines.recv_timeout(left) {
                Ok(line) if wanted(&line) => return line,
                Ok(line) => self.seen.push(line),
                Err(error) => panic!(
                    "no line {what} within {PATIENCE:?} ({error}); seen:\n{}",
                    self.seen.join("\n")
                ),
            }
        }
    }

    /// Keeps the lines read so far (the last 2,000).
    pub fn drain(&mut self) {
        self.seen.extend(self.lines.try_iter());
        let excess = self.seen.len().saturating_sub(2_000);
        self.seen.drain(..excess);
    }

    /// Whether both processes still run.
    pub fn alive(&mut self) -> bool {
        matches!(self.station.try_wait(), Ok(None)) && matches!(self.robot.try_wait(), Ok(None))
    }

    /// SIGTERM to the robot: its exit status and its stdout, within [`PATIENCE`].
    pub fn stop_robot(&mut self) -> (std::process::ExitStatus, String) {
        use rustix::process::{Pid, Signal, kill_process};
        kill_process(Pid::from_child(&self.robot), Signal::TERM).expect("SIGTERM");
        let status = wait_exit(&mut self.robot, "the robot");
        let out = self
            .robot_out
            .take()
            .expect("the robot's output")
            .join()
            .expect("stdout read");
        (status, out)
    }

    /// SIGTERM to the station, and its exit status.
    pub fn stop_station(&mut self) -> std::process::ExitStatus {
        use rustix::process::{Pid, Signal, kill_process};
        kill_process(Pid::from_child(&self.station), Signal::TERM).expect("SIGTERM");
        wait_exit(&mut self.station, "the station")
    }
}

impl Drop for Processes {
    fn drop(&mut self) {
        let _ = self.robot.kill();
        let _ = self.station.kill();
        let _ = self.robot.wait();
        let _ = self.station.wait();
    }
}

fn wait_exit(child: &mut Child, who: &str) -> std::process::ExitStatus {
    let deadline = Instant::now() + PATIENCE;
    loop {
        if let Some(status) = child.try_wait().expect("waitable") {
            return status;
        }
        assert!(
            Instant::now() < deadline,
            "{who} did not exit within {PATIENCE:?} of SIGTERM"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// A process's resident memory, from `/proc/PID/status` (`VmRSS`), in KiB.
pub fn rss_kib(child: &Child) -> u64 {
    let status = std::fs::read_to_string(format!("/proc/{}/status", child.id()))
        .expect("the process's status");
    status
        .lines()
        .find_map(|line| line.strip_prefix("VmRSS:"))
        .and_then(|rest| rest.trim().trim_end_matches("kB").trim().parse().ok())
        .expect("VmRSS")
}

/// A process's CPU time so far (user and system), from `/proc/PID/stat`.
pub fn cpu(child: &Child) -> Duration {
    let stat =
        std::fs::read_to_string(format!("/proc/{}/stat", child.id())).expect("the process's stat");
    // After the command's `(name)`: the fields from the third on; utime and stime are
    // the 14th and 15th, in clock ticks (USER_HZ, 100 on Linux).
    let rest = &stat[stat.rfind(')').expect("(comm)") + 2..];
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let ticks: u64 = fields[11].parse::<u64>().unwrap() + fields[12].parse::<u64>().unwrap();
    Duration::from_millis(ticks * 10)
}

// ---------------------------------------------------------------- the keys

/// The placement the robot made on the station: its keys and names.
#[derive(Debug, Clone)]
pub struct Placement {
    /// `5-robot-robot-wanderer-<epoch>`: the root of the bridge keys and names.
    pub root: String,
    /// The instance's name on the station (`<root>-1`).
    pub instance: String,
}

impl Placement {
    pub fn link(&self, path: &str) -> String {
        format!("coolbot-link/station/{}/{path}", self.root)
    }
}

/// A data key of the placement: its key, what it carries, and where what reaches
/// it is counted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Bridge {
    /// The robot's scans to the wanderer (station inlet `<instance>-scan`).
    Scan,
    /// The robot's pose to the wanderer (station inlet `<instance>-pose`).
    Pose,
    /// The wanderer's commands to the robot (the proxy's output: `@network`).
    Command,
}

pub const BRIDGES: [Bridge; 3] = [Bridge::Scan, Bridge::Pose, Bridge::Command];

impl Bridge {
    pub fn key(self, placement: &Placement) -> String {
        placement.link(match self {
            Bridge::Scan => "in/scan",
            Bridge::Pose => "in/pose",
            Bridge::Command => "out/command",
        })
    }

    pub fn name(self) -> &'static str {
        match self {
            Bridge::Scan => "scan",
            Bridge::Pose => "pose",
            Bridge::Command => "command",
        }
    }

    /// A valid packet of the key's type, from `rng`.
    fn packet(self, rng: &mut Rng) -> Vec<u8> {
        match self {
            Bridge::Scan => encode(&scan(rng)),
            Bridge::Pose => encode(&pose(rng)),
            Bridge::Command => encode(&twist(rng)),
        }
    }

    /// Another type's packet.
    fn other_packet(self, rng: &mut Rng) -> Vec<u8> {
        match self {
            Bridge::Scan => encode(&pose(rng)),
            Bridge::Pose => encode(&scan(rng)),
            Bridge::Command => encode(&pose(rng)),
        }
    }

    /// Whether `bytes` decode, strictly, as a message of the key.
    fn decodes(self, bytes: &[u8]) -> bool {
        match self {
            Bridge::Scan => strict::<(u64, u64, RangeScan)>(bytes),
            Bridge::Pose => strict::<(u64, u64, Pose2D)>(bytes),
            Bridge::Command => strict::<(u64, u64, Twist)>(bytes),
        }
    }
}

fn encode(value: &impl Serialize) -> Vec<u8> {
    postcard::to_allocvec(value).expect("encodes")
}

fn strict<T: DeserializeOwned>(bytes: &[u8]) -> bool {
    matches!(postcard::take_from_bytes::<T>(bytes), Ok((_, rest)) if rest.is_empty())
}

fn stamp(rng: &mut Rng) -> Time {
    Time(rng.extreme())
}

fn scan(rng: &mut Rng) -> RangeScan {
    RangeScan {
        stamp: stamp(rng),
        ir: std::array::from_fn(|_| rng.float() as f32),
        us: std::array::from_fn(|_| rng.float() as f32),
        bumpers: std::array::from_fn(|_| rng.below(2) == 0),
    }
}

fn pose(rng: &mut Rng) -> Pose2D {
    Pose2D {
        x: rng.float(),
        y: rng.float(),
        theta: rng.float(),
    }
}

fn twist(rng: &mut Rng) -> Twist {
    Twist {
        linear: rng.float(),
        angular: rng.float(),
    }
}

// ---------------------------------------------------------------- the fuzzer

/// What the fuzzer sent, by kind, and what the nodes must have counted.
#[derive(Debug, Default, Clone)]
pub struct Figures {
    /// Packets and queries sent, by kind.
    pub sent: BTreeMap<&'static str, u64>,
    /// Bad packets put on each bridge (each one at its `network`/`@network`).
    pub bad: BTreeMap<Bridge, u64>,
    /// Resets each bridge's inlet must count: forged jumps, far reports.
    pub resets: BTreeMap<Bridge, u64>,
    /// Undecodable events on the instance's monitoring key (the proxy's `@network`).
    pub bad_events: u64,
    /// Control and agent queries answered, refused.
    pub refused: u64,
    /// Control and agent queries answered, accepted: what it was, the answer.
    pub accepted: Vec<String>,
    /// Control and agent queries no one answered: what it was.
    pub unanswered: Vec<String>,
}

impl Figures {
    fn count(&mut self, kind: &'static str) {
        *self.sent.entry(kind).or_default() += 1;
    }

    pub fn total(&self) -> u64 {
        self.sent.values().sum()
    }
}

/// The hostile peer: a Zenoh session connected to both nodes.
pub struct Fuzzer {
    pub session: zenoh::Session,
    pub ctl: Ctl,
    pub placement: Placement,
    /// The live epoch of each bridge's honest outlet.
    epochs: BTreeMap<Bridge, u64>,
    /// Epochs used for "never seen" messages, never used again.
    used: std::collections::BTreeSet<u64>,
    /// Every component path, `node/path`, of both nodes.
    components: Vec<String>,
    jumps: u64,
    rng: Rng,
    pub figures: Figures,
    /// How many oversized (64 MiB) packets to send at most.
    pub oversized_left: u32,
    /// Answers to the outlets' acknowledgment questions, under a made-up inlet
    /// (kept for the run).
    _answers: Vec<zenoh::query::Queryable<()>>,
}

impl Fuzzer {
    /// Connects to both nodes, finds the placement and the bridges' live epochs.
    pub fn connect(endpoints: &[String], seed: u64) -> Fuzzer {
        let mut config =
            coolbot_zenoh::peer_config(&[], endpoints, false).expect("a configuration");
        // A peer of another host: its messages come by the link, none through this
        // host's shared memory.
        config
            .insert_json5("transport/shared_memory/enabled", "false")
            .expect("shared memory off");
        let session = zenoh::open(config).wait().expect("a session");
        let ctl = Ctl::new(session.clone(), Duration::from_secs(5));
        let placement = wait_for("the placement's tokens", || {
            let replies = session
                .liveliness()
                .get("coolbot-link/station/*/in/scan/@in/station/*/*")
                .timeout(Duration::from_secs(2))
                .wait()
                .ok()?;
            let reply = replies.recv().ok()?;
            let sample = reply.result().ok()?.clone();
            let chunks: Vec<&str> = sample.key_expr().as_str().split('/').collect();
            let root = chunks[2].to_owned();
            let instance = chunks[7].strip_suffix("-scan")?.to_owned();
            Some(Placement { root, instance })
        });
        // The honest outlets' epochs, from their first messages.
        let (sender, received) = mpsc::channel();
        let _subscriber = session
            .declare_subscriber(placement.link("*/*"))
            .callback(move |sample| {
                let key = sample.key_expr().as_str().to_owned();
                if let Ok(((epoch, _seq), _)) =
                    postcard::take_from_bytes::<(u64, u64)>(&sample.payload().to_bytes())
                {
                    let _ = sender.send((key, epoch));
                }
            })
            .wait()
            .expect("a subscriber");
        let mut epochs = BTreeMap::new();
        let deadline = Instant::now() + PATIENCE;
        while epochs.len() < BRIDGES.len() {
            let left = deadline.saturating_duration_since(Instant::now());
            let (key, epoch) = received
                .recv_timeout(left)
                .expect("a message on each bridge");
            if let Some(bridge) = BRIDGES.iter().find(|b| b.key(&placement) == key) {
                epochs.insert(*bridge, epoch);
            }
        }
        let components = wait_for("both nodes' components", || {
            let listed = ctl.components(None).ok()?;
            let paths: Vec<String> = listed
                .iter()
                .map(|c| format!("{}/{}", c.node, c.path))
                .collect();
            (paths.iter().any(|p| p.starts_with("robot/"))
                && paths.iter().any(|p| p.starts_with("station/")))
            .then_some(paths)
        });
        // Every outlet's questions are also answered by a made-up inlet: random
        // bytes, answers cut short, and extreme numbers (what a forged
        // acknowledgment can do is documented; that it breaks nothing is shown).
        let answers = BRIDGES
            .iter()
            .enumerate()
            .map(|(n, bridge)| {
                let mut rng = Rng::new(seed ^ (n as u64 + 1));
                let key = format!("{}/@ack/fuzz/answers", bridge.key(&placement));
                let reply_key = key.clone();
                let rng = std::sync::Mutex::new(rng.next());
                session
                    .declare_queryable(key)
                    .callback(move |query| {
                        let mut state = rng.lock().unwrap_or_else(|e| e.into_inner());
                        let mut rng = Rng::new(*state);
                        *state = rng.next();
                        let epochs: Vec<(u64, u64, u64, u64, u64)> = (0..rng.index(70))
                            .map(|_| {
                                (
                                    rng.extreme(),
                                    rng.extreme(),
                                    rng.extreme(),
                                    rng.extreme(),
                                    rng.extreme(),
                                )
                            })
                            .collect();
                        let process = "p".repeat(rng.index(300));
                        let mut bytes = encode(&(process, epochs));
                        match rng.below(3) {
                            0 => {
                                let cut = rng.index(bytes.len());
                                bytes.truncate(cut);
                            }
                            1 => {
                                let len = rng.index(400);
                                bytes = rng.bytes(len);
                            }
                            _ => {}
                        }
                        let _ = query.reply(reply_key.clone(), bytes).wait();
                    })
                    .wait()
                    .expect("a queryable")
            })
            .collect();
        Fuzzer {
            _answers: answers,
            session,
            ctl,
            placement,
            epochs,
            used: std::collections::BTreeSet::new(),
            components,
            jumps: 0,
            rng: Rng::new(seed),
            figures: Figures::default(),
            oversized_left: 1,
        }
    }

    fn put(&self, key: &str, bytes: Vec<u8>) {
        self.session
            .put(key, bytes)
            .congestion_control(CongestionControl::Block)
            .wait()
            .expect("put");
    }

    /// Ask `key` with `payload`: the answers' payloads.
    fn ask(&self, key: &str, payload: Vec<u8>, timeout: Duration) -> Vec<Vec<u8>> {
        let Ok(replies) = self
            .session
            .get(key)
            .payload(payload)
            .timeout(timeout)
            .wait()
        else {
            return Vec::new();
        };
        let mut answers = Vec::new();
        while let Ok(reply) = replies.recv() {
            match reply.result() {
                Ok(sample) => answers.push(sample.payload().to_bytes().into_owned()),
                Err(error) => answers.push(error.payload().to_bytes().into_owned()),
            }
        }
        answers
    }

    /// One action of a kind drawn at random; `n` numbers the action.
    pub fn step(&mut self) {
        match self.rng.below(16) {
            0..=6 => self.bridge(),
            7 | 8 => self.acknowledgment(),
            9 => self.query(),
            10 => self.liveliness(),
            11 | 12 => self.monitoring(),
            13 | 14 => self.control(),
            _ => self.agent(),
        }
    }

    /// An epoch no node has seen: neither a live one nor one the fuzzer used.
    fn fresh_epoch(&mut self) -> u64 {
        loop {
            let candidate = self.rng.extreme();
            if !self.used.contains(&candidate) && !self.epochs.values().any(|e| *e == candidate) {
                self.used.insert(candidate);
                return candidate;
            }
        }
    }

    /// A bad or forged message on a bridge.
    fn bridge(&mut self) {
        let bridge = BRIDGES[self.rng.index(BRIDGES.len())];
        let key = bridge.key(&self.placement);
        let epoch = self.epochs[&bridge];
        let bad = |fuzzer: &mut Fuzzer, mut bytes: Vec<u8>, kind: &'static str| {
            // Bytes that happen to decode are made not to (a byte after the value).
            if bridge.decodes(&bytes) {
                bytes.push(0);
            }
            fuzzer.put(&key, bytes);
            fuzzer.figures.count(kind);
            *fuzzer.figures.bad.entry(bridge).or_default() += 1;
        };
        match self.rng.below(9) {
            0 | 1 => {
                let len = self.rng.index(300);
                let bytes = self.rng.bytes(len);
                bad(self, bytes, "bridge: random bytes");
            }
            2 => {
                let mut bytes = encode(&(epoch, self.rng.next()));
                bytes.extend(bridge.packet(&mut self.rng));
                let cut = self.rng.index(bytes.len());
                bytes.truncate(cut);
                bad(self, bytes, "bridge: truncated");
            }
            3 => {
                let mut bytes = encode(&(epoch, self.rng.next()));
                bytes.extend(bridge.packet(&mut self.rng));
                let extra = 1 + self.rng.index(8);
                bytes.extend(self.rng.bytes(extra));
                bad(self, bytes, "bridge: trailing bytes");
            }
            4 => {
                let mut bytes = encode(&(epoch, self.rng.next()));
                bytes.extend(bridge.other_packet(&mut self.rng));
                bad(self, bytes, "bridge: another type");
            }
            5 if self.oversized_left > 0 => {
                self.oversized_left -= 1;
                let mut bytes = encode(&(epoch, 1u64));
                bytes.extend(bridge.packet(&mut self.rng));
                bytes.resize(DEFAULT_MAX_PAYLOAD + 1, 0);
                bad(self, bytes, "bridge: over 64 MiB");
            }
            5 | 6 => {
                // One message of an epoch never seen, with an extreme number: counts
                // nothing (the first of an epoch).
                let fresh = self.fresh_epoch();
                let seq = self.rng.extreme();
                let mut bytes = encode(&(fresh, seq));
                bytes.extend(bridge.packet(&mut self.rng));
                self.put(&key, bytes);
                self.figures.count("bridge: an epoch never seen");
            }
            7 => {
                // The live epoch, a number out of the window (each jump far from the
                // one before): one reset.
                self.jumps += 1;
                let seq = if self.jumps.is_multiple_of(2) {
                    self.jumps << 40
                } else {
                    u64::MAX - (self.jumps << 40)
                };
                let mut bytes = encode(&(epoch, seq));
                bytes.extend(bridge.packet(&mut self.rng));
                self.put(&key, bytes);
                self.figures.count("bridge: a jump out of the window");
                *self.figures.resets.entry(bridge).or_default() += 1;
            }
            _ => {
                // Number 0: a pull answer, delivered and not numbered.
                let mut bytes = encode(&(epoch, 0u64));
                bytes.extend(bridge.packet(&mut self.rng));
                self.put(&key, bytes);
                self.figures.count("bridge: number 0");
            }
        }
    }

    /// A question to a bridge's inlets, as an outlet asks.
    fn acknowledgment(&mut self) {
        let bridge = BRIDGES[self.rng.index(BRIDGES.len())];
        let key = format!("{}/@ack/**", bridge.key(&self.placement));
        let epoch = self.epochs[&bridge];
        match self.rng.below(5) {
            0 => {
                let len = self.rng.index(400);
                let bytes = self.rng.bytes(len);
                self.ask(&key, bytes, Duration::from_secs(5));
                self.figures.count("ack: random report");
            }
            1 => {
                let ended: Vec<(u64, u64)> = (0..17)
                    .map(|_| (self.rng.next(), self.rng.next()))
                    .collect();
                let mut bytes = encode(&ended);
                if self.rng.below(2) == 0 {
                    let cut = self.rng.index(bytes.len());
                    bytes.truncate(cut);
                    self.figures.count("ack: truncated report");
                } else {
                    self.figures.count("ack: report over the bound");
                }
                self.ask(&key, bytes, Duration::from_secs(5));
            }
            2 => {
                let fresh = self.fresh_epoch();
                let ended = vec![(fresh, self.rng.extreme())];
                self.ask(&key, encode(&ended), Duration::from_secs(5));
                self.figures.count("ack: an epoch never seen");
            }
            _ => {
                // The live epoch said ended far beyond the window: one reset at the
                // inlet that has it (its answer shows whether it does).
                self.jumps += 1;
                let last = u64::MAX - (self.jumps << 40);
                let answers = self.ask(&key, encode(&vec![(epoch, last)]), ANSWER);
                self.figures.count("ack: the live epoch ended far ahead");
                let had = answers.iter().any(|answer| {
                    postcard::from_bytes::<(String, Vec<(u64, u64, u64, u64, u64)>)>(answer)
                        .is_ok_and(|(_, had)| {
                            had.iter().any(|h| h.0 == epoch && h.2 + WINDOW < last)
                        })
                });
                if had {
                    *self.figures.resets.entry(bridge).or_default() += 1;
                }
            }
        }
    }

    /// Queries with payloads on value, pull and shape keys.
    fn query(&mut self) {
        let bridge = BRIDGES[self.rng.index(BRIDGES.len())];
        let len = self.rng.index(200);
        let payload = self.rng.bytes(len);
        let key = match self.rng.below(3) {
            0 => bridge.key(&self.placement),
            1 => format!("{}/@pull", bridge.key(&self.placement)),
            _ => {
                let component = &self.components[self.rng.index(self.components.len())];
                format!("coolbot/{component}/s")
            }
        };
        self.ask(&key, payload, Duration::from_millis(500));
        self.figures.count("query: value, pull, shape");
    }

    /// Tokens under made-up names on the bridges' keys and as nodes, withdrawn again.
    fn liveliness(&mut self) {
        let bridge = BRIDGES[self.rng.index(BRIDGES.len())];
        let key = bridge.key(&self.placement);
        let longest = if self.rng.below(8) == 0 { 2_000 } else { 16 };
        let name_len = 1 + self.rng.index(longest);
        let name: String = (0..name_len)
            .map(|_| char::from(b'a' + self.rng.below(26) as u8))
            .collect();
        let token = match self.rng.below(4) {
            0 => format!("{key}/@in/fuzz/{name}/{:x}", self.rng.next()),
            1 => format!("{key}/@in/station/{name}/{:x}", self.rng.next()),
            2 => format!("{key}/@out/last/fuzz/{name}"),
            _ => format!("coolbot/fuzz-{name}"),
        };
        if let Ok(token) = self.session.liveliness().declare_token(token).wait() {
            let _ = token.undeclare().wait();
        }
        self.figures.count("liveliness: a token made up");
    }

    /// Events that do not decode on monitoring keys.
    fn monitoring(&mut self) {
        // A node's batch of echoed packets too (`coolctl echo` reads it; nothing in a
        // node).
        if self.rng.below(4) == 0 {
            let len = self.rng.index(200);
            let bytes = self.rng.bytes(len);
            self.put("coolbot/robot/o", bytes);
            self.figures.count("echo: bytes on a node's echo batch key");
            return;
        }
        let instance_key = format!("coolbot/station/{}/m", self.placement.instance);
        let key = if self.rng.below(2) == 0 {
            instance_key.clone()
        } else {
            let component = &self.components[self.rng.index(self.components.len())];
            format!("coolbot/{component}/m")
        };
        // The proxy hears the instance's key, whichever way it was drawn.
        let instance = key == instance_key;
        let mut bytes = match self.rng.below(4) {
            0 => {
                let len = self.rng.index(300);
                self.rng.bytes(len)
            }
            1 => {
                let event = serde_json::to_vec(&MonitorEvent::UserState(Some("x".repeat(40))))
                    .expect("encodes");
                let cut = self.rng.index(event.len());
                event[..cut].to_vec()
            }
            2 => serde_json::to_vec(&ControlCommand::SetPriority(i32::MAX)).expect("encodes"),
            _ => format!(
                "{{\"Period\":{{\"secs\":{},\"nanos\":4000000000}}}}",
                u64::MAX
            )
            .into_bytes(),
        };
        if serde_json::from_slice::<MonitorEvent>(&bytes).is_ok() {
            bytes.push(b'}');
        }
        self.put(&key, bytes);
        self.figures
            .count("monitoring: an event that does not decode");
        if instance {
            self.figures.bad_events += 1;
        }
    }

    fn answered(&mut self, what: String, answers: Vec<Vec<u8>>) {
        match answers.first() {
            None => self.figures.unanswered.push(what),
            Some(answer) => match serde_json::from_slice::<ControlReply>(answer) {
                Ok(ControlReply::Rejected { .. }) => self.figures.refused += 1,
                _ => self.figures.accepted.push(format!(
                    "{what}: {}",
                    String::from_utf8_lossy(&answer[..answer.len().min(200)])
                )),
            },
        }
    }

    /// A command every component must refuse.
    fn control(&mut self) {
        let component = self.components[self.rng.index(self.components.len())].clone();
        let key = format!("coolbot/{component}/c");
        let (bytes, kind): (Vec<u8>, &'static str) = match self.rng.below(6) {
            0 => {
                let len = self.rng.index(300);
                (self.rng.bytes(len), "control: random bytes")
            }
            1 => {
                let json = serde_json::to_vec(&ControlCommand::SetState(Controllable::Dead))
                    .expect("encodes");
                let cut = self.rng.index(json.len());
                (json[..cut].to_vec(), "control: truncated")
            }
            2 => {
                let long = "x".repeat(coolbot_zenoh::limits::COMMAND.max + 1);
                let json =
                    serde_json::to_vec(&ControlCommand::Set("seek".into(), Value::Str(long)))
                        .expect("encodes");
                (json, "control: over COMMAND")
            }
            3 => {
                let json = serde_json::to_vec(&MonitorEvent::State {
                    from: coolbot::State::Running,
                    to: coolbot::State::Dead,
                })
                .unwrap_or_else(|_| b"{\"State\":1}".to_vec());
                (json, "control: another type")
            }
            _ => {
                let command = match self.rng.below(7) {
                    0 => ControlCommand::SetPeriod(Duration::ZERO),
                    1 => ControlCommand::SetPeriod(Duration::MAX),
                    2 => ControlCommand::SetMaxResponse(Duration::ZERO),
                    3 => ControlCommand::SetPriority(if self.rng.below(2) == 0 {
                        i32::MAX
                    } else {
                        i32::MIN
                    }),
                    4 => ControlCommand::SetQuality(usize::MAX),
                    5 => ControlCommand::Set("max_speed".into(), Value::Float(f64::MAX)),
                    _ => ControlCommand::Set(
                        "x".repeat(1 + self.rng.index(100_000)),
                        Value::UInt(u64::MAX),
                    ),
                };
                (
                    serde_json::to_vec(&command).expect("encodes"),
                    "control: out of range",
                )
            }
        };
        let answers = self.ask(&key, bytes, ANSWER);
        self.figures.count(kind);
        self.answered(format!("{kind} to {component}"), answers);
    }

    /// A request every agent must refuse.
    fn agent(&mut self) {
        let node = if self.rng.below(2) == 0 {
            "robot"
        } else {
            "station"
        };
        // (On plaintext, the requester's chunk of the key is the asker's word.)
        let key = coolbot_zenoh::keys::agent(node, "Wanderer", "fuzz");
        let request = |fuzzer: &mut Fuzzer| Instantiate {
            type_name: "Wanderer".into(),
            name: format!(
                "{}{:x}",
                coolbot_zenoh::keys::namespace("fuzz"),
                fuzzer.rng.next()
            ),
            wires: vec![Wire::Output {
                port: "command".into(),
                key: format!("fuzz/{:x}", fuzzer.rng.next()),
                to: RemoteInput::Fifo { capacity: 4 },
            }],
            configuration: None,
            variables: Vec::new(),
            timing: None,
            run: false,
            owner: None,
        };
        let (bytes, kind): (Vec<u8>, &'static str) = match self.rng.below(6) {
            0 => {
                let len = self.rng.index(300);
                (self.rng.bytes(len), "agent: random bytes")
            }
            1 => {
                let json = serde_json::to_vec(&request(self)).expect("encodes");
                let cut = self.rng.index(json.len());
                (json[..cut].to_vec(), "agent: truncated")
            }
            2 => {
                let mut wanted = request(self);
                wanted.configuration =
                    Some(Value::Str("x".repeat(coolbot_zenoh::limits::REQUEST.max)));
                (
                    serde_json::to_vec(&wanted).expect("encodes"),
                    "agent: over REQUEST",
                )
            }
            3 => (
                serde_json::to_vec(&ControlCommand::SetPeriod(Duration::ZERO)).expect("encodes"),
                "agent: another type",
            ),
            _ => {
                let mut wanted = request(self);
                match self.rng.below(5) {
                    0 => {
                        wanted.wires = vec![Wire::Output {
                            port: "command".into(),
                            key: format!("fuzz/{:x}", self.rng.next()),
                            to: RemoteInput::Fifo {
                                capacity: usize::MAX >> self.rng.below(4),
                            },
                        }]
                    }
                    1 => {
                        wanted.wires = vec![Wire::Output {
                            port: "command".into(),
                            key: format!("fuzz/{:x}", self.rng.next()),
                            to: RemoteInput::Ufifo {
                                initial: 1 << 61,
                                max: Some(usize::MAX),
                            },
                        }]
                    }
                    2 => {
                        wanted.name = "n"
                            .repeat(1 + coolbot_zenoh::limits::NAME.max + self.rng.index(100_000))
                    }
                    3 => {
                        wanted.wires = (0..=coolbot_zenoh::limits::WIRES.max)
                            .map(|i| Wire::Input {
                                port: "scan".into(),
                                key: format!("fuzz/{i}"),
                            })
                            .collect()
                    }
                    _ => wanted.type_name = format!("Nope{:x}", self.rng.next()),
                }
                (
                    serde_json::to_vec(&wanted).expect("encodes"),
                    "agent: over a limit",
                )
            }
        };
        let answers = self.ask(&key, bytes, ANSWER);
        self.figures.count(kind);
        self.answered(format!("{kind} to {node}"), answers);
    }

    /// What the nodes count now: for each bridge, (bad, resets) at its inlet; the
    /// proxy's `@network` counts both for `command`, plus its undecodable events.
    pub fn counts(&self) -> Option<Counts> {
        let inlet = |port: &str| -> Option<(u64, u64)> {
            let monitor = self
                .ctl
                .snapshot(&format!("station/{}-{port}", self.placement.instance))
                .ok()?;
            Some((at(&monitor, "network"), at(&monitor, "resets")))
        };
        let proxy = self.ctl.snapshot("robot/robot.wanderer").ok()?;
        Some(Counts {
            scan: inlet("scan")?,
            pose: inlet("pose")?,
            network: at(&proxy, "@network"),
        })
    }

    /// The deadlines the robot's components missed so far, summed.
    pub fn missed_deadlines(&self) -> u64 {
        self.missed_by_component().iter().map(|(_, n)| n).sum()
    }

    /// The deadlines each of the robot's components missed so far.
    pub fn missed_by_component(&self) -> Vec<(String, u64)> {
        self.ctl
            .components(Some("robot"))
            .map(|listed| {
                listed
                    .into_iter()
                    .map(|c| (c.path, c.monitor.missed_deadlines))
                    .collect()
            })
            .unwrap_or_default()
    }

    /// What the counts must be, from `before`, after what was sent.
    pub fn expected(&self, before: &Counts) -> Counts {
        let figures = &self.figures;
        let of = |map: &BTreeMap<Bridge, u64>, bridge| map.get(&bridge).copied().unwrap_or(0);
        Counts {
            scan: (
                before.scan.0 + of(&figures.bad, Bridge::Scan),
                before.scan.1 + of(&figures.resets, Bridge::Scan),
            ),
            pose: (
                before.pose.0 + of(&figures.bad, Bridge::Pose),
                before.pose.1 + of(&figures.resets, Bridge::Pose),
            ),
            network: before.network
                + of(&figures.bad, Bridge::Command)
                + of(&figures.resets, Bridge::Command)
                + figures.bad_events,
        }
    }
}

/// A port's count in a snapshot (0 when the port is not listed).
pub fn at(monitor: &Monitor, port: &str) -> u64 {
    monitor
        .port_overflows
        .iter()
        .find(|(name, _)| name == port)
        .map_or(0, |(_, n)| *n)
}

/// What the nodes counted from the network: `(network, resets)` at the station's
/// scan and pose inlets, and the robot's proxy's `@network`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Counts {
    pub scan: (u64, u64),
    pub pose: (u64, u64),
    pub network: u64,
}

/// Polls `probe` until it gives something, within [`PATIENCE`].
pub fn wait_for<T>(what: &str, mut probe: impl FnMut() -> Option<T>) -> T {
    let deadline = Instant::now() + PATIENCE;
    loop {
        if let Some(found) = probe() {
            return found;
        }
        assert!(Instant::now() < deadline, "no {what} within {PATIENCE:?}");
        std::thread::sleep(Duration::from_millis(50));
    }
}
