//! The `Robot` and `MobileBase` compounds of `examples/components/mobile_base.cool`,
//! assembled on a `coolbot::System`, and the mobile base's supervisor.
//!
//! **Hand-written for now.** coolc's compound code generation is partial: for a
//! compound it emits its `INSTANCES`, its `CONNECTIONS` and `connect()`, which wires
//! the connections between instances already added to a system. It does not yet emit
//! the instances themselves, the configuration overrides, the exported ports, the
//! error policies (`on error ranges: substitute`), the recovery queue or the
//! supervisor. [`wire_robot`] does the first part and uses the generated
//! `mobile_base::connect` and `robot::CONNECTIONS`; [`MobileBaseSupervisor`] does the
//! rest, rule for rule as the description says. Both go away when coolc generates
//! compounds in full.

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

/// `instance ranges: RangeServer { noise = 0.005; }`: the override (the noise and
/// seed of a run replace the description's), as a configuration value.
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
}

/// Adds the instances of `MobileBase` (`motion`, `ranges`, `sim_ranges`) and of
/// `Robot` (`wanderer`) to a new system and makes the connections of both compounds:
/// `MobileBase`'s with the generated `mobile_base::connect`, `Robot`'s from the
/// generated `robot::CONNECTIONS` with `base.*` resolved through [`BASE_EXPORTS`].
pub fn wire_robot(platform: &Arc<Platform>, setup: &Setup) -> Result<System, String> {
    let mut system = System::new();
    let add = |system: &mut System, component| system.add(component).map_err(|e| e.to_string());
    add(
        &mut system,
        motion_controller::component(MOTION, MotionController::new(Arc::clone(platform))),
    )?;
    add(
        &mut system,
        range_server::component(RANGES, RangeServer::new(Arc::clone(platform))),
    )?;
    add(
        &mut system,
        sim_range_server::component(SIM_RANGES, SimRangeServer::new(Arc::clone(platform))),
    )?;
    add(
        &mut system,
        wanderer::component(WANDERER, Wanderer::default()),
    )?;
    mobile_base::connect(&mut system, "").map_err(|e| e.to_string())?;
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
