//! What the tests of the `coolctl` binary share (`coolctl.rs`, `security.rs`): a node
//! on loopback with explicit endpoints and multicast scouting off, waiting for
//! conditions, and the robot's system of hand-written components. The binary exists
//! only for this package's tests (`CARGO_BIN_EXE_coolctl`), and this package does not
//! depend on coolc: every other network test runs on generated components in
//! `tests/zenoh` (package `coolbot-zenoh-tests`), whose `cool/robot.cool` describes
//! the same robot.

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

/// A component with ports the test drives from outside and variables it keeps.
pub struct Shell {
    spec: &'static Spec,
    values: Vec<Value>,
}

impl Shell {
    /// A component named `name` of shape `spec` with `ports`.
    pub fn component(name: &str, spec: &'static Spec, ports: PortSet) -> Component {
        let values = spec.variables.iter().map(|_| Value::Float(0.0)).collect();
        Component::new(name, Box::new(Shell { spec, values }), ports)
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
    fn answer(&mut self, _: usize, _: &mut Context) -> Result<(), Fault> {
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
        type_name: "Compound",
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
