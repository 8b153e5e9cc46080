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

use std::sync::Arc;
use std::time::Duration;

use coolbot::{Command, Controllable, Handle, Report, State, System, Value};

use crate::generated::types::BaseMode;
use crate::generated::{
    mapper, mobile_base, motion_controller, range_server, robot, sim_range_server, teleop, wanderer,
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
/// back the limit it found. The periodic sections have nothing to do: whoever
/// watches the base's instances reads their own monitoring ports
/// ([`Robot::instance`]).
#[derive(Debug, Default)]
pub struct BaseSupervisor {
    /// The motion controller's `max_speed` before `degraded` lowered it.
    max_speed: Option<f64>,
}

impl mobile_base::Supervisor for BaseSupervisor {
    fn operating_entry(&mut self, cx: &mut mobile_base::Cx<'_>) -> coolbot::SectionResult {
        cx.vars.mode = BaseMode::Normal;
        if cx.view.state(MOTION) == Some(State::Suspended) {
            cx.instances.motion().run()?;
        }
        Ok(())
    }

    fn operating_periodic(&mut self, _cx: &mut mobile_base::Cx<'_>) -> coolbot::SectionResult {
        Ok(())
    }

    fn degraded_entry(&mut self, cx: &mut mobile_base::Cx<'_>) -> coolbot::SectionResult {
        cx.vars.mode = BaseMode::Degraded;
        cx.vars.faults = cx.vars.faults.saturating_add(1);
        let limit = cx
            .view
            .var(MOTION, "max_speed")
            .and_then(|value| f64::try_from(value).ok());
        if let Some(limit) = limit.filter(|limit| *limit > DEGRADED_MAX_SPEED) {
            cx.instances.motion().set_max_speed(DEGRADED_MAX_SPEED)?;
            self.max_speed = Some(limit);
        }
        Ok(())
    }

    fn degraded_exit(&mut self, cx: &mut mobile_base::Cx<'_>) -> coolbot::SectionResult {
        if let Some(limit) = self.max_speed.take() {
            cx.instances.motion().set_max_speed(limit)?;
        }
        Ok(())
    }

    fn degraded_periodic(&mut self, _cx: &mut mobile_base::Cx<'_>) -> coolbot::SectionResult {
        Ok(())
    }

    fn stopped_entry(&mut self, cx: &mut mobile_base::Cx<'_>) -> coolbot::SectionResult {
        cx.vars.mode = BaseMode::Stopped;
        // The platform moves only when the motion controller's periodic section
        // drives it: suspended, it stands still.
        cx.instances.motion().suspend()?;
        Ok(())
    }

    fn stopped_periodic(&mut self, _cx: &mut mobile_base::Cx<'_>) -> coolbot::SectionResult {
        Ok(())
    }
}

/// `Robot`'s supervisor sections: `teleoperated` lets the outside commands drive the
/// base (sets `teleop`'s controllable `follow`), `autonomous` gives it back to the
/// wanderer. The description's `when` rules move between them on `teleop`'s user
/// state; each move is the supervisor's user state on the robot's monitoring port.
#[derive(Debug)]
pub struct RobotSupervisor;

impl robot::Supervisor for RobotSupervisor {
    fn autonomous_entry(&mut self, cx: &mut robot::Cx<'_>) -> coolbot::SectionResult {
        cx.instances.teleop().set_follow(false)?;
        Ok(())
    }

    fn teleoperated_entry(&mut self, cx: &mut robot::Cx<'_>) -> coolbot::SectionResult {
        cx.instances.teleop().set_follow(true)?;
        Ok(())
    }
}

/// The behaviours of `MobileBase`'s instances: the motion controller and both range
/// servers on the shared platform.
#[derive(Clone, Debug)]
pub struct BaseParts {
    platform: Arc<Platform>,
    overrides: Overrides,
}

impl mobile_base::Parts for BaseParts {
    fn supervisor(&mut self) -> impl mobile_base::Supervisor {
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

/// The behaviours of `Robot`'s instances: the mobile base and the wanderer.
#[derive(Debug)]
pub struct RobotParts {
    base: BaseParts,
}

impl robot::Parts for RobotParts {
    fn supervisor(&mut self) -> impl robot::Supervisor {
        RobotSupervisor
    }

    fn base(&mut self) -> impl mobile_base::Parts {
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

/// The running robot: one `Robot` component on a system, and the monitoring ports at
/// each level.
#[derive(Debug)]
pub struct Robot {
    system: System,
    /// The `Robot` compound's control and monitoring ports.
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
    /// Builds `Robot` with the generated `robot::builder`, starts it (every instance at
    /// every level starts; the substitute stays `ready`), applies `setup` through the
    /// control ports, and sets it running.
    pub fn start(platform: &Arc<Platform>, setup: &Setup) -> Result<Robot, String> {
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
        let built = robot::component(ROBOT, parts).map_err(text)?;
        let mut system = System::new();
        let robot = system.add(built).map_err(text)?;
        let instance = |path: &str| {
            robot
                .instance(path)
                .ok_or_else(|| format!("`Robot` has no instance `{path}`"))
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
        commands.push((&robot, Command::SetState(Controllable::Running)));
        for (handle, command) in commands {
            if let Err(rejected) = handle.command(command) {
                let _ = system.shutdown();
                return Err(format!("{}: {rejected}", handle.name()));
            }
        }
        Ok(Robot {
            system,
            robot,
            base,
            wanderer,
            mapper,
        })
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
    }
}
