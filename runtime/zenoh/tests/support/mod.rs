//! What the network tests share: two nodes on loopback with explicit endpoints and
//! multicast scouting off, hand-written components (ports, variables, pull answers),
//! and waiting for conditions.

#![allow(
    dead_code,
    reason = "each test binary includes this module and uses a different part of it"
)]

use std::net::TcpListener;
use std::time::{Duration, Instant};

use coolbot::{
    Automaton, Component, Context, Fault, InputSpec, OutputSpec, PortSet, Section, Spec, StateSpec,
    TimingSpec, Value, VarKind, VarSpec,
};
use coolbot_zenoh::Node;
use zenoh::Wait;

/// Generous: the machine is shared and may be loaded.
pub const PATIENCE: Duration = Duration::from_secs(30);

/// A TCP port free on 127.0.0.1 now.
pub fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .and_then(|listener| listener.local_addr())
        .map(|address| address.port())
        .expect("a free loopback port")
}

/// A node listening on a free loopback port, connecting to `connect`.
pub fn node(name: &str, connect: &[String]) -> (Node, String) {
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let config = coolbot_zenoh::peer_config(std::slice::from_ref(&endpoint), connect, false)
        .expect("config");
    (Node::open(name, config).expect("open node"), endpoint)
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

/// A spec with the given ports and variables and one state that does nothing.
pub fn spec(
    type_name: &'static str,
    inputs: Vec<InputSpec>,
    outputs: Vec<OutputSpec>,
    variables: Vec<VarSpec>,
) -> &'static Spec {
    Box::leak(Box::new(Spec {
        type_name,
        doc: "",
        states: &[StateSpec {
            name: "idle",
            entry: false,
            exit: false,
            periodic: None,
            on: &[],
            after: &[],
            may: &[],
        }],
        initial: 0,
        inputs: Box::leak(inputs.into_boxed_slice()),
        outputs: Box::leak(outputs.into_boxed_slice()),
        variables: Box::leak(variables.into_boxed_slice()),
        exceptions: &[],
        timing: TimingSpec::NONE,
    }))
}

/// An observable or controllable variable's spec.
pub fn var(name: &'static str, kind: VarKind) -> VarSpec {
    VarSpec {
        name,
        kind,
        ty: "f64",
        doc: "",
    }
}

/// What a pull answer does (on the component's thread), by output index.
pub type Answer = Box<dyn FnMut(usize) + Send>;

/// A component with ports the test drives from outside, variables it keeps, and an
/// optional pull answer.
pub struct Shell {
    spec: &'static Spec,
    values: Vec<Value>,
    answer: Option<Answer>,
}

impl Shell {
    /// A component named `name` of shape `spec` with `ports`.
    pub fn component(name: &str, spec: &'static Spec, ports: PortSet) -> Component {
        Shell::with_answer(name, spec, ports, None)
    }

    /// The same, answering pull requests with `answer`.
    pub fn with_answer(
        name: &str,
        spec: &'static Spec,
        ports: PortSet,
        answer: Option<Answer>,
    ) -> Component {
        let values = spec.variables.iter().map(|_| Value::Float(0.0)).collect();
        Component::new(
            name,
            Box::new(Shell {
                spec,
                values,
                answer,
            }),
            ports,
        )
    }
}

impl Automaton for Shell {
    fn spec(&self) -> &'static Spec {
        self.spec
    }
    fn start(&mut self, _cx: &mut Context) -> Result<(), Fault> {
        Ok(())
    }
    fn stop(&mut self, _cx: &mut Context) {}
    fn section(&mut self, _: usize, _: Section, _: &mut Context) -> Result<(), Fault> {
        Ok(())
    }
    fn choose(&mut self, _: usize, _: &mut Context) -> Option<usize> {
        None
    }
    fn exception(&mut self, _: usize, _: &str, _: &mut Context) {}
    fn answer(&mut self, output: usize, _: &mut Context) -> Result<(), Fault> {
        if let Some(answer) = &mut self.answer {
            answer(output);
        }
        Ok(())
    }
    fn configure(&mut self, _: &Value) -> Result<(), String> {
        Err("no configuration".to_owned())
    }
    fn set(&mut self, variable: usize, value: &Value) -> Result<(), String> {
        if self.spec.variables[variable].kind != VarKind::Controllable {
            return Err("not controllable".to_owned());
        }
        let number = f64::try_from(value).map_err(|error| error.to_string())?;
        self.values[variable] = Value::Float(number);
        Ok(())
    }
    fn get(&self, variable: usize) -> Value {
        self.values[variable].clone()
    }
}

/// A compound's supervisor with one state that does nothing.
pub struct Idle(&'static Spec);

impl coolbot::Supervisor for Idle {
    fn spec(&self) -> &'static Spec {
        self.0
    }
}

/// [`Idle`] in state `state`, of a compound type named `Compound`.
pub fn supervisor(state: &'static str) -> Idle {
    supervisor_of("Compound", state)
}

/// [`Idle`] in state `state`, of compound type `type_name`.
pub fn supervisor_of(type_name: &'static str, state: &'static str) -> Idle {
    let states: &'static [StateSpec] = Box::leak(Box::new([StateSpec {
        name: state,
        entry: false,
        exit: false,
        periodic: None,
        on: &[],
        after: &[],
        may: &[],
    }]));
    Idle(Box::leak(Box::new(Spec {
        type_name,
        doc: "",
        states,
        initial: 0,
        inputs: &[],
        outputs: &[],
        variables: &[],
        exceptions: &[],
        timing: TimingSpec::NONE,
    })))
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

/// The robot's system of the network tests: a compound `robot` (holding a compound
/// `base` with `motion` and `ranges`, and a `planner`) and an atomic `logger`,
/// running, exposed on `node`.
pub fn robot(node: &Node) -> coolbot::System {
    let motion = spec(
        "Motion",
        vec![],
        vec![],
        vec![
            var("odometry", VarKind::Observable),
            var("max_speed", VarKind::Controllable),
        ],
    );
    let plain = spec("Plain", vec![], vec![], vec![]);
    let base = coolbot::CompoundBuilder::new("base", supervisor("operating"))
        .instance(Shell::component("motion", motion, PortSet::new()))
        .instance(Shell::component("ranges", plain, PortSet::new()))
        .build()
        .unwrap();
    let robot = coolbot::CompoundBuilder::new("robot", supervisor("exploring"))
        .instance(base)
        .instance(Shell::component("planner", plain, PortSet::new()))
        .build()
        .unwrap();
    let mut system = coolbot::System::new();
    system.add(robot).unwrap();
    system
        .add(Shell::component("logger", plain, PortSet::new()))
        .unwrap();
    system.run_all().unwrap();
    node.expose_system(&system).unwrap();
    system
}
