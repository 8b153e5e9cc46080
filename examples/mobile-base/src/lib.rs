//! The CoolBOT paper's mobile robot, simulated: the components of Figures 4 and 5
//! described in `examples/components/*.cool`, compiled by `coolc` from this crate's
//! build script, filled in here and run on the `coolbot` runtime.
//!
//! [`run`] builds the robot (see [`robot`]), lets it wander in its room for a while
//! with the mobile base's supervisor watching, shows the components' monitoring ports,
//! shuts everything down and returns a [`Summary`]. The `mobile-base` binary and the
//! integration test both call it.
#![deny(missing_docs)]

pub mod converters;
pub mod drivers;
pub mod finite;
pub mod mapper;
pub mod motion_controller;
pub mod node;
pub mod range_server;
pub mod robot;
#[cfg(feature = "ros2")]
pub mod ros;
pub mod sensing;
pub mod sim_range_server;
pub mod status;
pub mod teleop;
pub mod topics;
pub mod wanderer;
pub mod world;

/// The code `coolc` generated from `examples/components/*.cool` (in `OUT_DIR`).
#[allow(missing_docs, unused_qualifications)]
pub mod generated {
    include!(concat!(env!("OUT_DIR"), "/cool.rs"));
}

use std::fmt;
use std::io::{IsTerminal, Write};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use coolbot::adapt::{AdaptAction, Adaptation};
use coolbot::{Handle, Monitor, MonitorEvent, State, Step, Supervision};

use crate::drivers::{Drivers, DriversReport};
use crate::node::NodeOptions;
use crate::robot::{
    BASE, MAPPER, MOTION, RANGES, ROBOT, Ranges, Robot, SIM_RANGES, Setup, WANDERER,
};
use crate::world::{FaultKind, Overload, Platform, SensorFault, World};

/// How the run shows itself.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Display {
    /// The live table when stdout is a terminal, status lines otherwise.
    Auto,
    /// The live table, redrawn in place (ANSI).
    Table,
    /// One status line per second, and events as they happen.
    Lines,
    /// Nothing (tests).
    Quiet,
}

/// What to run.
#[derive(Clone, Debug)]
pub struct Options {
    /// How long the robot runs.
    pub duration: Duration,
    /// When the range sensors fail, if they do.
    pub fault_after: Option<Duration>,
    /// How long the sensors stay down after the fault.
    pub outage: Duration,
    /// How the range server fails.
    pub fault_kind: FaultKind,
    /// Range noise of the real sensors (m), if not the description's.
    pub noise: Option<f64>,
    /// Seed of the noise and the wandering.
    pub seed: u64,
    /// A goal for the wanderer to seek.
    pub goal: Option<(f64, f64)>,
    /// The base's speed limit (m/s), if not the description's.
    pub max_speed: Option<f64>,
    /// The range servers' scan frequency (Hz), if not the description's.
    pub scan_rate: Option<f64>,
    /// How the run shows itself.
    pub display: Display,
    /// Set to stop the run early (SIGINT or SIGTERM: `coolbot::process`).
    pub stop: Arc<AtomicBool>,
    /// Record the odometry (`base.motion.pose`), the scans (`base.scan`, from
    /// whichever range server stands in) and the base's monitoring events into this
    /// file (`coolbot::record`, MCAP); with `record_format` `Ros2`, the ROS 2 topics
    /// into a rosbag2 bag directory instead.
    pub record: Option<std::path::PathBuf>,
    /// The format of `record`: CoolBOT's own, or a rosbag2 bag of the ROS 2 topics
    /// (`/scan`, `/odom`, and with `ros2` `/cmd_vel`; no monitoring events).
    pub record_format: coolbot::record::RecordFormat,
    /// Join ROS 2 (`--ros2`): publish `/scan` and `/odom`, take `/cmd_vel`.
    #[cfg(feature = "ros2")]
    pub ros2: Option<ros::RosSetup>,
    /// A simulated processor shortage (`--load 3s..9s`): meanwhile the range server's
    /// scans cost time ([`world::OVERLOAD_COST_PER_BEAM`]), so that the runtime
    /// degrades it, and promotes it back after.
    pub load: Option<Overload>,
    /// Expose every component on the network as this Zenoh node (`--node`), for
    /// `coolctl`.
    pub node: Option<NodeOptions>,
    /// Run the range server in a process of its own, the node `drivers`, started and
    /// kept by this one (`--drivers`, `crate::drivers`; needs the `network` feature).
    /// The robot is then on the network as `node`, or as the node `robot` on a
    /// loopback port of its own.
    pub drivers: Option<Drivers>,
    /// Run on a virtual clock instead of the real one (tests): the robot's system, the
    /// simulated platform and the run itself read that clock only, and the run moves it
    /// forward itself, one step at a time, where it would otherwise sleep (see
    /// [`VirtualTime`]). `None` (the binary): the real clock.
    pub virtual_time: Option<VirtualTime>,
}

/// A run on a virtual clock ([`Options::virtual_time`]): the robot's system runs on
/// `clock` (`coolbot::System::with_clock`), so do the simulated platform's uptime,
/// faults and processor shortage ([`world::Platform::with_clock`]), the run's
/// duration and the stop request; each turn of the run advances the clock by `step`
/// ([`world::Platform::advance`]: every timer due by then has fired and every
/// component has settled when it returns, but for a section taking the simulated
/// shortage's processor time) instead of sleeping. What the run does
/// then depends on no real time, so not on the machine's load. Not with `node` or
/// `drivers` (other processes and the network keep real time).
#[derive(Clone)]
pub struct VirtualTime {
    /// The clock.
    pub clock: Arc<coolbot::VirtualClock>,
    /// How far each turn of the run advances it (10 ms, half the smallest period of
    /// the robot's components, keeps every period's timing).
    pub step: Duration,
    /// Called after each step with the run's time (since the start): a test's way to
    /// act at a time of the run (a stop request at 1.5 s: [`Options::stop`]).
    pub after_step: Option<Arc<dyn Fn(Duration) + Send + Sync>>,
}

impl VirtualTime {
    /// A new virtual clock, advanced 10 ms a turn.
    pub fn new() -> VirtualTime {
        VirtualTime {
            clock: coolbot::VirtualClock::new(),
            step: Duration::from_millis(10),
            after_step: None,
        }
    }
}

impl Default for VirtualTime {
    fn default() -> Self {
        VirtualTime::new()
    }
}

impl fmt::Debug for VirtualTime {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("VirtualTime")
            .field("clock", &self.clock)
            .field("step", &self.step)
            .field("after_step", &self.after_step.is_some())
            .finish()
    }
}

impl Default for Options {
    fn default() -> Self {
        Options {
            duration: Duration::from_secs(10),
            fault_after: None,
            outage: Duration::from_millis(1500),
            fault_kind: FaultKind::Raise,
            noise: None,
            seed: 1,
            goal: None,
            max_speed: None,
            scan_rate: None,
            display: Display::Auto,
            stop: Arc::new(AtomicBool::new(false)),
            record: None,
            record_format: coolbot::record::RecordFormat::Coolbot,
            #[cfg(feature = "ros2")]
            ros2: None,
            load: None,
            node: None,
            drivers: None,
            virtual_time: None,
        }
    }
}

/// One adaptation step (paper 3.6), as a compound's monitoring port published it: a
/// level its supervisor gave one of its instances, or a step of its own (the cap
/// raised, the floor lowered, a violation notified to the compound above).
#[derive(Clone, Debug, PartialEq)]
pub struct AdaptationStep {
    /// When the run saw it (since the start).
    pub at: Duration,
    /// The compound whose supervisor took it (`robot` or `base`).
    pub compound: String,
    /// The step.
    pub step: Adaptation,
}

impl fmt::Display for AdaptationStep {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let step = &self.step;
        write!(
            f,
            "{:6.2}s {}: {} {} {} -> {}",
            self.at.as_secs_f64(),
            self.compound,
            step.component,
            action(step.action),
            step.from,
            step.to
        )?;
        if !step.detail.is_empty() {
            write!(f, " ({})", step.detail)?;
        }
        Ok(())
    }
}

/// An adaptation action in words.
pub fn action(action: AdaptAction) -> &'static str {
    match action {
        AdaptAction::Degraded => "degraded",
        AdaptAction::Promoted => "promoted",
        AdaptAction::CapRaised => "raised its cap",
        AdaptAction::FloorLowered => "lowered its floor",
        AdaptAction::NotifiedHigher => "notified higher",
        AdaptAction::ReportedSpare => "reported spare time",
        AdaptAction::Exhausted => "exhausted",
        AdaptAction::Suspended => "suspended",
        AdaptAction::Resumed => "resumed",
        AdaptAction::Equalized => "equalized",
        _ => "adapted",
    }
}

/// The levels an atomic component went through, from its own monitoring port.
#[derive(Clone, Debug, PartialEq)]
pub struct LevelPath {
    /// The instance (`motion`, `ranges`).
    pub name: String,
    /// Its levels in order, nominal (0) first.
    pub levels: Vec<u32>,
    /// Its period at the end.
    pub period: Option<Duration>,
    /// Its quality at the end, by name (`None`: it declares no quality levels).
    pub quality: Option<String>,
}

impl LevelPath {
    /// The path of the component whose monitor is `monitor` (its own adaptation
    /// history: the last [`coolbot::adapt::ADAPTATION_HISTORY`] steps).
    fn of(monitor: &Monitor, qualities: &[&str]) -> LevelPath {
        let own: Vec<&Adaptation> = monitor
            .adaptation
            .history
            .iter()
            .filter(|s| matches!(s.action, AdaptAction::Degraded | AdaptAction::Promoted))
            .collect();
        let mut levels = vec![own.first().map_or(monitor.adaptation.level, |s| s.from)];
        levels.extend(own.iter().map(|s| s.to));
        LevelPath {
            name: monitor.name.clone(),
            levels,
            period: monitor.period,
            quality: (!qualities.is_empty()).then(|| status::quality(monitor.quality, qualities)),
        }
    }

    /// The highest level reached.
    pub fn highest(&self) -> u32 {
        self.levels.iter().copied().max().unwrap_or(0)
    }

    /// The level at the end.
    pub fn last(&self) -> u32 {
        self.levels.last().copied().unwrap_or(0)
    }
}

impl fmt::Display for LevelPath {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let levels: Vec<String> = self.levels.iter().map(u32::to_string).collect();
        write!(
            f,
            "{} {} (at the end: period {}",
            self.name,
            levels.join(" -> "),
            status::period(self.period),
        )?;
        if let Some(quality) = &self.quality {
            write!(f, ", quality {quality}")?;
        }
        f.write_str(")")
    }
}

/// One supervision step, as a compound's monitoring port published it.
#[derive(Clone, Debug, PartialEq)]
pub struct SupervisionStep {
    /// When the run saw it (since the start).
    pub at: Duration,
    /// The compound whose supervisor took it (`robot` or `base`).
    pub compound: String,
    /// The step.
    pub step: Supervision,
}

impl fmt::Display for SupervisionStep {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{:6.2}s {}: {}",
            self.at.as_secs_f64(),
            self.compound,
            self.step
        )
    }
}

/// What happened in a run, as the monitoring ports told it (and the simulated
/// platform's ground truth).
#[derive(Clone, Debug, PartialEq)]
pub struct Summary {
    /// How long it ran.
    pub elapsed: Duration,
    /// Whether it was stopped early (SIGINT or SIGTERM).
    pub interrupted: bool,
    /// Distance the robot really travelled (m, the platform's ground truth).
    pub distance: f64,
    /// Distance by the motion controller's odometry (m, its last published
    /// `distance`).
    pub odometry_distance: f64,
    /// The smallest distance between the robot's rim and an obstacle (m).
    pub min_clearance: f64,
    /// The same, ahead of the robot only (along the beams the emergency stop uses).
    pub min_front_clearance: f64,
    /// Moves refused because the robot touched an obstacle.
    pub contacts: u64,
    /// Emergencies raised by the range servers (real and simulated).
    pub emergencies: u64,
    /// Emergency stops the motion controller executed.
    pub halts: u64,
    /// Times the wanderer turned away from an obstacle.
    pub avoidances: u64,
    /// Goals the wanderer reached (with `goal`).
    pub goals_reached: u64,
    /// Scans published by `ranges` and by `sim_ranges`.
    pub scans: (u64, u64),
    /// Every supervision step the compounds published, in order.
    pub supervision: Vec<SupervisionStep>,
    /// The base supervisor's states, in the order its monitoring port reported them.
    pub user_states: Vec<String>,
    /// The robot supervisor's states (`autonomous`, `teleoperated`), in the order its
    /// monitoring port reported them.
    pub drive_states: Vec<String>,
    /// Outside commands the robot's `teleop` took and refused (not finite).
    pub teleop: (u64, u64),
    /// With ROS 2 (`--ros2`): what went through each topic.
    pub topics: Vec<TopicCount>,
    /// The base supervisor's last state.
    pub supervisor: String,
    /// The base's own `mode` at the end.
    pub mode: String,
    /// The base's own `faults` at the end (faults its supervisor handled).
    pub base_faults: u64,
    /// The range emergency distance the run used (m).
    pub emergency_distance: f64,
    /// Each component's state before shutdown, at every level: `(name, state)`.
    pub states_before_shutdown: Vec<(String, State)>,
    /// `robot`, `base` and `wanderer` after shutdown.
    pub final_states: Vec<(String, State)>,
    /// Whether every component, at every level, released the simulated platform
    /// after shutdown (its code was dropped: its thread ended).
    pub released: bool,
    /// Every thread joined, every component dead, no runtime panic.
    pub clean_shutdown: bool,
    /// With `record`: what the recording holds (per port, packets sent, recorded and
    /// lost).
    pub recorded: Option<coolbot::record::Summary>,
    /// The simulated processor shortage of the run, if any.
    pub load: Option<Overload>,
    /// Every adaptation step the compounds published, in order.
    pub adaptation: Vec<AdaptationStep>,
    /// The adaptation levels `motion`, `ranges` and `mapper` went through.
    pub levels: Vec<LevelPath>,
    /// The mapper's response times (an aperiodic component: a scan's arrival to the
    /// end of its handling) and its `max_response`, from its monitoring port.
    pub responses: Option<(coolbot::ResponseTimes, Option<Duration>)>,
    /// With `node`: the node's name and how many components it exposed.
    pub node: Option<(String, usize)>,
    /// With `drivers`: what became of the drivers processes.
    pub drivers: Option<DriversReport>,
}

/// What went through one ROS 2 topic of the run.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TopicCount {
    /// The fully qualified topic (`/scan`).
    pub topic: String,
    /// Its message type (`sensor_msgs/msg/LaserScan`).
    pub type_name: String,
    /// Published (else subscribed).
    pub outgoing: bool,
    /// Messages published, or received and delivered.
    pub messages: u64,
    /// Packets not published, or messages received that did not decode.
    pub lost: u64,
}

impl Summary {
    /// How many of the supervision steps are of the kind `step` accepts.
    pub fn count(&self, step: fn(&Step) -> bool) -> usize {
        self.supervision
            .iter()
            .filter(|s| step(&s.step.step))
            .count()
    }

    /// Member faults the supervisors saw.
    pub fn faults(&self) -> usize {
        self.count(|s| matches!(s, Step::Failed))
    }

    /// Substitutions made.
    pub fn substitutions(&self) -> usize {
        self.count(|s| matches!(s, Step::Substituted { .. }))
    }

    /// Instances recovered from the recovery queue.
    pub fn recoveries(&self) -> usize {
        self.count(|s| matches!(s, Step::Recovered))
    }

    /// Instances retired at their recovery deadline.
    pub fn retired(&self) -> usize {
        self.count(|s| matches!(s, Step::Retired))
    }

    /// The adaptation levels of instance `name` of the base, if it adapts.
    pub fn levels_of(&self, name: &str) -> Option<&LevelPath> {
        self.levels.iter().find(|l| l.name == name)
    }
}

impl fmt::Display for Summary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "summary after {:.1} s{}:",
            self.elapsed.as_secs_f64(),
            if self.interrupted {
                " (interrupted)"
            } else {
                ""
            }
        )?;
        writeln!(
            f,
            "  distance travelled   {:.2} m (odometry {:.2} m)",
            self.distance, self.odometry_distance
        )?;
        writeln!(
            f,
            "  nearest approach     {:.3} m from an obstacle, {:.3} m ahead; contacts {}",
            self.min_clearance, self.min_front_clearance, self.contacts
        )?;
        writeln!(
            f,
            "  emergencies          {} raised, {} emergency stops; {} avoidance turns",
            self.emergencies, self.halts, self.avoidances
        )?;
        if self.goals_reached > 0 {
            writeln!(f, "  goals reached        {}", self.goals_reached)?;
        }
        writeln!(
            f,
            "  scans                ranges {}, sim_ranges {}",
            self.scans.0, self.scans.1
        )?;
        writeln!(
            f,
            "  faults               {} (substitutions {}, recoveries {}, retired {})",
            self.faults(),
            self.substitutions(),
            self.recoveries(),
            self.retired()
        )?;
        if self.supervision.is_empty() {
            writeln!(f, "  supervision steps    none")?;
        } else {
            writeln!(f, "  supervision steps")?;
            for step in &self.supervision {
                writeln!(f, "    {step}")?;
            }
        }
        if let Some(load) = self.load {
            writeln!(
                f,
                "  simulated load       the processor is short from {:.1} s to {:.1} s ({} ms a beam for the range server)",
                load.from.as_secs_f64(),
                load.until.as_secs_f64(),
                world::OVERLOAD_COST_PER_BEAM.as_millis()
            )?;
        }
        if self.adaptation.is_empty() {
            writeln!(f, "  adaptation steps     none")?;
        } else {
            writeln!(f, "  adaptation steps")?;
            for step in &self.adaptation {
                writeln!(f, "    {step}")?;
            }
        }
        for (i, path) in self.levels.iter().enumerate() {
            let label = if i == 0 { "adaptation levels" } else { "" };
            writeln!(f, "  {label:<20} {path}")?;
        }
        if let Some((times, bound)) = &self.responses {
            let ms = |d: Duration| d.as_secs_f64() * 1e3;
            writeln!(
                f,
                "  response times       mapper p50 {:.1} ms, p99 {:.1} ms, worst {:.1} ms; {} late of {}{}",
                ms(times.p50),
                ms(times.p99),
                ms(times.worst),
                times.late,
                times.count,
                bound.map_or(String::new(), |b| format!(
                    " (max_response {:.0} ms)",
                    ms(b)
                ))
            )?;
        }
        writeln!(
            f,
            "  base supervisor      {} (mode {}, faults {}); states {}",
            self.supervisor,
            self.mode,
            self.base_faults,
            self.user_states.join(" -> ")
        )?;
        writeln!(
            f,
            "  robot supervisor     {}; outside commands {} taken, {} refused",
            self.drive_states.join(" -> "),
            self.teleop.0,
            self.teleop.1
        )?;
        for (i, count) in self.topics.iter().enumerate() {
            let label = if i == 0 { "ROS 2 topics" } else { "" };
            writeln!(
                f,
                "  {label:<20} {} {} {} ({}), {} lost",
                count.topic,
                if count.outgoing { "out" } else { "in" },
                count.messages,
                count.type_name,
                count.lost
            )?;
        }
        let before: Vec<String> = self
            .states_before_shutdown
            .iter()
            .map(|(n, s)| format!("{n}={s}"))
            .collect();
        writeln!(f, "  states at the end    {}", before.join(" "))?;
        let after: Vec<String> = self
            .final_states
            .iter()
            .map(|(n, s)| format!("{n}={s}"))
            .collect();
        writeln!(
            f,
            "  after shutdown       {}; every component released the platform: {}",
            after.join(" "),
            if self.released { "yes" } else { "NO" }
        )?;
        if let Some(recorded) = &self.recorded {
            let ports: Vec<String> = recorded
                .ports
                .iter()
                .map(|p| format!("{} {} recorded, {} lost", p.port, p.recorded, p.lost))
                .chain(recorded.monitors.iter().map(|m| {
                    format!(
                        "{} monitoring events {} recorded, {} lost",
                        m.component, m.events, m.lost
                    )
                }))
                .collect();
            writeln!(f, "  recorded             {}", ports.join("; "))?;
        }
        if let Some(drivers) = &self.drivers {
            let ended = if drivers.ended.is_empty() {
                "none ended while the robot ran".to_owned()
            } else {
                format!(
                    "{} ended while the robot ran ({})",
                    drivers.ended.len(),
                    drivers.ended.join(", ")
                )
            };
            writeln!(
                f,
                "  drivers process      started {} time{}, {ended}; at the end: {}",
                drivers.started,
                if drivers.started == 1 { "" } else { "s" },
                drivers.stopped.as_deref().unwrap_or("-")
            )?;
        }
        if let Some((name, count)) = &self.node {
            writeln!(
                f,
                "  network node         `{name}` exposed {count} components (`coolctl list {name}` while it ran)"
            )?;
        }
        write!(
            f,
            "  shutdown             {}",
            if self.clean_shutdown {
                "clean: every component dead, every thread joined"
            } else {
                "NOT clean"
            }
        )
    }
}

/// The ports `--record` taps: the motion controller's odometry and the base's
/// exported scans (from whichever range server stands in).
pub const RECORDED_PORTS: [&str; 2] = ["robot.base.motion.pose", "robot.base.scan"];

/// Starts recording the ROS 2 topics into a rosbag2 bag: `/scan` and `/odom` from the
/// relay (`crate::topics`), and `/cmd_vel` as it came in when `cmd_vel` names the
/// subscription's output.
fn start_bag(
    robot: &Robot,
    path: &std::path::Path,
    cmd_vel: Option<&str>,
) -> Result<coolbot::record::Recording, String> {
    use coolbot::record::{RecordFormat, Recorder};
    use generated::types::{LaserScan, Odometry, RosTwist};
    let system = robot.system();
    let mut recorder = Recorder::new()
        .format(RecordFormat::Ros2)
        .clock(system.clock().clone());
    recorder
        .tap_ros_on::<LaserScan>(system, topics::SCAN_PORT, topics::SCAN)
        .map_err(text)?;
    recorder
        .tap_ros_on::<Odometry>(system, topics::ODOM_PORT, topics::ODOM)
        .map_err(text)?;
    if let Some(port) = cmd_vel {
        recorder
            .tap_ros_on::<RosTwist>(system, port, topics::CMD_VEL)
            .map_err(text)?;
    }
    recorder.start(path).map_err(text)
}

/// Starts recording the odometry, the scans and the base's monitoring events.
fn start_recording(
    robot: &Robot,
    path: &std::path::Path,
) -> Result<coolbot::record::Recording, String> {
    use coolbot::record::Recorder;
    use generated::types::{Pose2D, RangeScan};
    let system = robot.system();
    let mut recorder = Recorder::new().clock(system.clock().clone());
    recorder
        .tap::<Pose2D>(system, RECORDED_PORTS[0])
        .map_err(text)?;
    recorder
        .tap::<RangeScan>(system, RECORDED_PORTS[1])
        .map_err(text)?;
    recorder.monitor(system, "robot.base").map_err(text)?;
    recorder.start(path).map_err(text)
}

/// An error with its sources, for the run's messages.
fn text(error: impl std::error::Error) -> String {
    coolbot::Chain(&error).to_string()
}

fn number(value: Option<&coolbot::Value>) -> f64 {
    match value {
        Some(coolbot::Value::Float(x)) => *x,
        Some(coolbot::Value::Int(x)) => *x as f64,
        Some(coolbot::Value::UInt(x)) => *x as f64,
        Some(coolbot::Value::Json(v)) => v.as_f64().unwrap_or(0.0),
        _ => 0.0,
    }
}

fn lookup<'a>(monitor: &'a Monitor, name: &str) -> Option<&'a coolbot::Value> {
    monitor
        .variables
        .iter()
        .find(|(n, _)| n == name)
        .map(|(_, v)| v)
}

fn variable(monitor: Option<&Monitor>, name: &str) -> f64 {
    number(monitor.and_then(|m| lookup(m, name)))
}

/// A variable shown as text (an enum's variant name).
fn word(monitor: &Monitor, name: &str) -> String {
    lookup(monitor, name).map_or_else(|| "-".to_owned(), status::value)
}

/// One row of the table: a component at some depth of the robot, read from its own
/// monitoring port.
struct Line {
    depth: usize,
    type_name: &'static str,
    handle: Handle,
    cpu: Duration,
}

/// The quality levels a component type declares in its timing block, by name (empty
/// without any), from the generated code.
fn qualities(type_name: &str) -> &'static [&'static str] {
    use generated::{mapper, motion_controller, range_server, sim_range_server, wanderer};
    let specs = [
        &mapper::SPEC,
        &motion_controller::SPEC,
        &range_server::SPEC,
        &sim_range_server::SPEC,
        &wanderer::SPEC,
    ];
    specs
        .iter()
        .find(|spec| spec.type_name == type_name)
        .map_or(&[], |spec| spec.timing.qualities)
}

/// The instances a compound type declares, `(name, type)`, from the generated code
/// (empty for an atomic type).
fn declared(type_name: &str) -> &'static [(&'static str, &'static str)] {
    use generated::{isolated_base, isolated_robot, mobile_base, robot};
    [
        (robot::TYPE_NAME, robot::INSTANCES),
        (mobile_base::TYPE_NAME, mobile_base::INSTANCES),
        (isolated_robot::TYPE_NAME, isolated_robot::INSTANCES),
        (isolated_base::TYPE_NAME, isolated_base::INSTANCES),
    ]
    .into_iter()
    .find(|(name, _)| *name == type_name)
    .map_or(&[], |(_, instances)| instances)
}

/// The table's rows below `handle` (a component of type `type_name` at `depth`):
/// itself, then its instances in declaration order, each with its own instances.
fn walk(handle: Handle, type_name: &'static str, depth: usize, lines: &mut Vec<Line>) {
    let instances = handle.instances();
    let children: Vec<Handle> = instances
        .iter()
        .filter_map(|name| handle.instance(name))
        .collect();
    lines.push(Line {
        depth,
        type_name,
        handle,
        cpu: Duration::ZERO,
    });
    for child in children {
        let child_type = declared(type_name)
            .iter()
            .find(|(name, _)| *name == child.name())
            .map_or("?", |(_, t)| *t);
        walk(child, child_type, depth + 1, lines);
    }
}

/// What the monitoring ports of the robot, the base and the wanderer publish, as it
/// happens: the log lines, every supervision and adaptation step, the base
/// supervisor's states.
struct Events {
    /// Each port's subscription, with how many of its dropped events were reported.
    receivers: Vec<(String, coolbot::Subscription, u64)>,
    supervision: Vec<SupervisionStep>,
    adaptation: Vec<AdaptationStep>,
    user_states: Vec<String>,
    drive_states: Vec<String>,
}

impl Events {
    fn new(handles: &[&Handle]) -> Events {
        let receivers = handles
            .iter()
            .map(|h| (h.name().to_owned(), h.subscribe_counted(), 0))
            .collect();
        // The state the base's supervisor is in now; changes follow as events.
        let user_states = handles
            .iter()
            .find(|h| h.name() == BASE)
            .and_then(|h| h.snapshot().user_state)
            .into_iter()
            .collect();
        let drive_states = handles
            .iter()
            .find(|h| h.name() == ROBOT)
            .and_then(|h| h.snapshot().user_state)
            .into_iter()
            .collect();
        Events {
            receivers,
            supervision: Vec::new(),
            adaptation: Vec::new(),
            user_states,
            drive_states,
        }
    }

    /// Takes what was published since the last call (`at`: the run's clock) and
    /// returns it as log lines.
    fn take(&mut self, at: Duration) -> Vec<String> {
        let time = at.as_secs_f64();
        let mut lines = Vec::new();
        for (name, receiver, reported) in &mut self.receivers {
            // Events dropped because this display fell behind: said, never hidden.
            let dropped = receiver.dropped();
            if dropped > *reported {
                let lost = dropped - *reported;
                lines.push(format!(
                    "{time:6.2}s {name}: {lost} monitoring events lost (the display fell behind)"
                ));
                *reported = dropped;
            }
            for event in receiver.try_iter() {
                match event {
                    MonitorEvent::State { from, to } => {
                        lines.push(format!("{time:6.2}s {name}: {from} -> {to}"));
                    }
                    MonitorEvent::Error(Some(error)) => {
                        lines.push(format!("{time:6.2}s {name}: error: {error}"));
                    }
                    MonitorEvent::UserState(Some(state))
                        if *name == BASE && self.user_states.last() != Some(&state) =>
                    {
                        lines.push(format!("{time:6.2}s {name}: supervisor -> {state}"));
                        self.user_states.push(state);
                    }
                    MonitorEvent::UserState(Some(state))
                        if *name == ROBOT && self.drive_states.last() != Some(&state) =>
                    {
                        lines.push(format!("{time:6.2}s {name}: supervisor -> {state}"));
                        self.drive_states.push(state);
                    }
                    MonitorEvent::Supervision(step) => {
                        let step = SupervisionStep {
                            at,
                            compound: name.clone(),
                            step,
                        };
                        lines.push(step.to_string());
                        self.supervision.push(step);
                    }
                    // The compounds' adaptation decisions (the wanderer does not adapt).
                    // A compound applying the level its own supervisor granted it is
                    // already listed as that supervisor's step.
                    MonitorEvent::Adaptation(step)
                        if name != WANDERER
                            && !(step.component == *name
                                && matches!(
                                    step.action,
                                    AdaptAction::Degraded | AdaptAction::Promoted
                                )) =>
                    {
                        let step = AdaptationStep {
                            at,
                            compound: name.clone(),
                            step,
                        };
                        lines.push(step.to_string());
                        self.adaptation.push(step);
                    }
                    _ => {}
                }
            }
        }
        lines
    }
}

/// The injected sensor fault of `options`, if any.
fn sensor_fault(options: &Options) -> Option<SensorFault> {
    options.fault_after.map(|after| SensorFault {
        after,
        outage: options.outage,
        kind: options.fault_kind,
    })
}

/// `--serve`: this process is the node `options.node` of the robot's network, and
/// runs what other nodes place on it (the wanderer on a station, the range server on
/// `drivers`), until `options.stop` is set, or until the process `parent` is no longer
/// this one's parent (`--parent`: a drivers process started by a robot ends with it).
/// A range server built here reads a sensor board of this process, with the fault,
/// shortage, noise, seed and scan rate of `options`. Returns the node's name.
pub fn serve(options: &Options, parent: Option<u32>) -> Result<String, String> {
    let Some(node) = &options.node else {
        return Err("`--serve` needs `--node`".to_owned());
    };
    let board = node::Board {
        platform: Arc::new(
            Platform::new(
                World::example(),
                World::example_start(),
                sensor_fault(options),
            )
            .with_overload(options.load),
        ),
        overrides: sensing::Overrides {
            noise: options.noise,
            seed: Some(options.seed),
            frequency: options.scan_rate,
        },
    };
    let network = node::open(node, &board)?;
    println!(
        "node `{}` on the network: serving what other nodes place on it",
        network.name()
    );
    let orphaned = || parent.is_some_and(|parent| std::os::unix::process::parent_id() != parent);
    while !options.stop.load(Ordering::Acquire) && !orphaned() {
        std::thread::sleep(Duration::from_millis(50));
    }
    if orphaned() {
        println!(
            "node `{}`: the process that started it is gone",
            network.name()
        );
    }
    Ok(network.name().to_owned())
}

/// The node the robot opens with `--drivers`: `options.node`, or `robot`; listening
/// on a loopback port of its own when no endpoint is given, so that the drivers
/// process can connect to it.
fn robot_node(options: &Options) -> Result<NodeOptions, String> {
    let mut node = options
        .node
        .clone()
        .unwrap_or_else(|| NodeOptions::named(ROBOT));
    if node.listen.is_empty() {
        let port = node::loopback_port();
        node.listen.push(format!("tcp/127.0.0.1:{port}"));
    }
    Ok(node)
}

/// Builds the robot, runs it for `options.duration` (or until `options.stop`), shuts
/// it down and reports.
pub fn run(options: &Options) -> Result<Summary, String> {
    let fault = sensor_fault(options);
    let virtual_time = options.virtual_time.as_ref();
    if virtual_time.is_some() && (options.node.is_some() || options.drivers.is_some()) {
        return Err(
            "a run on a virtual clock has no node and no drivers process: they keep real time"
                .to_owned(),
        );
    }
    let mut platform =
        Platform::new(World::example(), World::example_start(), fault).with_overload(options.load);
    if let Some(time) = virtual_time {
        platform = platform.with_clock(coolbot::Clock::virtual_clock(&time.clock));
    }
    let platform = Arc::new(platform);
    let setup = Setup {
        noise: options.noise,
        seed: options.seed,
        goal: options.goal,
        max_speed: options.max_speed,
        scan_rate: options.scan_rate,
        ranges: if options.drivers.is_some() {
            Ranges::Drivers
        } else {
            Ranges::Here
        },
    };
    // On the network only when asked: nothing of Zenoh runs otherwise. The node is
    // opened first: its placer puts the wanderer (`on "station"`) on its node, or the
    // range server (`on "drivers"`, `--drivers`) on the drivers process, which is
    // started next and serves before the robot is built.
    if cfg!(not(feature = "network")) && options.drivers.is_some() {
        return Err("`--drivers`: this build has no network support; build the example with \
             `--features network` (cargo run --release -p mobile-base --features network -- --drivers)"
            .to_owned());
    }
    let node_options = match &options.drivers {
        Some(_) => Some(robot_node(options)?),
        None => options.node.clone(),
    };
    let network = match &node_options {
        Some(node) => Some(node::open(node, &node::Board::example())?),
        None => None,
    };
    let (drivers_lines, drivers_said) = std::sync::mpsc::channel();
    let keeper = match (&options.drivers, &node_options) {
        (Some(drivers), Some(node)) => {
            let settings = drivers::Settings {
                connect: node.listen.clone(),
                lease: node.lease,
                noise: options.noise,
                seed: options.seed,
                scan_rate: options.scan_rate,
                fault,
                load: options.load,
            };
            let clock = Arc::clone(&platform);
            Some(
                drivers::Keeper::start(drivers, settings, move || clock.uptime(), drivers_lines)
                    .map_err(text)?,
            )
        }
        _ => None,
    };
    let mut robot = Robot::ready(&platform, &setup)?;
    // A panic the runtime catches in one of the robot's components prints one line
    // (under `coolbot::process`'s panic hook, when the program installed it).
    coolbot::process::watch_system(robot.system());
    let bag =
        options.record.is_some() && options.record_format == coolbot::record::RecordFormat::Ros2;
    #[cfg(feature = "ros2")]
    let speaks_ros = bag || options.ros2.is_some();
    #[cfg(not(feature = "ros2"))]
    let speaks_ros = bag;
    if speaks_ros && let Err(error) = topics::add_relay(robot.system_mut()) {
        let _ = robot.shutdown();
        return Err(error);
    }
    #[cfg(feature = "ros2")]
    let ros_node = match &options.ros2 {
        Some(setup) => match ros::join(robot.system_mut(), setup) {
            Ok(node) => Some(node),
            Err(error) => {
                let _ = robot.shutdown();
                return Err(error);
            }
        },
        None => None,
    };
    #[cfg(feature = "ros2")]
    let cmd_vel = ros_node.as_ref().map(ros::RosNode::cmd_vel_port);
    #[cfg(not(feature = "ros2"))]
    let cmd_vel: Option<String> = None;
    // Recording from before the robot runs: its first packets are in the file.
    let recording = match &options.record {
        Some(path) if bag => start_bag(&robot, path, cmd_vel.as_deref()).map(Some),
        Some(path) => start_recording(&robot, path).map(Some),
        None => Ok(None),
    };
    let recording = match recording.and_then(|recording| robot.run().map(|()| recording)) {
        Ok(recording) => recording,
        Err(error) => {
            let _ = robot.shutdown();
            return Err(error);
        }
    };
    let node = match network {
        Some(network) => match network.expose(&robot) {
            Ok(()) => Some(network),
            Err(error) => {
                let _ = robot.shutdown();
                return Err(error);
            }
        },
        None => None,
    };
    // Every change on the monitoring ports of the robot, the base and the wanderer.
    let mut events = Events::new(&[&robot.robot, &robot.base, &robot.wanderer]);

    // Every component at every level, each read from its own monitoring port.
    let mut lines = Vec::new();
    walk(robot.robot.clone(), robot.type_name(), 0, &mut lines);

    let display = match options.display {
        Display::Auto if std::io::stdout().is_terminal() => Display::Table,
        Display::Auto => Display::Lines,
        other => other,
    };
    let mut log: Vec<String> = Vec::new();
    let mut last_frame = Instant::now();
    let mut last_line = Duration::ZERO;
    // The run's clock is the platform's: injected faults and events agree.
    let started = platform.uptime();
    let stdout = std::io::stdout();
    let mut screen = None;
    if display == Display::Table {
        screen = Some(status::Screen::open().map_err(|e| format!("the terminal: {e}"))?);
        // Log lines and caught panics go into the table's event pane, not over it.
        coolbot::process::capture_output(true);
    }

    let interrupted = loop {
        let now = platform.uptime();
        let at = now.saturating_sub(started);
        if options.stop.load(Ordering::Relaxed) {
            break true;
        }
        if at >= options.duration {
            break false;
        }
        // What the monitoring ports reported since the last turn.
        let mut fresh = events.take(at);
        fresh.extend(
            drivers_said
                .try_iter()
                .map(|line| format!("{:6.2}s {line}", at.as_secs_f64())),
        );
        fresh.extend(coolbot::process::take_output());
        if display == Display::Lines {
            let mut out = stdout.lock();
            for line in &fresh {
                let _ = writeln!(out, "{line}");
            }
        }
        log.extend(fresh);
        let keep = log.len().saturating_sub(200);
        log.drain(..keep);

        let frame_due = last_frame.elapsed() >= Duration::from_millis(250);
        let line_due = at >= last_line + Duration::from_secs(1);
        if (display == Display::Table && frame_due) || (display == Display::Lines && line_due) {
            let wall = last_frame.elapsed().as_secs_f64().max(1e-3);
            last_frame = Instant::now();
            let rows: Vec<status::Row> = lines
                .iter_mut()
                .map(|line| {
                    let monitor = line.handle.snapshot();
                    let load = monitor.cpu_time.saturating_sub(line.cpu).as_secs_f64() / wall;
                    line.cpu = monitor.cpu_time;
                    status::Row {
                        depth: line.depth,
                        type_name: line.type_name,
                        qualities: qualities(line.type_name),
                        monitor,
                        load,
                    }
                })
                .collect();
            let base = robot.base.snapshot();
            let supervisor = base.user_state.as_deref().unwrap_or("-");
            let truth = platform.truth();
            if let Some(screen) = &mut screen {
                let header = format!(
                    "CoolBOT mobile base   t={:5.1}s/{:.0}s   base supervisor: {} (mode {})   pose ({:.2}, {:.2}, {:.0} deg)   distance {:.2} m   contacts {}{}",
                    at.as_secs_f64(),
                    options.duration.as_secs_f64(),
                    supervisor,
                    word(&base, "mode"),
                    truth.pose.x,
                    truth.pose.y,
                    truth.pose.theta.to_degrees(),
                    truth.distance,
                    truth.contacts,
                    load_note(&platform),
                );
                if let Err(error) = screen.draw(&header, &rows, &log) {
                    log.push(format!("the table cannot be drawn: {error}"));
                }
            } else {
                let mut out = stdout.lock();
                last_line = at;
                let extra = format!(
                    "mode={} distance={:.2}m{}",
                    word(&base, "mode"),
                    truth.distance,
                    load_note(&platform)
                );
                let _ = writeln!(out, "{}", status::line(at, &rows, &extra));
                let _ = out.flush();
            }
        }
        match virtual_time {
            None => std::thread::sleep(Duration::from_millis(20)),
            // The run's own turn moves the time (and waits for the robot to settle).
            Some(time) => {
                if let Err(error) = platform.advance(time.step) {
                    let _ = robot.shutdown();
                    return Err(format!("the robot on its virtual clock: {error}"));
                }
                if let Some(after_step) = &time.after_step {
                    after_step(platform.uptime().saturating_sub(started));
                }
            }
        }
    };

    if display == Display::Table {
        // The shell's screen back, then what is left and what the shutdown logs on
        // stderr again.
        drop(screen);
        coolbot::process::capture_output(false);
    }
    // Before shutdown: every level's monitoring port, in the table's order.
    let elapsed = platform.uptime().saturating_sub(started);
    let base = robot.base.snapshot();
    let wanderer = robot.wanderer.snapshot();
    let states_before_shutdown: Vec<(String, State)> = lines
        .iter()
        .map(|line| (line.handle.name().to_owned(), line.handle.state()))
        .collect();
    // The supervision steps and states published up to the end.
    events.take(elapsed);

    let recorded = match recording {
        Some(recording) => Some(recording.finish().map_err(text)?),
        None => None,
    };
    #[cfg(feature = "ros2")]
    let topics = ros_node
        .as_ref()
        .map(ros::RosNode::counts)
        .unwrap_or_default();
    #[cfg(not(feature = "ros2"))]
    let topics = Vec::new();
    let handles = [
        robot.robot.clone(),
        robot.base.clone(),
        robot.wanderer.clone(),
    ];
    let exposed = node
        .as_ref()
        .map(|node| (node.name().to_owned(), lines.len()));
    coolbot::process::forget_system(robot.system());
    let report = robot.shutdown();
    // The node leaves after the robot: the proxies of its remote instances have sent
    // them to `dead`. Then the drivers process ends.
    drop(node);
    let drivers = keeper.map(drivers::Keeper::stop);
    // The ROS 2 node leaves once its publishers and subscription are dead.
    #[cfg(feature = "ros2")]
    if let Some(node) = ros_node {
        node.close();
    }
    // The variables as the components left them, each from its own monitoring port:
    // read after the last section ran, so that they agree with the platform's ground
    // truth.
    let monitor = |path: &str| handles[0].instance(path).as_ref().map(Handle::snapshot);
    let motion = monitor(&format!("{BASE}.{MOTION}"));
    let ranges = monitor(&format!("{BASE}.{RANGES}"));
    let sim_ranges = monitor(&format!("{BASE}.{SIM_RANGES}"));
    let mapper = monitor(MAPPER);
    let teleop = monitor(robot::TELEOP);
    let final_states: Vec<(String, State)> = handles
        .iter()
        .map(|h| (h.name().to_owned(), h.state()))
        .collect();
    // Our `platform` is the last reference when every behaviour, at every level, was
    // dropped: their threads ended.
    let released = Arc::strong_count(&platform) == 1;
    let clean_shutdown = report.clean()
        && report
            .components
            .iter()
            .all(|c| c.joined && c.state == State::Dead)
        && final_states.iter().all(|(_, s)| *s == State::Dead)
        && released;
    let levels: Vec<LevelPath> = [(&motion, MOTION), (&ranges, RANGES), (&mapper, MAPPER)]
        .into_iter()
        .filter_map(|(monitor, name)| {
            let monitor = monitor.as_ref()?;
            let type_name = generated::mobile_base::INSTANCES
                .iter()
                .chain(generated::robot::INSTANCES)
                .find(|(n, _)| *n == name)
                .map_or("?", |(_, t)| *t);
            monitor
                .adaptation
                .enabled
                .then(|| LevelPath::of(monitor, qualities(type_name)))
        })
        .collect();
    let truth = platform.truth();
    let emergencies =
        variable(ranges.as_ref(), "emergencies") + variable(sim_ranges.as_ref(), "emergencies");
    Ok(Summary {
        elapsed,
        interrupted,
        distance: truth.distance,
        odometry_distance: variable(motion.as_ref(), "distance"),
        min_clearance: truth.min_clearance,
        min_front_clearance: truth.min_front_clearance,
        contacts: truth.contacts,
        emergencies: emergencies as u64,
        halts: variable(motion.as_ref(), "halts") as u64,
        avoidances: variable(Some(&wanderer), "avoidances") as u64,
        goals_reached: variable(Some(&wanderer), "goals_reached") as u64,
        scans: (
            variable(ranges.as_ref(), "scans") as u64,
            variable(sim_ranges.as_ref(), "scans") as u64,
        ),
        supervision: events.supervision,
        user_states: events.user_states,
        drive_states: events.drive_states,
        teleop: (
            variable(teleop.as_ref(), "received") as u64,
            variable(teleop.as_ref(), "refused") as u64,
        ),
        topics,
        supervisor: base.user_state.clone().unwrap_or_else(|| "-".to_owned()),
        mode: word(&base, "mode"),
        base_faults: variable(Some(&base), "faults") as u64,
        emergency_distance: variable(ranges.as_ref(), "emergency_distance"),
        states_before_shutdown,
        final_states,
        released,
        clean_shutdown,
        recorded,
        load: options.load,
        adaptation: events.adaptation,
        levels,
        responses: mapper.as_ref().map(|m| (m.response, m.max_response)),
        node: exposed,
        drivers,
    })
}

/// `   overloaded` while the simulated processor shortage lasts (the table's header).
fn load_note(platform: &Platform) -> &'static str {
    if platform.overloaded() {
        "   PROCESSOR SHORT (--load)"
    } else {
        ""
    }
}
