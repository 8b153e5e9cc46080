//! `mobile-base`: runs the simulated mobile robot of the CoolBOT paper and shows its
//! components live. See `examples/README.md`.

use std::process::ExitCode;
use std::time::Duration;

use clap::{Parser, ValueEnum};
use mobile_base::drivers::Drivers;
use mobile_base::node::NodeOptions;
use mobile_base::world::{FaultKind, Overload};
use mobile_base::{Display, Options};

/// Run the CoolBOT paper's mobile robot (MotionController, RangeServer, MobileBase)
/// in a simulated room.
#[derive(Debug, Parser)]
#[command(name = "mobile-base", version, about)]
struct Args {
    /// How long to run (e.g. `10s`, `1500ms`, `1min`); Ctrl-C stops earlier.
    #[arg(long, default_value = "10s", value_parser = parse_duration)]
    duration: Duration,
    /// Make the range sensors fail after this time (e.g. `3s`).
    #[arg(long, value_parser = parse_duration)]
    fault_after: Option<Duration>,
    /// How long the sensors stay down after the fault (past 5 s the recovery deadline
    /// expires and the range server is retired).
    #[arg(long, default_value = "1500ms", value_parser = parse_duration)]
    outage: Duration,
    /// How the range server fails: it raises its `sensor_timeout` exception, or panics.
    #[arg(long, value_enum, default_value_t = Fault::Raise)]
    fault: Fault,
    /// Range noise of the real sensors: standard deviation in metres (0: noise-free;
    /// default: the description's `noise = 0.005`).
    #[arg(long, value_parser = parse_noise)]
    noise: Option<f64>,
    /// Seed of the range noise and the wandering.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Seek this goal (`x,y` in metres; the room is 6 by 4) instead of wandering.
    #[arg(long, value_parser = parse_goal)]
    goal: Option<(f64, f64)>,
    /// The base's speed limit in m/s (its controllable `max_speed`, mapped onto the
    /// motion controller's).
    #[arg(long, value_parser = parse_speed)]
    max_speed: Option<f64>,
    /// The range servers' scan frequency in Hz, 0.5 to 20 (their controllable
    /// `frequency`; the range server publishes at most that often).
    #[arg(long, value_parser = parse_rate)]
    scan_rate: Option<f64>,
    /// Simulate a processor shortage from one time to another (e.g. `3s..9s`):
    /// meanwhile the range server's scans cost 7 ms a beam, whatever the machine's
    /// real load, and the runtime degrades it (a longer period, then half scans) and
    /// promotes it back once the shortage is over.
    #[arg(long, value_name = "FROM..UNTIL", value_parser = parse_load)]
    load: Option<Overload>,
    /// Expose every component on the network as this Zenoh node, for `coolctl`
    /// (`cargo run -p coolbot-zenoh --bin coolctl -- list` in another terminal).
    #[arg(long, value_name = "NAME")]
    node: Option<String>,
    /// With --node: do not run the robot; run what other nodes place on this one (the
    /// wanderer, declared `on "station"`: `--node station --serve`; the range server,
    /// `on "drivers"` with --drivers: `--node drivers --serve`) until stopped.
    #[arg(long, requires = "node")]
    serve: bool,
    /// With --serve: end when the process PID is no longer this one's parent (a
    /// drivers process started by a robot ends with it).
    #[arg(long, requires = "serve", value_name = "PID", hide = true)]
    parent: Option<u32>,
    /// Run the range server in a process of its own on this host, the node `drivers`:
    /// this binary with `--node drivers --serve`, which the robot starts, starts again
    /// when it ends, and stops at the end. The robot is on the network too (--node, or
    /// the node `robot` on a loopback port). Needs the `network` feature.
    #[arg(long, conflicts_with_all = ["serve", "config"])]
    drivers: bool,
    /// With --node: the Zenoh session lease, after which a silent peer is lost (e.g.
    /// `2s`, the default); an instance on a lost node is a fault of its proxy.
    #[arg(long, requires = "node", value_parser = parse_duration)]
    lease: Option<Duration>,
    /// With --node: how long the wanderer, placed on the station, may leave its
    /// monitoring unanswered before its proxy fails (e.g. `3s`, the default).
    #[arg(long, requires = "node", value_parser = parse_duration)]
    silence: Option<Duration>,
    /// With --node: listen on this Zenoh endpoint (e.g. `tcp/127.0.0.1:7447`; off
    /// loopback, `quic/0.0.0.0:7447` with --config, or tcp with --insecure); repeatable.
    #[arg(long, requires = "node", value_name = "ENDPOINT")]
    listen: Vec<String>,
    /// With --node: connect to this Zenoh endpoint; repeatable.
    #[arg(long, requires = "node", value_name = "ENDPOINT")]
    connect: Vec<String>,
    /// With --node: do not look for peers by multicast scouting (name them with
    /// --listen / --connect): the default without TLS.
    #[arg(long, requires = "node")]
    no_multicast: bool,
    /// With --node: look for peers by multicast scouting (the default with TLS;
    /// without TLS it needs --insecure).
    #[arg(long, requires = "node", conflicts_with = "no_multicast")]
    multicast: bool,
    /// With --node: the security file, TLS certificates and access rules
    /// (docs/distribution.md, "Security"); without one the node stays on loopback.
    #[arg(long, requires = "node", value_name = "FILE")]
    config: Option<std::path::PathBuf>,
    /// With --node: allow plaintext endpoints off loopback, and multicast scouting,
    /// without TLS.
    #[arg(long, requires = "node")]
    insecure: bool,
    /// Output: the live table, status lines, or auto (the table on a terminal).
    #[arg(long, value_enum, default_value_t = Output::Auto)]
    output: Output,
    /// Record the odometry, the scans and the base's monitoring events into this file
    /// (MCAP: Foxglove and the MCAP tools open it; see docs/tools.md).
    #[arg(long, value_name = "FILE")]
    record: Option<std::path::PathBuf>,
    /// The format of --record: `coolbot` (MCAP, above) or `ros2` (a rosbag2 bag
    /// directory of the ROS 2 topics /scan and /odom, with --ros2 /cmd_vel too:
    /// `ros2 bag info FILE` reads it).
    #[arg(long, value_name = "FORMAT", requires = "record", default_value = "coolbot", value_parser = parse_format)]
    record_format: coolbot::record::RecordFormat,
    /// Join ROS 2 over Zenoh as rmw_zenoh does: publish /scan
    /// (sensor_msgs/msg/LaserScan) and /odom (nav_msgs/msg/Odometry), and drive the
    /// base by /cmd_vel (geometry_msgs/msg/Twist) while Twists keep arriving.
    #[cfg(feature = "ros2")]
    #[arg(long)]
    ros2: bool,
    /// With --ros2: the Zenoh router ROS 2 runs on (`ros2 run rmw_zenoh_cpp rmw_zenohd`).
    #[cfg(feature = "ros2")]
    #[arg(
        long,
        requires = "ros2",
        value_name = "ENDPOINT",
        default_value = "tcp/127.0.0.1:7447"
    )]
    ros_router: String,
    /// With --ros2: the ROS domain id (ROS_DOMAIN_ID).
    #[cfg(feature = "ros2")]
    #[arg(long, requires = "ros2", value_name = "N", default_value_t = 0)]
    ros_domain: u32,
    /// With --ros2: the node's namespace; the topics are in it (`/robot1`: /robot1/scan).
    #[cfg(feature = "ros2")]
    #[arg(long, requires = "ros2", value_name = "NS", default_value = "/")]
    ros_namespace: String,
    /// With --ros2: the node's name.
    #[cfg(feature = "ros2")]
    #[arg(
        long,
        requires = "ros2",
        value_name = "NAME",
        default_value = "mobile_base"
    )]
    ros_node: String,
}

/// Parses a recording format: `coolbot` or `ros2`.
fn parse_format(text: &str) -> Result<coolbot::record::RecordFormat, String> {
    text.parse()
        .map_err(|_| format!("`{text}` is not a recording format: coolbot or ros2"))
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum Fault {
    Raise,
    Panic,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum Output {
    Auto,
    Table,
    Lines,
}

/// Parses `250ms`, `10s`, `1.5s`, `2min`, `500us`.
fn parse_duration(text: &str) -> Result<Duration, String> {
    let text = text.trim();
    let split = text
        .find(|c: char| !(c.is_ascii_digit() || c == '.'))
        .ok_or_else(|| format!("`{text}` needs a unit: ms, s or min"))?;
    let (number, unit) = text.split_at(split);
    let value: f64 = number
        .parse()
        .map_err(|_| format!("`{text}` does not start with a number"))?;
    let seconds = match unit {
        "us" => value / 1e6,
        "ms" => value / 1e3,
        "s" => value,
        "min" => value * 60.0,
        _ => return Err(format!("unknown unit `{unit}` (use us, ms, s or min)")),
    };
    Duration::try_from_secs_f64(seconds).map_err(|e| format!("`{text}`: {e}"))
}

/// Parses a noise level: 0 to 0.5 m.
fn parse_noise(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(noise) if (0.0..=0.5).contains(&noise) => Ok(noise),
        _ => Err(format!("`{text}` is not a noise level from 0 to 0.5 (m)")),
    }
}

/// Parses a speed limit: 0 to 2 m/s.
fn parse_speed(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(speed) if (0.0..=2.0).contains(&speed) => Ok(speed),
        _ => Err(format!("`{text}` is not a speed from 0 to 2 (m/s)")),
    }
}

/// Parses a scan frequency the range servers serve: 0.5 to 20 Hz.
fn parse_rate(text: &str) -> Result<f64, String> {
    use mobile_base::sensing::{MAX_SCAN_RATE, period_for};
    match text.parse::<f64>() {
        Ok(rate) if period_for(rate).is_some() && rate <= MAX_SCAN_RATE => Ok(rate),
        _ => Err(format!(
            "`{text}` is not a frequency from 0.5 to {MAX_SCAN_RATE} (Hz)"
        )),
    }
}

/// Parses `FROM..UNTIL`, two durations (`3s..9s`), FROM before UNTIL.
fn parse_load(text: &str) -> Result<Overload, String> {
    let (from, until) = text
        .split_once("..")
        .ok_or_else(|| format!("`{text}` is not FROM..UNTIL, e.g. `3s..9s`"))?;
    let (from, until) = (parse_duration(from)?, parse_duration(until)?);
    if from >= until {
        return Err(format!("`{text}`: the shortage must end after it starts"));
    }
    Ok(Overload { from, until })
}

/// Parses `x,y`.
fn parse_goal(text: &str) -> Result<(f64, f64), String> {
    let (x, y) = text.split_once(',').ok_or("expected `x,y`, e.g. `5,3`")?;
    let parse = |s: &str| {
        s.trim()
            .parse::<f64>()
            .map_err(|_| format!("`{s}` is not a number"))
    };
    Ok((parse(x)?, parse(y)?))
}

fn main() -> ExitCode {
    let args = Args::parse();
    // Logs (RUST_LOG), SIGINT and SIGTERM (a clean shutdown), and the panic hook: a
    // panic the runtime catches in a component prints one line.
    // The logs default to warnings: the run's own output shows the supervision and
    // adaptation steps (RUST_LOG=info shows the runtime's too).
    let process = match coolbot::process::Process::builder()
        .default_log("warn")
        .init()
    {
        Ok(process) => process,
        Err(error) => {
            eprintln!("error: {}", coolbot::Chain(&error));
            return ExitCode::from(2);
        }
    };
    let options = Options {
        duration: args.duration,
        fault_after: args.fault_after,
        outage: args.outage,
        fault_kind: match args.fault {
            Fault::Raise => FaultKind::Raise,
            Fault::Panic => FaultKind::Panic,
        },
        noise: args.noise,
        seed: args.seed,
        goal: args.goal,
        max_speed: args.max_speed,
        scan_rate: args.scan_rate,
        display: match args.output {
            Output::Auto => Display::Auto,
            Output::Table => Display::Table,
            Output::Lines => Display::Lines,
        },
        record: args.record,
        record_format: args.record_format,
        #[cfg(feature = "ros2")]
        ros2: args.ros2.then(|| mobile_base::ros::RosSetup {
            router: args.ros_router.clone(),
            domain: args.ros_domain,
            namespace: args.ros_namespace.clone(),
            node: args.ros_node.clone(),
        }),
        load: args.load,
        node: args.node.map(|name| {
            let named = NodeOptions::named(name);
            NodeOptions {
                listen: args.listen,
                connect: args.connect,
                multicast: match (args.multicast, args.no_multicast) {
                    (true, _) => Some(true),
                    (_, true) => Some(false),
                    _ => None,
                },
                security: args.config,
                insecure: args.insecure,
                lease: args.lease.unwrap_or(named.lease),
                silence: args.silence.unwrap_or(named.silence),
                ..named
            }
        }),
        drivers: None,
        // The binary runs on the real clock.
        virtual_time: None,
        stop: process.stop_flag(),
    };
    if args.serve {
        return match mobile_base::serve(&options, args.parent) {
            Ok(name) => {
                println!("node `{name}` stopped");
                ExitCode::SUCCESS
            }
            Err(error) => {
                eprintln!("error: {error}");
                ExitCode::from(2)
            }
        };
    }
    let options = if args.drivers {
        let program = match std::env::current_exe() {
            Ok(program) => program,
            Err(error) => {
                eprintln!("error: --drivers: this program's path: {error}");
                return ExitCode::from(2);
            }
        };
        Options {
            drivers: Some(Drivers { program }),
            ..options
        }
    } else {
        options
    };
    match mobile_base::run(&options) {
        Ok(summary) => {
            println!("\n{summary}");
            if let Some(signal) = process.signal() {
                println!("stopped by {signal}");
            }
            if summary.clean_shutdown {
                ExitCode::SUCCESS
            } else {
                ExitCode::FAILURE
            }
        }
        Err(error) => {
            eprintln!("error: {error}");
            ExitCode::from(2)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn durations_parse_with_units() {
        assert_eq!(parse_duration("10s"), Ok(Duration::from_secs(10)));
        assert_eq!(parse_duration("1500ms"), Ok(Duration::from_millis(1500)));
        assert_eq!(parse_duration("1.5s"), Ok(Duration::from_millis(1500)));
        assert_eq!(parse_duration("2min"), Ok(Duration::from_secs(120)));
        assert!(parse_duration("10").is_err());
        assert!(parse_duration("10h").is_err());
        assert!(parse_duration("s").is_err());
    }

    #[test]
    fn limits_are_checked() {
        assert_eq!(parse_speed("0.3"), Ok(0.3));
        assert_eq!(parse_noise("0"), Ok(0.0));
        assert!(parse_noise("-0.1").is_err());
        assert!(parse_speed("-1").is_err());
        assert!(parse_speed("fast").is_err());
        assert_eq!(parse_rate("10"), Ok(10.0));
        assert!(parse_rate("40").is_err());
        assert!(parse_rate("1000").is_err());
        assert!(parse_rate("0").is_err());
    }

    #[test]
    fn load_windows_parse() {
        let ms = Duration::from_millis;
        assert_eq!(
            parse_load("3s..9s"),
            Ok(Overload {
                from: ms(3000),
                until: ms(9000)
            })
        );
        assert_eq!(
            parse_load("500ms..1.5s"),
            Ok(Overload {
                from: ms(500),
                until: ms(1500)
            })
        );
        assert!(parse_load("9s..3s").is_err());
        assert!(parse_load("3s").is_err());
        assert!(parse_load("3s..").is_err());
        assert!(parse_load("3..9s").is_err());
    }

    #[test]
    fn goals_parse() {
        assert_eq!(parse_goal("5,3"), Ok((5.0, 3.0)));
        assert!(parse_goal("5").is_err());
        assert!(parse_goal("a,3").is_err());
    }
}
