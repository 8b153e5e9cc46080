//! The `Robot` and `MobileBase` compounds of `examples/components/mobile_base.cool`,
//! assembled on a `coolbot::System`, and the mobile base's supervisor.
//!
//! **Partly hand-written for now.** coolc's compound code generation is partial. For
//! `MobileBase` it generates `mobile_base::build`, which adds the atomic instances
//! `motion` and `ranges` with their configuration overrides (behaviours from our
//! [`mobile_base::Parts`]) and makes the compound's connections; [`wire_robot`] uses
//! it. Not generated yet, so done here by hand and mirroring the description: the
//! substitute `sim_ranges` (generated code only lists it in `SUBSTITUTES`), the
//! instance timing overrides, the nested compound `Robot` (its instance `base` is a
//! compound, so `robot::build` cannot wire it: [`wire_robot`] resolves its generated
//! `robot::CONNECTIONS` through `MobileBase`'s exported ports), and the supervisor
//! with its error policies and recovery queue ([`MobileBaseSupervisor`], rule for
//! rule as the description says). These go away when coolc generates compounds in
//! full.

use std::sync::Arc;
use std::time::{Duration, Instant};

use coolbot::{Command, Controllable, Monitor, State, System, TaskResult, Value};

use crate::generated::types::BaseMode;
use crate::generated::{
    mobile_base, motion_controller, range_server, robot, sim_range_server, wanderer,
};
use crate::motion_controller::MotionController;
use crate::range_server::RangeServer;
use crate::sim_range_server::SimRangeServer;
use crate::wanderer::Wanderer;
use crate::world::Platform;

/// Instance `motion` of `MobileBase`.
pub const MOTION: &str = "motion";
/// Instance `ranges` of `MobileBase`.
pub const RANGES: &str = "ranges";
/// Instance `sim_ranges` of `MobileBase` (`substitutes ranges`).
pub const SIM_RANGES: &str = "sim_ranges";
/// Instance `wanderer` of `Robot`.
pub const WANDERER: &str = "wanderer";
/// Instance `base` of `Robot`: the `MobileBase` compound (flattened into its members).
pub const BASE: &str = "base";

/// `MobileBase`'s exported ports, as its description maps them to member ports:
/// `input command = motion.command; output scan = ranges.scan; output pose = motion.pose;`.
pub const BASE_EXPORTS: &[(&str, &str)] = &[
    ("command", "motion.command"),
    ("scan", "ranges.scan"),
    ("pose", "motion.pose"),
];

/// The range server's configuration for a run: the description's override
/// (`noise = 0.005`) replaced by the run's noise, and the run's seed.
fn ranges_overrides(noise: f64, seed: u64) -> Value {
    Value::Json(serde_json::json!({ "noise": noise, "seed": seed }))
}

/// Resolves an address of the `Robot` compound (`base.scan`, `wanderer.command`) to
/// the member port that implements it.
fn resolve(address: &str) -> String {
    match address.split_once('.') {
        Some((BASE, port)) => BASE_EXPORTS
            .iter()
            .find(|(exported, _)| *exported == port)
            .map_or_else(|| address.to_owned(), |(_, member)| (*member).to_owned()),
        _ => address.to_owned(),
    }
}

/// How the robot is put together beyond the descriptions' defaults.
#[derive(Clone, Debug)]
pub struct Setup {
    /// Range noise of the real sensors (m, standard deviation).
    pub noise: f64,
    /// Seed of the range noise and the wanderer's random turns.
    pub seed: u64,
    /// A goal to seek, if any.
    pub goal: Option<(f64, f64)>,
    /// The motion controller's controllable `max_speed` (m/s), if not the default.
    pub max_speed: Option<f64>,
    /// The range servers' controllable `frequency` (Hz), if not the default.
    pub scan_rate: Option<f64>,
}

/// The behaviours of `MobileBase`'s atomic instances, for the generated
/// `mobile_base::build`.
struct BaseParts<'a> {
    platform: &'a Arc<Platform>,
}

impl mobile_base::Parts for BaseParts<'_> {
    fn motion(&mut self) -> impl motion_controller::Behavior {
        MotionController::new(Arc::clone(self.platform))
    }

    fn ranges(&mut self) -> impl range_server::Behavior {
        RangeServer::new(Arc::clone(self.platform))
    }
}

/// Builds the robot on a new system and starts it: `MobileBase`'s instances and
/// connections with the generated `mobile_base::build`, its substitute `sim_ranges`
/// (left `ready`, a standby), `Robot`'s `wanderer`, and `Robot`'s connections from the
/// generated `robot::CONNECTIONS` with `base.*` resolved through [`BASE_EXPORTS`].
pub fn wire_robot(platform: &Arc<Platform>, setup: &Setup) -> Result<System, String> {
    let mut system = System::new();
    mobile_base::build(&mut system, "", &mut BaseParts { platform }).map_err(|e| e.to_string())?;
    // `instance sim_ranges: SimRangeServer substitutes ranges;`
    system
        .add(sim_range_server::component(
            SIM_RANGES,
            SimRangeServer::new(Arc::clone(platform)),
        ))
        .map_err(|e| e.to_string())?;
    // `compound Robot { instance base: MobileBase; instance wanderer: Wanderer; ... }`
    system
        .add(wanderer::component(WANDERER, Wanderer::default()))
        .map_err(|e| e.to_string())?;
    for (from, to) in robot::CONNECTIONS {
        system
            .connect(&resolve(from), &resolve(to))
            .map_err(|e| e.to_string())?;
    }

    system.start().map_err(|e| e.to_string())?;
    for name in [MOTION, RANGES, SIM_RANGES, WANDERER] {
        let handle = system
            .handle(name)
            .ok_or_else(|| format!("no component {name}"))?;
        handle
            .wait_for(|m| m.state != State::Starting, Duration::from_secs(5))
            .map_err(|e| e.to_string())?;
    }
    let command = |name: &str, command: Command| -> Result<(), String> {
        let handle = system
            .handle(name)
            .ok_or_else(|| format!("no component {name}"))?;
        handle.command(command).map_err(|e| e.to_string())
    };
    // Not generated yet: `motion`'s timing override `timing { priority 7; period
    // 20ms..40ms; }`, through the control port.
    command(MOTION, Command::SetPriority(7))?;
    command(MOTION, Command::SetPeriod(Duration::from_millis(20)))?;
    // The run's noise and seed (the description's `noise = 0.005` is the default).
    command(
        RANGES,
        Command::Configure(ranges_overrides(setup.noise, setup.seed)),
    )?;
    let mut wanderer_config = serde_json::json!({ "seed": setup.seed });
    if let Some((x, y)) = setup.goal {
        wanderer_config["goal_x"] = x.into();
        wanderer_config["goal_y"] = y.into();
    }
    command(WANDERER, Command::Configure(Value::Json(wanderer_config)))?;
    if setup.goal.is_some() {
        command(WANDERER, Command::Set("seek".to_owned(), Value::Bool(true)))?;
    }
    // Controllable variables, through the control port.
    if let Some(speed) = setup.max_speed {
        command(
            MOTION,
            Command::Set("max_speed".to_owned(), Value::Float(speed)),
        )?;
    }
    if let Some(rate) = setup.scan_rate {
        for name in [RANGES, SIM_RANGES] {
            command(
                name,
                Command::Set("frequency".to_owned(), Value::Float(rate)),
            )?;
        }
    }
    // The substitute stays `ready` (a warm standby) until the supervisor needs it.
    for name in [MOTION, RANGES, WANDERER] {
        command(name, Command::SetState(Controllable::Running))?;
    }
    Ok(system)
}

/// The supervisor's states (`supervisor { ... }` in `mobile_base.cool`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SupervisorState {
    /// Every member is running.
    Operating,
    /// The simulated range server stands in for the failed one.
    Degraded,
    /// The base cannot go on.
    Stopped,
}

impl SupervisorState {
    /// The state's name in the description.
    pub fn name(self) -> &'static str {
        match self {
            SupervisorState::Operating => "operating",
            SupervisorState::Degraded => "degraded",
            SupervisorState::Stopped => "stopped",
        }
    }
}

/// An instance waiting in the recovery queue.
#[derive(Clone, Debug)]
struct Recovering {
    instance: &'static str,
    since: Instant,
    next_try: Instant,
}

/// `MobileBase`'s supervisor, error policies and recovery queue, as described:
///
/// ```text
/// on error motion: propagate;
/// on error ranges: substitute;            // by sim_ranges
/// recovery { retry every 500ms; deadline 5s; }
/// supervisor { operating / degraded / stopped, with the `when` rules }
/// ```
#[derive(Debug)]
pub struct MobileBaseSupervisor {
    state: SupervisorState,
    /// The compound's observable `mode`.
    pub mode: BaseMode,
    /// The compound's local `faults`.
    pub faults: u32,
    retry_every: Duration,
    deadline: Duration,
    recovering: Option<Recovering>,
    substituted: bool,
    /// Substitutions made.
    pub substitutions: u32,
    /// Instances recovered from the queue (the substitution undone).
    pub recoveries: u32,
    /// Instances retired from the queue at their deadline.
    pub retired: u32,
    /// The base's own error, when a member's error was propagated.
    pub error: Option<String>,
    log: Vec<String>,
}

impl Default for MobileBaseSupervisor {
    fn default() -> Self {
        MobileBaseSupervisor {
            state: SupervisorState::Operating,
            mode: BaseMode::Normal,
            faults: 0,
            retry_every: Duration::from_millis(500),
            deadline: Duration::from_secs(5),
            recovering: None,
            substituted: false,
            substitutions: 0,
            recoveries: 0,
            retired: 0,
            error: None,
            log: Vec::new(),
        }
    }
}

/// Moves every connection of `from`'s ports to the same ports of `to` (an equivalent
/// interface): disconnect first, so 1-producer inputs accept the new producer.
fn reroute(system: &mut System, from: &str, to: &str) -> Result<usize, String> {
    let prefix = format!("{from}.");
    let moved: Vec<(String, String)> = system
        .connections()
        .into_iter()
        .filter(|(out, input)| out.starts_with(&prefix) || input.starts_with(&prefix))
        .collect();
    let swap = |address: &str| match address.strip_prefix(&prefix) {
        Some(port) => format!("{to}.{port}"),
        None => address.to_owned(),
    };
    for (out, input) in &moved {
        system.disconnect(out, input).map_err(|e| e.to_string())?;
        system
            .connect(&swap(out), &swap(input))
            .map_err(|e| e.to_string())?;
    }
    Ok(moved.len())
}

impl MobileBaseSupervisor {
    /// The supervisor's current state.
    pub fn state(&self) -> SupervisorState {
        self.state
    }

    /// Whether `sim_ranges` currently stands in for `ranges`.
    pub fn substituted(&self) -> bool {
        self.substituted
    }

    /// What the compound's own monitoring port would publish: its default automaton
    /// state (`running`, or `running_error` once a member's error propagated), the
    /// supervisor's state as its user state, and its variables: the mapped
    /// `odometry = motion.odometry` and `max_speed = motion.max_speed`, and its own
    /// `mode` (its local `faults` is not observable). Built from `motion`'s snapshot,
    /// whose timing fields the compound does not have (they are zeroed).
    pub fn monitor(&self, motion: &Monitor) -> Monitor {
        let mapped = |name: &str| {
            motion
                .variables
                .iter()
                .find(|(n, _)| n == name)
                .map_or(Value::Unit, |(_, v)| v.clone())
        };
        let mut monitor = motion.clone();
        monitor.name = BASE.to_owned();
        monitor.state = if self.error.is_some() {
            State::RunningError
        } else {
            State::Running
        };
        monitor.user_state = Some(self.state.name().to_owned());
        monitor.error = self.error.clone();
        monitor.result = TaskResult::None;
        monitor.variables = vec![
            ("odometry".to_owned(), mapped("odometry")),
            ("max_speed".to_owned(), mapped("max_speed")),
            ("mode".to_owned(), Value::Enum(format!("{:?}", self.mode))),
        ];
        monitor.cpu_time = Duration::ZERO;
        monitor.elapsed_time = Duration::ZERO;
        monitor.missed_deadlines = 0;
        monitor.overruns = 0;
        monitor.overflows = 0;
        monitor.port_overflows = Vec::new();
        // The supervisor is evaluated every turn of the run loop.
        monitor.period = Some(Duration::from_millis(20));
        monitor
    }

    /// Takes the log lines written since the last call.
    pub fn take_log(&mut self) -> Vec<String> {
        std::mem::take(&mut self.log)
    }

    fn note(&mut self, at: Duration, text: String) {
        self.log
            .push(format!("{:6.2}s base: {text}", at.as_secs_f64()));
    }

    /// One turn: error policies, the recovery queue, then the supervisor's rules.
    /// `at` is the run's clock, for the log.
    pub fn tick(&mut self, system: &mut System, at: Duration) {
        let snapshot = |name: &str| system.handle(name).map(|h| h.snapshot());
        let (Some(motion), Some(ranges)) = (snapshot(MOTION), snapshot(RANGES)) else {
            return;
        };
        let now = Instant::now();

        // on error ranges: substitute.
        let failed = matches!(ranges.state, State::RunningError | State::StartingError);
        if failed && !self.substituted && self.recovering.is_none() {
            self.faults += 1;
            match self.substitute(system) {
                Ok(routes) => {
                    self.substituted = true;
                    self.substitutions += 1;
                    self.note(
                        at,
                        format!(
                            "ranges failed ({}); sim_ranges substitutes it ({routes} connections moved)",
                            ranges.error.as_deref().unwrap_or("no reason given")
                        ),
                    );
                }
                Err(error) => self.note(at, format!("substitution failed: {error}")),
            }
            self.recovering = Some(Recovering {
                instance: RANGES,
                since: now,
                next_try: now + self.retry_every,
            });
        }

        // The recovery queue: restart periodically; undo the substitution on success;
        // retire the instance at its deadline.
        if let Some(entry) = self.recovering.clone() {
            if ranges.state == State::Running {
                self.recovering = None;
                self.recoveries += 1;
                if self.substituted {
                    match self.restore(system) {
                        Ok(()) => self.note(
                            at,
                            "ranges recovered; sim_ranges back to standby".to_owned(),
                        ),
                        Err(error) => self.note(at, format!("restoring ranges failed: {error}")),
                    }
                    self.substituted = false;
                }
            } else if now.duration_since(entry.since) >= self.deadline {
                self.recovering = None;
                self.retired += 1;
                if let Some(handle) = system.handle(entry.instance) {
                    let _ = handle.command(Command::SetState(Controllable::Dead));
                }
                self.note(
                    at,
                    format!("{} missed its recovery deadline; retired", entry.instance),
                );
            } else if now >= entry.next_try {
                if let Some(handle) = system.handle(entry.instance) {
                    // A restart runs `start` again (it fails while the board is down).
                    let _ = handle.command(Command::SetState(Controllable::Running));
                }
                self.recovering = Some(Recovering {
                    next_try: now + self.retry_every,
                    ..entry
                });
            }
        }

        // on error motion: propagate (the base itself is in error).
        if motion.state == State::RunningError && self.error.is_none() {
            self.error = Some(format!(
                "motion: {}",
                motion.error.as_deref().unwrap_or("running_error")
            ));
            self.note(
                at,
                "motion failed; the error propagates to the base".to_owned(),
            );
        }

        self.rules(&motion, &ranges, at);
    }

    /// The supervisor's `when` rules, in declaration order per state.
    fn rules(&mut self, motion: &Monitor, ranges: &Monitor, at: Duration) {
        let user_state = |m: &Monitor, name: &str| m.user_state.as_deref() == Some(name);
        let next = match self.state {
            SupervisorState::Operating => {
                if ranges.state == State::RunningError {
                    Some(SupervisorState::Degraded)
                } else if matches!(motion.result, TaskResult::Fail(_)) || self.faults > 3 {
                    Some(SupervisorState::Stopped)
                } else {
                    None
                }
            }
            SupervisorState::Degraded => {
                if ranges.state == State::Running && user_state(ranges, "streaming") {
                    Some(SupervisorState::Operating)
                } else if motion.state == State::RunningError {
                    Some(SupervisorState::Stopped)
                } else {
                    None
                }
            }
            SupervisorState::Stopped => None,
        };
        if let Some(next) = next {
            self.note(
                at,
                format!("supervisor {} -> {}", self.state.name(), next.name()),
            );
            self.state = next;
            // The states' entry sections.
            self.mode = match next {
                SupervisorState::Operating => BaseMode::Normal,
                SupervisorState::Degraded => BaseMode::Degraded,
                SupervisorState::Stopped => BaseMode::Stopped,
            };
        }
    }

    fn substitute(&mut self, system: &mut System) -> Result<usize, String> {
        let routes = reroute(system, RANGES, SIM_RANGES)?;
        let handle = system.handle(SIM_RANGES).ok_or("no sim_ranges")?;
        handle
            .command(Command::SetState(Controllable::Running))
            .map_err(|e| e.to_string())?;
        Ok(routes)
    }

    fn restore(&mut self, system: &mut System) -> Result<(), String> {
        reroute(system, SIM_RANGES, RANGES)?;
        let handle = system.handle(SIM_RANGES).ok_or("no sim_ranges")?;
        handle
            .command(Command::SetState(Controllable::Ready))
            .map_err(|e| e.to_string())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_hand_wired_parts_match_the_description() {
        assert_eq!(mobile_base::SUBSTITUTES, &[(SIM_RANGES, RANGES)]);
        let names: Vec<&str> = mobile_base::INSTANCES.iter().map(|(n, _)| *n).collect();
        assert_eq!(names, [MOTION, RANGES, SIM_RANGES]);
        assert_eq!(
            robot::INSTANCES,
            &[(BASE, "MobileBase"), (WANDERER, "Wanderer")]
        );
    }

    #[test]
    fn exported_ports_resolve_to_member_ports() {
        assert_eq!(resolve("base.command"), "motion.command");
        assert_eq!(resolve("base.scan"), "ranges.scan");
        assert_eq!(resolve("wanderer.command"), "wanderer.command");
        // Every `base.*` address the generated Robot connections use is exported.
        for (from, to) in robot::CONNECTIONS {
            for address in [from, to] {
                assert!(
                    !resolve(address).starts_with("base."),
                    "{address} is not exported"
                );
            }
        }
    }
}
