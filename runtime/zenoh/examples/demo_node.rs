//! A node to try `coolctl` on: a compound `robot` holding a periodic `counter` (an
//! observable `count`, a controllable `step`) and an idle `logger`, exposed on the
//! network.
//!
//! ```sh
//! cargo run -p coolbot-zenoh --example demo_node -- --listen tcp/127.0.0.1:7447 --no-multicast
//! cargo run -p coolbot-zenoh --bin coolctl -- --connect tcp/127.0.0.1:7447 --no-multicast list
//! cargo run -p coolbot-zenoh --bin coolctl -- --connect tcp/127.0.0.1:7447 --no-multicast \
//!     set demo/robot.counter step=5
//! ```

use std::time::{Duration, Instant};

use clap::Parser;
use coolbot::{
    Automaton, CompoundBuilder, Context, Fault, PeriodicSpec, PortSet, Section, Spec, StateSpec,
    Supervisor, System, TimingSpec, Value, ValueRefused, VarKind, VarSpec,
};
use coolbot_zenoh::Node;

/// Run a small system exposed on the network until killed (or for a while).
#[derive(Debug, Parser)]
struct Args {
    /// The node's name.
    #[arg(long, default_value = "demo")]
    name: String,
    /// Listen on this endpoint; repeatable.
    #[arg(long)]
    listen: Vec<String>,
    /// Connect to this endpoint; repeatable.
    #[arg(long)]
    connect: Vec<String>,
    /// Do not scout for peers by multicast.
    #[arg(long)]
    no_multicast: bool,
    /// The security file: TLS certificates and access rules (docs/distribution.md,
    /// "Security").
    #[arg(long, value_name = "FILE")]
    config: Option<std::path::PathBuf>,
    /// Allow plaintext endpoints off loopback, and multicast scouting, without TLS.
    #[arg(long)]
    insecure: bool,
    /// Stop after this many seconds (default: run until killed).
    #[arg(long = "for")]
    seconds: Option<u64>,
}

static COUNTER: Spec = Spec {
    type_name: "Counter",
    doc: "Adds `step` to `count` every 500 ms.",
    states: &[StateSpec {
        name: "counting",
        entry: false,
        exit: false,
        periodic: Some(PeriodicSpec { period: None }),
        on: &[],
        after: &[],
        may: &[],
    }],
    initial: 0,
    inputs: &[],
    outputs: &[],
    variables: &[
        VarSpec {
            name: "count",
            kind: VarKind::Observable,
            ty: "u64",
            doc: "",
            range: None,
        },
        VarSpec {
            name: "step",
            kind: VarKind::Controllable,
            ty: "u64",
            doc: "",
            range: None,
        },
    ],
    exceptions: &[],
    timing: TimingSpec {
        period: Some(Duration::from_millis(500)),
        ..TimingSpec::NONE
    },
};

static IDLE: Spec = Spec {
    type_name: "Idle",
    doc: "Does nothing.",
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
    inputs: &[],
    outputs: &[],
    variables: &[],
    exceptions: &[],
    timing: TimingSpec::NONE,
};

struct Counter {
    spec: &'static Spec,
    count: u64,
    step: u64,
}

impl Automaton for Counter {
    fn spec(&self) -> &'static Spec {
        self.spec
    }
    fn section(&mut self, _: usize, section: Section, _: &mut Context) -> Result<(), Fault> {
        if section == Section::Periodic {
            self.count += self.step;
        }
        Ok(())
    }
    fn set(&mut self, variable: usize, value: &Value) -> Result<(), ValueRefused> {
        match variable {
            1 => {
                self.step = u64::try_from(value).map_err(ValueRefused::other)?;
                Ok(())
            }
            _ => Err(ValueRefused::not_settable(self.spec, variable)),
        }
    }
    fn get(&self, variable: usize) -> Value {
        match variable {
            0 => Value::from(self.count),
            _ => Value::from(self.step),
        }
    }
}

struct Exploring;

impl Supervisor for Exploring {
    fn spec(&self) -> &'static Spec {
        static SUPERVISOR: Spec = Spec {
            type_name: "Robot",
            doc: "",
            states: &[StateSpec {
                name: "exploring",
                entry: false,
                exit: false,
                periodic: None,
                on: &[],
                after: &[],
                may: &[],
            }],
            initial: 0,
            inputs: &[],
            outputs: &[],
            variables: &[],
            exceptions: &[],
            timing: TimingSpec::NONE,
        };
        &SUPERVISOR
    }
}

fn component(name: &str, spec: &'static Spec) -> coolbot::Component {
    let counter = Counter {
        spec,
        count: 0,
        step: 1,
    };
    coolbot::Component::new(name, Box::new(counter), PortSet::new())
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = Args::parse();
    let security = match &args.config {
        Some(path) => coolbot_zenoh::Security::load(path)?,
        None => coolbot_zenoh::Security::none(),
    }
    .allow_plaintext(args.insecure);
    let config =
        coolbot_zenoh::secure_config(&args.listen, &args.connect, !args.no_multicast, &security)?;
    let node = Node::open(&args.name, config)?;
    let robot = CompoundBuilder::new("robot", Exploring)
        .instance(component("counter", &COUNTER))
        .instance(component("logger", &IDLE))
        .build()?;
    let mut system = System::new();
    system.add(robot)?;
    system.run_all()?;
    node.expose_system(&system)?;
    println!("node `{}` running; components exposed", args.name);
    let started = Instant::now();
    while args
        .seconds
        .is_none_or(|seconds| started.elapsed() < Duration::from_secs(seconds))
    {
        std::thread::sleep(Duration::from_millis(100));
    }
    drop(node);
    let report = system.shutdown();
    println!("stopped: clean = {}", report.clean());
    Ok(())
}
