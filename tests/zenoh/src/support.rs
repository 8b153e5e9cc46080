//! What the network tests share: two nodes on loopback with explicit endpoints and
//! multicast scouting off, waiting for conditions, a node in a process of its own
//! (one of this package's binaries), a TCP forwarder whose link a test can cut, the
//! robot's system (generated components, `cool/robot.cool`), a node with an echoed
//! source and a tuner, and a certificate authority for security files.

use std::net::TcpListener;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use coolbot::crossbeam_channel::{self, Receiver, Sender};
use coolbot::port::{DataOut, FifoIn, LastIn, PosterIn, PosterOut, TickIn, TickOut, UfifoIn};
use coolbot::{Component, InputKind, Packet, SectionResult, System};
use coolbot_zenoh::Node;
use rcgen::{BasicConstraints, CertificateParams, DnType, IsCa, Issuer, KeyPair};
use zenoh::Wait;

use crate::generated::types::{Chunk, LaserScan, Picture, Pose, Ranges, Reading, Speed, Twist};
use crate::generated::{
    base, blocking_queue, chunk_queue, drive, goal, growing_queue, latest, lidar, motion,
    picture_queue, picture_source, plain, pose_source, poster_source, queue, ranger, reader,
    robot as robot_compound, shm_queue, shm_source, small_queue, source, tick_source, ticks,
    tiny_queue, tuner, two_source, wheels, wide_queue,
};

/// Ends this process when its standard input closes: a test's child process whose test
/// died (killed, or stopped by a timeout) without killing it does not run on.
pub fn exit_when_stdin_closes() {
    std::thread::spawn(|| {
        let _ = std::io::copy(&mut std::io::stdin(), &mut std::io::sink());
        std::process::exit(0);
    });
}

/// Generous: the machine is shared and may be loaded.
pub const PATIENCE: Duration = Duration::from_secs(30);

/// A port free on 127.0.0.1 now, outside the range outgoing connections take theirs
/// from (`coolbot_zenoh::free_loopback_port`).
pub fn free_port() -> u16 {
    coolbot_zenoh::free_loopback_port()
}

/// A node listening on a free loopback port, connecting to `connect`. Its outlets
/// keep no tally (none is written into the user's state directory; the processes
/// `tests/accounting.rs` kills keep theirs in a temporary one).
pub fn node(name: &str, connect: &[String]) -> (Node, String) {
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let config = coolbot_zenoh::peer_config(std::slice::from_ref(&endpoint), connect, false)
        .expect("config");
    let node = Node::open(name, config).expect("open node");
    (node.with_state_directory(None), endpoint)
}

/// Two nodes, the second connected to the first, each seeing the other's token.
pub fn pair(first: &str, second: &str) -> (Node, Node) {
    let (a, endpoint) = node(first, &[]);
    let (b, _) = node(second, &[endpoint]);
    let sees = |node: &Node, other: &str| {
        let key = format!("coolbot/{other}");
        wait_until(PATIENCE, || {
            let replies = node
                .session()
                .liveliness()
                .get(&key)
                .timeout(Duration::from_millis(500))
                .wait()
                .expect("liveliness query");
            replies.recv().is_ok()
        })
    };
    assert!(sees(&a, second), "{first} does not see {second}");
    assert!(sees(&b, first), "{second} does not see {first}");
    (a, b)
}

/// Poll `condition` every few milliseconds until it holds or `limit` passes.
pub fn wait_until(limit: Duration, mut condition: impl FnMut() -> bool) -> bool {
    let deadline = Instant::now() + limit;
    loop {
        if condition() {
            return true;
        }
        if Instant::now() >= deadline {
            return false;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// Wait until `node`'s session knows a subscriber on `key` (a bridge's inlet).
pub fn wait_subscribed(node: &Node, key: &str) {
    let publisher = node
        .session()
        .declare_publisher(key.to_owned())
        .wait()
        .expect("probe publisher");
    assert!(
        wait_until(PATIENCE, || publisher
            .matching_status()
            .wait()
            .is_ok_and(|status| status.matching())),
        "no subscriber on `{key}`"
    );
}

/// A node in a process of its own: one of this package's binaries, started by a test,
/// killed (`kill -9`) when dropped. It keeps no outlet tallies (a placement's bridges
/// keep none anyway).
pub struct NodeProcess {
    child: std::process::Child,
}

impl NodeProcess {
    /// Starts `program` (a `CARGO_BIN_EXE_...` path) with `args`, a process that opens
    /// the node `name` and prints `ready` once it serves. Returns when it has, and
    /// `observer` sees the node's liveliness token.
    pub fn start(program: &str, args: &[&str], name: &str, observer: &Node) -> NodeProcess {
        use std::io::BufRead;
        let mut child = std::process::Command::new(program)
            .args(args)
            .env("COOLBOT_STATE_DIR", "")
            .stdin(std::process::Stdio::piped())
            .stdout(std::process::Stdio::piped())
            .spawn()
            .unwrap_or_else(|error| panic!("`{program}` does not start: {error}"));
        let stdout = child.stdout.take().expect("piped");
        let process = NodeProcess { child };
        let (ready, started) = crossbeam_channel::bounded(1);
        std::thread::spawn(move || {
            let mut lines = std::io::BufReader::new(stdout)
                .lines()
                .map_while(Result::ok);
            let said = lines.any(|line| line == "ready");
            let _ = ready.send(said);
            // Read on, so that the process never writes into a closed pipe.
            lines.for_each(drop);
        });
        assert_eq!(
            started.recv_timeout(PATIENCE),
            Ok(true),
            "node `{name}`'s process did not start"
        );
        let token = format!("coolbot/{name}");
        assert!(
            wait_until(PATIENCE, || observer
                .session()
                .liveliness()
                .get(&token)
                .timeout(Duration::from_millis(200))
                .wait()
                .is_ok_and(|replies| replies.recv().is_ok())),
            "node `{}` does not see `{name}`",
            observer.name()
        );
        process
    }

    /// Waits (at most [`PATIENCE`]) for the process to end by itself: how it ended.
    /// Panics if it runs on.
    pub fn wait_end(mut self) -> std::process::ExitStatus {
        let mut status = None;
        let ended = wait_until(PATIENCE, || {
            status = self.child.try_wait().expect("the process's status");
            status.is_some()
        });
        assert!(ended, "the process runs on");
        status.expect("ended")
    }

    /// The process's id.
    pub fn id(&self) -> u32 {
        self.child.id()
    }

    /// `kill -9`: how it ended.
    pub fn kill(mut self) -> std::process::ExitStatus {
        self.child.kill().expect("the process is killed");
        self.child.wait().expect("the process's status")
    }
}

impl Drop for NodeProcess {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A TCP forwarder between two nodes on loopback, so that a test can break the link
/// between them while both stay alive: `cut` closes every connection through it and
/// refuses new ones until `restore`.
pub struct Forwarder {
    /// The endpoint to connect to (`tcp/127.0.0.1:<port>`): it forwards to `target`.
    pub endpoint: String,
    open: std::sync::Arc<std::sync::atomic::AtomicBool>,
    streams: std::sync::Arc<std::sync::Mutex<Vec<std::net::TcpStream>>>,
}

impl Forwarder {
    /// Forward connections on a free loopback port to `target` (`127.0.0.1:<port>`).
    pub fn start(target: std::net::SocketAddr) -> Forwarder {
        use std::sync::atomic::Ordering;
        let listener = TcpListener::bind("127.0.0.1:0").expect("a free port");
        let endpoint = format!("tcp/{}", listener.local_addr().expect("an address"));
        let open = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(true));
        let streams = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
        let (accepting, kept) = (open.clone(), streams.clone());
        std::thread::spawn(move || {
            for incoming in listener.incoming() {
                let Ok(client) = incoming else { continue };
                let Ok(server) = std::net::TcpStream::connect(target) else {
                    continue;
                };
                if !accepting.load(Ordering::Acquire) {
                    continue; // Dropped: the connection is refused.
                }
                let pipe = |from: &std::net::TcpStream, to: &std::net::TcpStream| {
                    let (mut from, mut to) = (from.try_clone().unwrap(), to.try_clone().unwrap());
                    std::thread::spawn(move || {
                        let _ = std::io::copy(&mut from, &mut to);
                        let _ = to.shutdown(std::net::Shutdown::Both);
                    });
                };
                pipe(&client, &server);
                pipe(&server, &client);
                kept.lock().unwrap().extend([client, server]);
            }
        });
        Forwarder {
            endpoint,
            open,
            streams,
        }
    }

    /// Close every connection through the forwarder, and refuse new ones.
    pub fn cut(&self) {
        self.open.store(false, std::sync::atomic::Ordering::Release);
        for stream in self.streams.lock().unwrap().drain(..) {
            let _ = stream.shutdown(std::net::Shutdown::Both);
        }
    }

    /// Accept connections again.
    pub fn restore(&self) {
        self.open.store(true, std::sync::atomic::Ordering::Release);
    }
}

/// The behaviour of every component of the robot: nothing.
pub struct Quiet;

impl motion::Behavior for Quiet {}
impl plain::Behavior for Quiet {}
impl base::Supervisor for Quiet {}
impl robot_compound::Supervisor for Quiet {}

impl base::Parts for Quiet {
    fn supervisor(&mut self) -> impl base::Supervisor {
        Quiet
    }
    fn motion(&mut self) -> impl motion::Behavior {
        Quiet
    }
    fn ranges(&mut self) -> impl plain::Behavior {
        Quiet
    }
}

impl robot_compound::Parts for Quiet {
    fn supervisor(&mut self) -> impl robot_compound::Supervisor {
        Quiet
    }
    fn base(&mut self) -> impl base::Parts {
        Quiet
    }
    fn planner(&mut self) -> impl plain::Behavior {
        Quiet
    }
}

/// The robot's system of the network tests: a compound `robot` (holding a compound
/// `base` with `motion` and `ranges`, and a `planner`) and an atomic `logger`
/// (`cool/robot.cool`), running, exposed on `node`.
pub fn robot(node: &Node) -> System {
    let mut system = System::new();
    system
        .add(robot_compound::component("robot", Quiet).expect("the robot builds"))
        .unwrap();
    system.add(plain::component("logger", Quiet)).unwrap();
    system.run_all().unwrap();
    node.expose_system(&system).unwrap();
    system
}

/// `Tuner`'s behaviour: its observables follow its configuration.
pub struct Tuning;

impl tuner::Behavior for Tuning {
    fn tuning_periodic(&mut self, cx: &mut tuner::Cx<'_>) -> SectionResult {
        cx.vars.gain = cx.config.gain;
        cx.vars.label.clone_from(&cx.config.label);
        Ok(())
    }
}

/// A behaviour that hands one of its component's ports to the test when the
/// component starts; the test then sends or reads on it from its own thread.
pub struct Hand<T>(pub Sender<T>);

/// Implements the `Behavior` of generated module `$module` for [`Hand`] of `$port`:
/// `start` hands over `cx.$side.$field`.
macro_rules! hand {
    ($module:ident, $port:ty, $side:ident . $field:ident) => {
        impl $module::Behavior for Hand<$port> {
            fn start(&mut self, cx: &mut $module::Cx<'_>) -> SectionResult {
                let _ = self.0.send(cx.$side.$field.clone());
                Ok(())
            }
        }
    };
}

hand!(source, DataOut<Reading>, outputs.out);
hand!(pose_source, DataOut<Pose>, outputs.out);
hand!(poster_source, PosterOut<Pose>, outputs.out);
hand!(tick_source, TickOut, outputs.out);
hand!(shm_source, DataOut<Chunk>, outputs.out);
hand!(lidar, DataOut<LaserScan>, outputs.scan);
hand!(ranger, DataOut<Ranges>, outputs.ranges);
hand!(wide_queue, FifoIn<Pose>, inputs.input);
hand!(queue, FifoIn<Pose>, inputs.input);
hand!(small_queue, FifoIn<Pose>, inputs.input);
hand!(tiny_queue, FifoIn<Pose>, inputs.input);
hand!(blocking_queue, FifoIn<Pose>, inputs.input);
hand!(growing_queue, UfifoIn<Pose>, inputs.input);
hand!(shm_queue, FifoIn<Chunk>, inputs.input);
hand!(chunk_queue, UfifoIn<Chunk>, inputs.input);
hand!(picture_source, DataOut<Picture>, outputs.out);
hand!(picture_queue, FifoIn<Picture>, inputs.input);
hand!(latest, LastIn<Pose>, inputs.input);
hand!(reader, PosterIn<Pose>, inputs.input);
hand!(ticks, TickIn, inputs.input);
hand!(goal, LastIn<Pose>, inputs.goal);
hand!(drive, FifoIn<Twist>, inputs.cmd);
hand!(wheels, FifoIn<Speed>, inputs.speed);

impl two_source::Behavior for Hand<(PosterOut<Pose>, DataOut<Pose>)> {
    fn start(&mut self, cx: &mut two_source::Cx<'_>) -> SectionResult {
        let _ = self
            .0
            .send((cx.outputs.post.clone(), cx.outputs.data.clone()));
        Ok(())
    }
}

/// A system of `source` feeding an outlet named `outlet` on `key`, which takes its
/// packets as `kind`, running; `source`'s behaviour hands its output `out` over
/// through `handed`. Returns the system and that output.
pub fn outlet_fed<T>(
    node: &Node,
    key: &str,
    kind: InputKind,
    source: Component,
    handed: &Receiver<DataOut<T>>,
) -> (System, DataOut<T>)
where
    T: Packet + serde::Serialize + serde::de::DeserializeOwned,
{
    fed(node, &[("outlet".to_owned(), key)], kind, source, handed)
}

/// A system of `source` feeding an outlet on each of `keys` (`outlet_0`, `outlet_1`,
/// ...: a fifo connection each when `kind` is a fifo), each taking its packets as
/// `kind`, running; `source`'s behaviour hands its output `out` over through `handed`.
/// Returns the system and that output.
pub fn outlets_fed<T>(
    node: &Node,
    keys: &[&str],
    kind: InputKind,
    source: Component,
    handed: &Receiver<DataOut<T>>,
) -> (System, DataOut<T>)
where
    T: Packet + serde::Serialize + serde::de::DeserializeOwned,
{
    let outlets: Vec<(String, &str)> = keys
        .iter()
        .enumerate()
        .map(|(index, key)| (format!("outlet_{index}"), *key))
        .collect();
    fed(node, &outlets, kind, source, handed)
}

/// A system of `source` feeding `outlets` (name, key), running; the system and the
/// output `handed` over.
fn fed<T>(
    node: &Node,
    outlets: &[(String, &str)],
    kind: InputKind,
    source: Component,
    handed: &Receiver<DataOut<T>>,
) -> (System, DataOut<T>)
where
    T: Packet + serde::Serialize + serde::de::DeserializeOwned,
{
    let mut system = System::new();
    let from = format!("{}.out", source.name());
    for (outlet, key) in outlets {
        system
            .add(
                node.outlet::<T>(outlet, key, kind)
                    .build()
                    .expect("the outlet"),
            )
            .expect("added");
    }
    system.add(source).expect("added");
    for (outlet, _) in outlets {
        system
            .connect(&from, &format!("{outlet}.input"))
            .expect("connected");
    }
    system.run_all().expect("runs");
    let out = handed.recv().expect("the source's output");
    (system, out)
}

/// A node with `tuner` and `source` running (`source`'s output `out` echoed, `idle`
/// not), the endpoint to reach it, and `out` to send on.
pub struct Sourced {
    /// The node, listening on `endpoint`.
    pub node: Node,
    /// Where the node listens (`tcp/127.0.0.1:<port>`).
    pub endpoint: String,
    /// The system of `tuner` and `source`, exposed on the node.
    pub system: System,
    /// `source`'s output, echoed.
    pub out: DataOut<Reading>,
}

/// Node `name` with a [`Sourced`] system, running.
pub fn sourced(name: &str) -> Sourced {
    let (node, endpoint) = node(name, &[]);
    let (hand, out) = crossbeam_channel::bounded(1);
    let mut system = System::new();
    system.add(source::component("source", Hand(hand))).unwrap();
    system.add(tuner::component("tuner", Tuning)).unwrap();
    system.run_all().unwrap();
    node.expose_system(&system).unwrap();
    node.echo::<Reading>(&system, "source.out").unwrap();
    let out = out.recv_timeout(PATIENCE).expect("the source started");
    Sourced {
        node,
        endpoint,
        system,
        out,
    }
}

/// A certificate authority: its certificate in `dir/<name>-ca.pem`, and what signs.
pub struct Authority {
    ca: PathBuf,
    issuer: Issuer<'static, KeyPair>,
}

impl Authority {
    /// A new authority named `name`, its certificate written in `dir`.
    pub fn new(dir: &Path, name: &str) -> Authority {
        let key = KeyPair::generate().expect("a CA key");
        let mut params = CertificateParams::new(Vec::<String>::new()).expect("CA params");
        params.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
        params.distinguished_name.push(DnType::CommonName, name);
        let certificate = params.self_signed(&key).expect("a self-signed CA");
        let ca = dir.join(format!("{name}-ca.pem"));
        std::fs::write(&ca, certificate.pem()).expect("write the CA");
        Authority {
            ca,
            issuer: Issuer::new(params, key),
        }
    }

    /// A security file `dir/<file>.toml` for the node whose certificate's common name
    /// is `name`, with `rules` (TOML `[[allow]]` tables) after its `[tls]` table.
    pub fn node(&self, dir: &Path, file: &str, name: &str, rules: &str) -> PathBuf {
        self.node_with(dir, file, name, "", rules)
    }

    /// [`Authority::node`] with `top` (top-level keys) before the `[tls]` table.
    pub fn node_with(&self, dir: &Path, file: &str, name: &str, top: &str, rules: &str) -> PathBuf {
        let key = KeyPair::generate().expect("a node key");
        let mut params =
            CertificateParams::new(vec!["localhost".to_owned(), "127.0.0.1".to_owned()])
                .expect("node params");
        params.distinguished_name.push(DnType::CommonName, name);
        let certificate = params.signed_by(&key, &self.issuer).expect("signed");
        std::fs::write(dir.join(format!("{file}.pem")), certificate.pem()).expect("write");
        std::fs::write(dir.join(format!("{file}.key")), key.serialize_pem()).expect("write");
        let path = dir.join(format!("{file}.toml"));
        let ca = self.ca.file_name().expect("a file").to_string_lossy();
        std::fs::write(
            &path,
            format!(
                "{top}\n[tls]\nca = \"{ca}\"\ncertificate = \"{file}.pem\"\nkey = \"{file}.key\"\n\n{rules}"
            ),
        )
        .expect("write the security file");
        path
    }
}
