//! The robot as `examples/components/mobile_base.cool` describes it: the compound
//! `Robot`, built by the generated `robot::builder`, with the compound `MobileBase`
//! (`base`) nested inside it and the `Wanderer` (`wanderer`) driving it.
//!
//! Everything structural comes from the description through the generated code:
//! the instances and their configuration overrides, the connections, `MobileBase`'s
//! exported ports and mapped variables, its `on error` policies, the substitute
//! `sim_ranges`, the recovery queue and the supervisor's `when` rules. This module
//! only says what runs where ([`RobotParts`], [`BaseParts`]: the behaviours, all on
//! one shared simulated [`Platform`]) and what the mobile base's supervisor sections
//! do ([`BaseSupervisor`]), then starts the whole robot as one component
//! ([`Robot::start`]).
//!
//! The robot is built from `Robot`, or from `IsolatedRobot` ([`Ranges::Drivers`],
//! `--drivers`): the same robot on `IsolatedBase`, whose range server is placed on the
//! node `drivers`, a process of its own. The same parts and supervisor sections serve
//! both (each generated trait is implemented for each compound by one macro).

use std::sync::Arc;
use std::time::Duration;

use coolbot::{Command, Controllable, Handle, Report, State, System, Value};

use crate::generated::types::BaseMode;
use crate::generated::{
    isolated_base, isolated_robot, mapper, mobile_base, motion_controller, range_server, robot,
    sim_range_server, teleop, wanderer,
};
use crate::mapper::Mapper;
use crate::motion_controller::MotionController;
use crate::range_server::RangeServer;
use crate::sensing::Overrides;
use crate::sim_range_server::SimRangeServer;
use crate::teleop::Teleop;
use crate::wanderer::Wanderer;
use crate::world::Platform;

/// The top compound's instance name.
pub const ROBOT: &str = "robot";
/// Instance `base` of `Robot`: the `MobileBase` compound.
pub const BASE: &str = "base";
/// Instance `wanderer` of `Robot`.
pub const WANDERER: &str = "wanderer";
/// Instance `fallback` of `Robot` (`substitutes wanderer`).
pub const FALLBACK: &str = "fallback";
/// Instance `mapper` of `Robot`.
pub const MAPPER: &str = "mapper";
/// Instance `teleop` of `Robot`.
pub const TELEOP: &str = "teleop";
/// Instance `motion` of `MobileBase`.
pub const MOTION: &str = "motion";
/// Instance `ranges` of `MobileBase`.
pub const RANGES: &str = "ranges";
/// Instance `sim_ranges` of `MobileBase` (`substitutes ranges`).
pub const SIM_RANGES: &str = "sim_ranges";

/// Where the range server runs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Ranges {
    /// In the robot's process, on the base's control thread with the motion
    /// controller (the compound `Robot`).
    #[default]
    Here,
    /// In the process of the node `drivers` (the compound `IsolatedRobot`, `--drivers`;
    /// without a placer installed on the building thread, here all the same).
    Drivers,
}

impl Ranges {
    /// The type of the top compound that puts the range server there.
    pub fn type_name(self) -> &'static str {
        match self {
            Ranges::Here => robot::TYPE_NAME,
            Ranges::Drivers => isolated_robot::TYPE_NAME,
        }
    }
}

/// How the robot is set up beyond the descriptions' defaults (the command line).
#[derive(Clone, Debug, Default)]
pub struct Setup {
    /// Range noise of the real sensors (m, standard deviation), if not the
    /// description's (`noise = 0.005`).
    pub noise: Option<f64>,
    /// Seed of the range noise and the wanderer's random turns.
    pub seed: u64,
    /// A goal to seek, if any.
    pub goal: Option<(f64, f64)>,
    /// The base's controllable `max_speed` (m/s), if not the default.
    pub max_speed: Option<f64>,
    /// The range servers' controllable `frequency` (Hz), if not the default.
    pub scan_rate: Option<f64>,
    /// Where the range server runs.
    pub ranges: Ranges,
}

/// The forward speed limit (m/s) of the motion controller while the simulated range
/// server stands in for the real one (`degraded`).
pub const DEGRADED_MAX_SPEED: f64 = 0.25;

/// `MobileBase`'s supervisor sections: `mode` follows the supervisor's state and each
/// entry into `degraded` counts a fault (`faults > 3` stops the base, by the
/// description's rule). The sections also control the motion controller through the
/// generated typed handle (`cx.instances.motion()`): `stopped` suspends it, so the
/// platform stands still; `operating` resumes it if it was suspended; `degraded`
/// lowers its controllable `max_speed` to [`DEGRADED_MAX_SPEED`] and its exit puts
/// back the limit it found. A command the controller cannot take while its restart
/// policy brings it back (`Refused::Stuck`, `Refused::Busy`) does not fail the
/// section: it is owed, and the periodic sections give it again until it is taken.
#[derive(Debug, Default)]
pub struct BaseSupervisor {
    /// The motion controller's `max_speed` before `degraded` lowered it.
    max_speed: Option<f64>,
    /// The commands the motion controller could not take yet (it was inside a
    /// section past its `max_response`, waiting for its restart, or busy), oldest
    /// first, at most one of each kind (a state, a speed limit): given again by every
    /// periodic section until they are taken; a later command of a kind replaces the
    /// one owed.
    owed: Vec<MotionCommand>,
}

/// A command of the base's supervisor to its motion controller.
#[derive(Debug, Clone, Copy, PartialEq)]
enum MotionCommand {
    Run,
    Suspend,
    SetMaxSpeed(f64),
}

impl MotionCommand {
    /// Whether `self` and `other` set the same thing (the state, or the limit).
    fn same_kind(self, other: MotionCommand) -> bool {
        matches!(self, MotionCommand::SetMaxSpeed(_))
            == matches!(other, MotionCommand::SetMaxSpeed(_))
    }
}

/// What the generated handle of a base's motion controller takes (the same for
/// `MobileBase` and `IsolatedBase`).
trait MotionControl {
    fn command(&mut self, command: MotionCommand) -> Result<(), coolbot::CommandError>;
}

impl BaseSupervisor {
    /// Give `command` to the motion controller (after any owed before it). Refused
    /// because the controller cannot take a command now (`Refused::Stuck`,
    /// `Refused::Busy`: its restart policy is bringing it back), it is owed and given
    /// again later; any other refusal fails the section.
    fn give(
        &mut self,
        motion: &mut impl MotionControl,
        command: MotionCommand,
    ) -> coolbot::SectionResult {
        self.owed.retain(|owed| !owed.same_kind(command));
        self.owed.push(command);
        self.settle(motion)
    }

    /// Give the owed commands in order, up to the first the controller cannot take
    /// yet (periodic sections).
    fn settle(&mut self, motion: &mut impl MotionControl) -> coolbot::SectionResult {
        while let Some(&command) = self.owed.first() {
            match motion.command(command) {
                Ok(()) => {
                    self.owed.remove(0);
                }
                Err(error)
                    if matches!(
                        error.reason,
                        coolbot::Refused::Stuck | coolbot::Refused::Busy { .. }
                    ) =>
                {
                    // Each periodic section while the controller restarts: one line
                    // per interval, with the count of those held back.
                    coolbot::limited!("the motion controller owed a command", |held| {
                        tracing::warn!(
                            "the motion controller will be commanded again: {error}{held}"
                        )
                    });
                    return Ok(());
                }
                Err(error) => {
                    self.owed.remove(0);
                    return Err(error.into());
                }
            }
        }
        Ok(())
    }

    /// Whether `command` is owed.
    fn owes(&self, command: MotionCommand) -> bool {
        self.owed.contains(&command)
    }
}

/// `BaseSupervisor` for the generated `Supervisor` of a base compound (`MobileBase`,
/// `IsolatedBase`: the same states and sections).
macro_rules! base_supervisor {
    ($base:ident) => {
        impl MotionControl for $base::MotionInstance<'_> {
            fn command(&mut self, command: MotionCommand) -> Result<(), coolbot::CommandError> {
                match command {
                    MotionCommand::Run => self.run(),
                    MotionCommand::Suspend => self.suspend(),
                    MotionCommand::SetMaxSpeed(limit) => self.set_max_speed(limit),
                }
            }
        }

        impl $base::Supervisor for BaseSupervisor {
            fn operating_entry(&mut self, cx: &mut $base::Cx<'_>) -> coolbot::SectionResult {
                cx.vars.mode = BaseMode::Normal;
                if self.owes(MotionCommand::Suspend) {
                    // Never taken: nothing to resume.
                    self.owed.retain(|owed| *owed != MotionCommand::Suspend);
                } else if cx.view.state(MOTION) == Some(State::Suspended) {
                    self.give(&mut cx.instances.motion(), MotionCommand::Run)?;
                }
                Ok(())
            }

            fn operating_periodic(&mut self, cx: &mut $base::Cx<'_>) -> coolbot::SectionResult {
                self.settle(&mut cx.instances.motion())
            }

            fn degraded_entry(&mut self, cx: &mut $base::Cx<'_>) -> coolbot::SectionResult {
                cx.vars.mode = BaseMode::Degraded;
                cx.vars.faults = cx.vars.faults.saturating_add(1);
                let limit = cx
                    .view
                    .var(MOTION, "max_speed")
                    .and_then(|value| f64::try_from(value).ok());
                if let Some(limit) = limit.filter(|limit| *limit > DEGRADED_MAX_SPEED) {
                    self.give(
                        &mut cx.instances.motion(),
                        MotionCommand::SetMaxSpeed(DEGRADED_MAX_SPEED),
                    )?;
                    self.max_speed = Some(limit);
                }
                Ok(())
            }

            fn degraded_exit(&mut self, cx: &mut $base::Cx<'_>) -> coolbot::SectionResult {
                if let Some(limit) = self.max_speed.take() {
                    self.give(
                        &mut cx.instances.motion(),
                        MotionCommand::SetMaxSpeed(limit),
                    )?;
                }
                Ok(())
            }

            fn degraded_periodic(&mut self, cx: &mut $base::Cx<'_>) -> coolbot::SectionResult {
                self.settle(&mut cx.instances.motion())
            }

            fn stopped_entry(&mut self, cx: &mut $base::Cx<'_>) -> coolbot::SectionResult {
                cx.vars.mode = BaseMode::Stopped;
                // The platform moves only when the motion controller's periodic section
                // drives it: suspended, it stands still.
                self.give(&mut cx.instances.motion(), MotionCommand::Suspend)
            }

            fn stopped_periodic(&mut self, cx: &mut $base::Cx<'_>) -> coolbot::SectionResult {
                self.settle(&mut cx.instances.motion())
            }
        }
    };
}

base_supervisor!(mobile_base);
base_supervisor!(isolated_base);

/// `Robot`'s supervisor sections: `teleoperated` lets the outside commands drive the
/// base (sets `teleop`'s controllable `follow`), `autonomous` gives it back to the
/// wanderer. The description's `when` rules move between them on `teleop`'s user
/// state; each move is the supervisor's user state on the robot's monitoring port.
#[derive(Debug)]
pub struct RobotSupervisor;

/// `RobotSupervisor` for the generated `Supervisor` of a top compound (`Robot`,
/// `IsolatedRobot`).
macro_rules! robot_supervisor {
    ($robot:ident) => {
        impl $robot::Supervisor for RobotSupervisor {
            fn autonomous_entry(&mut self, cx: &mut $robot::Cx<'_>) -> coolbot::SectionResult {
                cx.instances.teleop().set_follow(false)?;
                Ok(())
            }

            fn teleoperated_entry(&mut self, cx: &mut $robot::Cx<'_>) -> coolbot::SectionResult {
                cx.instances.teleop().set_follow(true)?;
                Ok(())
            }
        }
    };
}

robot_supervisor!(robot);
robot_supervisor!(isolated_robot);

/// The behaviours of `MobileBase`'s (or `IsolatedBase`'s) instances: the motion
/// controller and both range servers on the shared platform (a range server placed on
/// the node `drivers` is built there, on that process's own platform: `crate::node`).
#[derive(Clone, Debug)]
pub struct BaseParts {
    platform: Arc<Platform>,
    overrides: Overrides,
}

/// `BaseParts` for the generated `Parts` of a base compound.
macro_rules! base_parts {
    ($base:ident) => {
        impl $base::Parts for BaseParts {
            fn supervisor(&mut self) -> impl $base::Supervisor {
                BaseSupervisor::default()
            }

            fn motion(&mut self) -> impl motion_controller::Behavior {
                MotionController::new(Arc::clone(&self.platform))
            }

            fn ranges(&mut self) -> impl range_server::Behavior {
                RangeServer::new(Arc::clone(&self.platform), self.overrides)
            }

            fn sim_ranges(&mut self) -> impl sim_range_server::Behavior {
                SimRangeServer::new(Arc::clone(&self.platform), self.overrides)
            }
        }
    };
}

base_parts!(mobile_base);
base_parts!(isolated_base);

/// The behaviours of `Robot`'s (or `IsolatedRobot`'s) instances: the mobile base and
/// the wanderer.
#[derive(Debug)]
pub struct RobotParts {
    base: BaseParts,
}

/// `RobotParts` for the generated `Parts` of a top compound, on its base compound.
macro_rules! robot_parts {
    ($robot:ident, $base:ident) => {
        impl $robot::Parts for RobotParts {
            fn supervisor(&mut self) -> impl $robot::Supervisor {
                RobotSupervisor
            }

            fn base(&mut self) -> impl $base::Parts {
                self.base.clone()
            }

            fn wanderer(&mut self) -> impl wanderer::Behavior {
                Wanderer::default()
            }

            fn fallback(&mut self) -> impl wanderer::Behavior {
                Wanderer::default()
            }

            fn mapper(&mut self) -> impl mapper::Behavior {
                Mapper::new(Arc::clone(&self.base.platform))
            }

            fn teleop(&mut self) -> impl teleop::Behavior {
                Teleop::default()
            }
        }
    };
}

robot_parts!(robot, mobile_base);
robot_parts!(isolated_robot, isolated_base);

/// The running robot: one `Robot` (or `IsolatedRobot`) component on a system, and the
/// monitoring ports at each level.
#[derive(Debug)]
pub struct Robot {
    system: System,
    ranges: Ranges,
    /// The top compound's control and monitoring ports.
    pub robot: Handle,
    /// Instance `base` (the `MobileBase` compound) of `Robot`.
    pub base: Handle,
    /// Instance `wanderer` of `Robot`.
    pub wanderer: Handle,
    /// Instance `mapper` of `Robot`.
    pub mapper: Handle,
}

/// An error with its sources, for the run's messages.
fn text(error: impl std::error::Error) -> String {
    coolbot::Chain(&error).to_string()
}

impl Robot {
    /// Builds the robot, starts it, applies `setup` through the control ports and sets
    /// it running (`ready`, then `run`). Its system runs on the platform's clock
    /// ([`Platform::with_clock`]: a virtual clock in tests, which the test advances
    /// with [`Platform::advance`]).
    pub fn start(platform: &Arc<Platform>, setup: &Setup) -> Result<Robot, String> {
        let robot = Robot::ready(platform, setup)?;
        if let Err(error) = robot.run() {
            let _ = robot.shutdown();
            return Err(error);
        }
        Ok(robot)
    }

    /// Builds `Robot` with the generated `robot::builder` (`IsolatedRobot` for
    /// [`Ranges::Drivers`]), starts it (every instance at every level starts; the
    /// substitute stays `ready`) and applies `setup` through the control ports: the
    /// robot is `ready`, nothing moves yet.
    pub(crate) fn ready(platform: &Arc<Platform>, setup: &Setup) -> Result<Robot, String> {
        let parts = RobotParts {
            base: BaseParts {
                platform: Arc::clone(platform),
                overrides: Overrides {
                    noise: setup.noise,
                    seed: Some(setup.seed),
                    frequency: setup.scan_rate,
                },
            },
        };
        let built = match setup.ranges {
            Ranges::Here => robot::component(ROBOT, parts),
            Ranges::Drivers => isolated_robot::component(ROBOT, parts),
        }
        .map_err(text)?;
        // The platform's clock is the system's: on a virtual clock (tests) every
        // component, at every level, and the simulated platform read the same time.
        let mut system = System::with_clock(platform.clock().clone());
        let robot = system.add(built).map_err(text)?;
        let instance = |path: &str| {
            robot
                .instance(path)
                .ok_or_else(|| format!("`{}` has no instance `{path}`", setup.ranges.type_name()))
        };
        let (base, wanderer, mapper) = (instance(BASE)?, instance(WANDERER)?, instance(MAPPER)?);
        system.start().map_err(text)?;
        let started = robot
            .wait_for(|m| m.state != State::Starting, Duration::from_secs(10))
            .map_err(text)?;
        if started.state != State::Ready {
            let _ = system.shutdown();
            return Err(format!(
                "the robot did not start: {}",
                started.error.unwrap_or_else(|| started.state.to_string())
            ));
        }
        // The run's settings, through the control ports while the robot is `ready`.
        let mut config = serde_json::json!({ "seed": setup.seed });
        if let Some((x, y)) = setup.goal {
            config["goal_x"] = x.into();
            config["goal_y"] = y.into();
        }
        let mut commands = vec![(&wanderer, Command::Configure(Value::Json(config)))];
        if setup.goal.is_some() {
            commands.push((
                &wanderer,
                Command::Set("seek".to_owned(), Value::Bool(true)),
            ));
        }
        if let Some(speed) = setup.max_speed {
            // `controllable max_speed = motion.max_speed;`: forwarded by the base.
            commands.push((
                &base,
                Command::Set("max_speed".to_owned(), Value::Float(speed)),
            ));
        }
        for (handle, command) in commands {
            if let Err(rejected) = handle.command(command) {
                let _ = system.shutdown();
                return Err(format!("{}: {rejected}", handle.name()));
            }
        }
        Ok(Robot {
            system,
            ranges: setup.ranges,
            robot,
            base,
            wanderer,
            mapper,
        })
    }

    /// Sets the robot running.
    pub(crate) fn run(&self) -> Result<(), String> {
        self.robot
            .command(Command::SetState(Controllable::Running))
            .map_err(|rejected| format!("{}: {rejected}", self.robot.name()))
    }

    /// The type of the top compound (`Robot`, or `IsolatedRobot`).
    pub fn type_name(&self) -> &'static str {
        self.ranges.type_name()
    }

    /// The control and monitoring ports of the instance at `path` inside `Robot`
    /// (dotted through nested compounds: `"base"`, `"base.motion"`): the instance's
    /// own handle, read live.
    pub fn instance(&self, path: &str) -> Option<Handle> {
        self.robot.instance(path)
    }

    /// The system the robot runs on (to tap its ports: `coolbot::record`).
    pub fn system(&self) -> &System {
        &self.system
    }

    /// The system the robot runs on, to add components beside it (ROS 2 topics:
    /// `crate::topics`, `crate::ros`).
    pub fn system_mut(&mut self) -> &mut System {
        &mut self.system
    }

    /// Shuts the robot down: `Robot` goes `dead`, taking its instances (and theirs)
    /// with it.
    pub fn shutdown(self) -> Report {
        self.system.shutdown()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_instance_names_are_the_descriptions() {
        let names: Vec<&str> = mobile_base::INSTANCES.iter().map(|(n, _)| *n).collect();
        assert_eq!(names, [MOTION, RANGES, SIM_RANGES]);
        assert_eq!(mobile_base::SUBSTITUTES, &[(SIM_RANGES, RANGES)]);
        let names: Vec<&str> = robot::INSTANCES.iter().map(|(n, _)| *n).collect();
        assert_eq!(names, [BASE, WANDERER, FALLBACK, MAPPER, TELEOP]);
        assert_eq!(robot::SUBSTITUTES, &[(FALLBACK, WANDERER)]);
        // The isolated variant has the same instances, by the same names and types.
        assert_eq!(isolated_base::SUBSTITUTES, mobile_base::SUBSTITUTES);
        let types = |instances: &[(&str, &str)]| -> Vec<String> {
            instances.iter().map(|(n, t)| format!("{n}: {t}")).collect()
        };
        assert_eq!(
            types(isolated_base::INSTANCES),
            types(mobile_base::INSTANCES)
        );
        assert_eq!(isolated_robot::SUBSTITUTES, robot::SUBSTITUTES);
        let top = |instances: &[(&str, &str)]| -> Vec<String> {
            instances
                .iter()
                .map(|(n, t)| format!("{n}: {}", t.replace("IsolatedBase", "MobileBase")))
                .collect()
        };
        assert_eq!(top(isolated_robot::INSTANCES), top(robot::INSTANCES));
    }
}
