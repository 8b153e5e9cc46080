//! `coolctl`: look at and command CoolBOT nodes over Zenoh.
//!
//! ```text
//! coolctl nodes [--watch]
//! coolctl list [node]
//! coolctl watch <node>/<path> [--count N] [--for 10s]
//! coolctl set <node>/<path> state suspended
//! coolctl set <node>/<path> max_speed=0.5
//! ```
//!
//! Exit codes: 0 done, 1 a command rejected or nothing answered, 2 usage or network
//! errors.

use std::io::Write;
use std::process::ExitCode;
use std::time::Duration;

use clap::{Parser, Subcommand};
use coolbot_zenoh::ctl::{Ctl, CtlError, parse_duration};

/// Look at and command the CoolBOT components of the nodes on the network.
#[derive(Debug, Parser)]
#[command(name = "coolctl", version)]
struct Cli {
    /// Connect to this Zenoh endpoint (e.g. tcp/192.168.1.10:7447); repeatable.
    #[arg(long, global = true)]
    connect: Vec<String>,
    /// Listen on this Zenoh endpoint; repeatable.
    #[arg(long, global = true)]
    listen: Vec<String>,
    /// Do not look for peers by multicast scouting (name them with --connect).
    #[arg(long, global = true)]
    no_multicast: bool,
    /// How long to wait for answers (e.g. 500ms, 2s).
    #[arg(long, global = true, default_value = "2s", value_parser = duration)]
    timeout: Duration,
    #[command(subcommand)]
    command: Action,
}

#[derive(Debug, Subcommand)]
enum Action {
    /// The nodes alive on the network.
    Nodes {
        /// Then print `+ <node>` and `- <node>` as nodes come and go.
        #[arg(long)]
        watch: bool,
        /// With --watch: stop after this many changes.
        #[arg(long, requires = "watch")]
        count: Option<usize>,
        /// With --watch: stop after this long (e.g. 10s).
        #[arg(long = "for", requires = "watch", value_parser = duration)]
        duration: Option<Duration>,
    },
    /// Every component of a node (or of every node): state, user state, quality,
    /// missed deadlines, overruns, overflows.
    List {
        /// Only this node.
        node: Option<String>,
    },
    /// Print a component's monitoring events as they happen.
    Watch {
        /// The component, as NODE/PATH (e.g. robot/base.motion).
        target: String,
        /// Stop after this many events.
        #[arg(long)]
        count: Option<usize>,
        /// Stop after this long (e.g. 10s).
        #[arg(long = "for", value_parser = duration)]
        duration: Option<Duration>,
    },
    /// Command a component: `state <ready|running|suspended|dead>`, or
    /// `<variable>=<value>` (period, max_response, priority, quality, or a
    /// controllable variable).
    Set {
        /// The component, as NODE/PATH.
        target: String,
        /// `state <state>` or `<variable>=<value>`.
        #[arg(required = true, num_args = 1..=2)]
        args: Vec<String>,
    },
}

fn duration(text: &str) -> Result<Duration, String> {
    parse_duration(text).map_err(|error| error.to_string())
}

fn run(cli: Cli, out: &mut dyn Write) -> Result<bool, CtlError> {
    let config = coolbot_zenoh::peer_config(&cli.listen, &cli.connect, !cli.no_multicast)
        .map_err(|error| CtlError::Zenoh(error.to_string()))?;
    let session = {
        use zenoh::Wait;
        zenoh::open(config)
            .wait()
            .map_err(|error| CtlError::Zenoh(error.to_string()))?
    };
    let ctl = Ctl::new(session, cli.timeout);
    match cli.command {
        Action::Nodes { watch: false, .. } => ctl.nodes(out).map(|()| true),
        Action::Nodes {
            watch: true,
            count,
            duration,
        } => ctl.watch_nodes(count, duration, out).map(|()| true),
        Action::List { node } => ctl.list(node.as_deref(), out).map(|()| true),
        Action::Watch {
            target,
            count,
            duration,
        } => ctl.watch(&target, count, duration, out).map(|()| true),
        Action::Set { target, args } => ctl.set(&target, &args, out),
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let stdout = std::io::stdout();
    match run(cli, &mut stdout.lock()) {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::from(1),
        Err(error @ CtlError::NoAnswer { .. }) => {
            eprintln!("coolctl: {error}");
            ExitCode::from(1)
        }
        Err(error) => {
            eprintln!("coolctl: {error}");
            ExitCode::from(2)
        }
    }
}
