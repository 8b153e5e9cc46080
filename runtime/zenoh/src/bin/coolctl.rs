//! `coolctl`: look at and command CoolBOT nodes over Zenoh.
//!
//! ```text
//! coolctl nodes [--watch]
//! coolctl list [node]
//! coolctl watch <node>/<path> [--count N] [--for 10s]
//! coolctl set <node>/<path> state suspended
//! coolctl set <node>/<path> max_speed=0.5
//! coolctl get <node>/<path>
//! coolctl configure <node>/<path> FIELD=VALUE...
//! coolctl degrade <node>/<path> LEVEL
//! coolctl echo <node>/<path>.<port> [--hz 10] [--count N] [--for 10s]
//! coolctl top [--once [--json] [--size 160x40]] [--refresh 1s]
//! coolctl foxglove [--bind 127.0.0.1:8765] [--port 'NODE/PATH.PORT'...] [--map FILE] [--refresh 1s]
//!                  [--tls-certificate FILE --tls-key FILE]
//! ```
//!
//! Exit codes: 0 done, 1 a command rejected, nothing answered or found (no node
//! alive, nothing listed), or no such node, component or port (each within
//! `--timeout`), 2 usage or network errors (`top` without a terminal, a file given
//! that cannot be read or is too large).

use std::io::Write;
use std::process::ExitCode;
use std::time::Duration;

use clap::{Parser, Subcommand};
use coolbot::Chain;
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
    /// Do not look for peers by multicast scouting (name them with --connect): the
    /// default without a security file's TLS.
    #[arg(long, global = true)]
    no_multicast: bool,
    /// Look for peers by multicast scouting on the whole network (the default with a
    /// security file's TLS; without TLS it needs --insecure).
    #[arg(long, global = true, conflicts_with = "no_multicast")]
    multicast: bool,
    /// The security file (TLS certificates and access rules) the nodes use; its
    /// certificate's common name is who coolctl is to their access rules.
    #[arg(long, global = true, value_name = "FILE")]
    config: Option<std::path::PathBuf>,
    /// Allow plaintext (tcp/) endpoints off loopback, and multicast scouting, without
    /// TLS.
    #[arg(long, global = true)]
    insecure: bool,
    /// How long to wait for answers (e.g. 500ms, 2s; more than zero).
    #[arg(long, global = true, default_value = "2s", value_parser = timeout)]
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
    /// A component's type, states, timing, and every variable with its kind, type
    /// and value.
    Get {
        /// The component, as NODE/PATH.
        target: String,
    },
    /// Send a component a configuration: the fields given (the others keep their
    /// values), each value typed (true/false, integers, floats, JSON, else text).
    Configure {
        /// The component, as NODE/PATH.
        target: String,
        /// FIELD=VALUE, one or more.
        #[arg(required = true)]
        fields: Vec<String>,
    },
    /// Set a component's adaptation level (0 = nominal; a compound: the cap of its
    /// instances).
    Degrade {
        /// The component, as NODE/PATH.
        target: String,
        /// The level.
        level: u32,
    },
    /// A live view of every component of every node (keys: up/down select, s
    /// suspend, r run, R restart, v set a variable, q quit).
    Top {
        /// Print one snapshot and exit: the screen as text, or JSON with --json.
        #[arg(long)]
        once: bool,
        /// With --once: JSON, for scripts.
        #[arg(long, requires = "once")]
        json: bool,
        /// With --once: the screen's size, COLUMNSxROWS.
        #[arg(long, requires = "once", default_value = "160x40", value_parser = size)]
        size: (u16, u16),
        /// How often the view asks every node again (with --once: the interval the
        /// CPU shares are measured over).
        #[arg(long, default_value = "1s", value_parser = duration)]
        refresh: Duration,
    },
    /// Serve the nodes' components to Foxglove (its WebSocket protocol): the echoed
    /// outputs the patterns select, every component's monitoring, the supervision
    /// and adaptation steps; until stopped (Ctrl-C).
    Foxglove {
        /// Listen here (off loopback only with --config or --insecure; port 0: any
        /// free port, printed).
        #[arg(long, default_value = coolbot_zenoh::foxglove::DEFAULT_BIND)]
        bind: std::net::SocketAddr,
        /// Serve the echoed outputs NODE/PATH.PORT that match (`*`: any characters,
        /// e.g. 'robot/*'); repeatable.
        #[arg(long = "port", value_name = "PATTERN")]
        ports: Vec<String>,
        /// Show the outputs this file names as Foxglove's well-known messages (poses,
        /// transforms, laser scans; docs/foxglove.md, "Well-known messages").
        #[arg(long, value_name = "FILE")]
        map: Option<std::path::PathBuf>,
        /// How often the nodes are asked for new components, and a watched
        /// component's monitoring is read.
        #[arg(long, default_value = "1s", value_parser = duration)]
        refresh: Duration,
        /// Speak wss:// (TLS) with this certificate (PEM); with --tls-key.
        #[arg(long, value_name = "FILE", requires = "tls_key")]
        tls_certificate: Option<std::path::PathBuf>,
        /// The certificate's private key (PEM, PKCS#8); with --tls-certificate.
        #[arg(long, value_name = "FILE", requires = "tls_certificate")]
        tls_key: Option<std::path::PathBuf>,
    },
    /// Print the packets an echoed output sends, one JSON line each (a summary with
    /// the packets skipped and lost goes to stderr at the end).
    Echo {
        /// The output, as NODE/PATH.PORT (e.g. robot/robot.base.scan).
        target: String,
        /// At most this many lines a second (the others are skipped and counted; the
        /// producer is never slowed).
        #[arg(long)]
        hz: Option<f64>,
        /// Stop after this many lines.
        #[arg(long)]
        count: Option<u64>,
        /// Stop after this long (e.g. 10s).
        #[arg(long = "for", value_parser = duration)]
        duration: Option<Duration>,
    },
}

fn duration(text: &str) -> Result<Duration, CtlError> {
    parse_duration(text)
}

fn timeout(text: &str) -> Result<Duration, CtlError> {
    match parse_duration(text) {
        Ok(timeout) if timeout.is_zero() => Err(CtlError::BadArgument(format!(
            "`{text}`: nothing answers in no time; give a timeout of more than zero (e.g. 2s)"
        ))),
        other => other,
    }
}

fn size(text: &str) -> Result<(u16, u16), CtlError> {
    let (columns, rows) = text.split_once('x').ok_or_else(|| {
        CtlError::BadArgument(format!("`{text}` is not COLUMNSxROWS (e.g. 160x40)"))
    })?;
    let parse = |n: &str| {
        n.parse::<u16>()
            .ok()
            .filter(|n| (10..=1000).contains(n))
            .ok_or_else(|| CtlError::BadArgument(format!("`{n}` is not a size from 10 to 1000")))
    };
    Ok((parse(columns)?, parse(rows)?))
}

fn run(cli: Cli, out: &mut dyn Write) -> Result<bool, CtlError> {
    let security = match &cli.config {
        Some(path) => coolbot_zenoh::Security::load(path),
        None => Ok(coolbot_zenoh::Security::none()),
    }?
    .allow_plaintext(cli.insecure);
    // Multicast scouting reaches the whole network: on by default only under TLS.
    let multicast = cli.multicast || (!cli.no_multicast && security.has_tls());
    let config = coolbot_zenoh::secure_config(&cli.listen, &cli.connect, multicast, &security)?;
    let session = {
        use zenoh::Wait;
        zenoh::open(config)
            .wait()
            .map_err(CtlError::zenoh("open the session"))?
    };
    let ctl = Ctl::new(session.clone(), cli.timeout).with_security(&security)?;
    match cli.command {
        Action::Top {
            once: true,
            json: true,
            refresh,
            ..
        } => {
            writeln!(out, "{}", coolbot_zenoh::top::once_json(&ctl, refresh)?)?;
            Ok(true)
        }
        Action::Top {
            once: true,
            size: (columns, rows),
            refresh,
            ..
        } => {
            let (board, _) = coolbot_zenoh::top::board(&ctl, refresh)?;
            write!(out, "{}", coolbot_zenoh::top::render(&board, columns, rows))?;
            Ok(true)
        }
        Action::Top { refresh, .. } => {
            // The terminal is the display's: log lines wait until it is given back.
            coolbot::process::capture_output(true);
            let shown = coolbot_zenoh::top::run(&ctl, &session, refresh).map(|()| true);
            coolbot::process::capture_output(false);
            shown
        }
        Action::Foxglove {
            bind,
            ports,
            map,
            refresh,
            tls_certificate,
            tls_key,
        } => {
            let foxglove =
                |error: coolbot_zenoh::foxglove::FoxgloveError| CtlError::Foxglove(Box::new(error));
            let mappings = match map {
                Some(path) => coolbot_zenoh::foxglove::wellknown::Mappings::load(&path)
                    .map_err(|error| foxglove(error.into()))?,
                None => Default::default(),
            };
            let options = coolbot_zenoh::foxglove::Options {
                bind,
                ports,
                mappings,
                refresh,
                secured: cli.config.is_some(),
                insecure: cli.insecure,
                tls: tls_certificate.zip(tls_key).map(|(certificate, key)| {
                    coolbot_zenoh::foxglove::TlsFiles { certificate, key }
                }),
            };
            let scheme = options.scheme();
            let server = coolbot_zenoh::foxglove::Server::start(ctl, session.clone(), options)
                .map_err(foxglove)?;
            writeln!(out, "serving {scheme}://{}:{}", bind.ip(), server.port())?;
            out.flush()?;
            loop {
                std::thread::park();
            }
        }
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
        Action::Get { target } => ctl.get(&target, out).map(|()| true),
        Action::Configure { target, fields } => ctl.configure(&target, &fields, out),
        Action::Degrade { target, level } => ctl.degrade(&target, level, out),
        Action::Echo {
            target,
            hz,
            count,
            duration,
        } => {
            let summary = ctl.echo(&target, hz, count, duration, out)?;
            eprintln!("coolctl echo {target}: {summary}");
            Ok(true)
        }
    }
}

/// Zenoh's runtimes in `coolctl` unless `ZENOH_RUNTIME` says otherwise: every one
/// handed over to `net`, so all of Zenoh's work runs on one thread. A client's
/// traffic needs no more, and a sample received then wakes one thread, not three
/// (`docs/performance.md`, "Foxglove").
const ZENOH_RUNTIME: &str =
    "(rx: (handover: net), tx: (handover: net), acc: (handover: net), app: (handover: net))";

fn main() -> ExitCode {
    if std::env::var_os("ZENOH_RUNTIME").is_none() {
        // SAFETY: the first thing `main` does: no other thread exists yet that could
        // read the environment meanwhile (Zenoh reads it when it starts its runtimes).
        #[allow(unsafe_code)]
        unsafe {
            std::env::set_var("ZENOH_RUNTIME", ZENOH_RUNTIME);
        }
    }
    let cli = Cli::parse();
    // What goes wrong on the way (a packet a Foxglove mapping does not fit, one that
    // does not decode) is warned about on stderr; Zenoh's own warnings (no peer
    // found by scouting) are not coolctl's to give: only its errors.
    coolbot::process::init_logs("warn,zenoh=error");
    let stdout = std::io::stdout();
    match run(cli, &mut stdout.lock()) {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::from(1),
        Err(
            error @ (CtlError::NoAnswer { .. }
            | CtlError::Refused { .. }
            | CtlError::NoNode { .. }
            | CtlError::NoComponents { .. }
            | CtlError::UnknownNode { .. }
            | CtlError::UnknownComponent { .. }
            | CtlError::UnknownPort(_)),
        ) => {
            eprintln!("coolctl: {}", Chain(&error));
            ExitCode::from(1)
        }
        Err(error) => {
            eprintln!("coolctl: {}", Chain(&error));
            ExitCode::from(2)
        }
    }
}
