//! The CoolBOT paper's mobile robot, simulated: the components of Figures 4 and 5
//! described in `examples/components/*.cool`, compiled by `coolc` from this crate's
//! build script, filled in here and run on the `coolbot` runtime.
//!
//! [`run`] builds the robot (see [`robot`]), lets it wander in its room for a while
//! with the mobile base's supervisor watching, shows the components' monitoring ports,
//! shuts everything down and returns a [`Summary`]. The `mobile-base` binary and the
//! integration test both call it.
#![deny(missing_docs)]

pub mod motion_controller;
pub mod range_server;
pub mod robot;
pub mod sensing;
pub mod sim_range_server;
pub mod status;
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

use coolbot::{MonitorEvent, State};

use crate::robot::{MOTION, MobileBaseSupervisor, RANGES, SIM_RANGES, Setup, WANDERER};
use crate::world::{FaultKind, Platform, SensorFault, World};

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
    /// Range noise of the real sensors (m).
    pub noise: f64,
    /// Seed of the noise and the wandering.
    pub seed: u64,
    /// A goal for the wanderer to seek.
    pub goal: Option<(f64, f64)>,
    /// How the run shows itself.
    pub display: Display,
    /// Set to stop the run early (Ctrl-C).
    pub stop: Arc<AtomicBool>,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            duration: Duration::from_secs(10),
            fault_after: None,
            outage: Duration::from_millis(1500),
            fault_kind: FaultKind::Raise,
            noise: 0.005,
            seed: 1,
            goal: None,
            display: Display::Auto,
            stop: Arc::new(AtomicBool::new(false)),
        }
    }
}

/// What happened in a run.
#[derive(Clone, Debug, PartialEq)]
pub struct Summary {
    /// How long it ran.
    pub elapsed: Duration,
    /// Whether it was stopped early (Ctrl-C).
    pub interrupted: bool,
    /// Distance the robot really travelled (m).
    pub distance: f64,
    /// Distance by the motion controller's odometry (m).
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
    /// Components entering `running_error` or `starting_error`, all together.
    pub faults: u64,
    /// Substitutions by the supervisor.
    pub substitutions: u32,
    /// Recoveries from the recovery queue.
    pub recoveries: u32,
    /// Instances retired at their recovery deadline.
    pub retired: u32,
    /// The supervisor's last state.
    pub supervisor: String,
    /// The range emergency distance the run used (m).
    pub emergency_distance: f64,
    /// Each component's state before shutdown: `(name, state)`.
    pub states_before_shutdown: Vec<(String, State)>,
    /// Each component's state after shutdown, and whether its thread was joined.
    pub final_states: Vec<(String, State, bool)>,
    /// Every thread joined, every component dead, no runtime panic.
    pub clean_shutdown: bool,
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
            self.faults, self.substitutions, self.recoveries, self.retired
        )?;
        writeln!(f, "  supervisor           {}", self.supervisor)?;
        let before: Vec<String> = self
            .states_before_shutdown
            .iter()
            .map(|(n, s)| format!("{n}={s}"))
            .collect();
        writeln!(f, "  states at the end    {}", before.join(" "))?;
        let after: Vec<String> = self
            .final_states
            .iter()
            .map(|(n, s, joined)| format!("{n}={s}{}", if *joined { "" } else { " (NOT joined)" }))
            .collect();
        writeln!(f, "  after shutdown       {}", after.join(" "))?;
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

fn number(value: Option<&coolbot::Value>) -> f64 {
    match value {
        Some(coolbot::Value::Float(x)) => *x,
        Some(coolbot::Value::Int(x)) => *x as f64,
        Some(coolbot::Value::UInt(x)) => *x as f64,
        Some(coolbot::Value::Json(v)) => v.as_f64().unwrap_or(0.0),
        _ => 0.0,
    }
}

fn variable(monitor: &coolbot::Monitor, name: &str) -> f64 {
    number(
        monitor
            .variables
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v),
    )
}

/// Builds the robot, runs it for `options.duration` (or until `options.stop`), shuts
/// it down and reports.
pub fn run(options: &Options) -> Result<Summary, String> {
    let fault = options.fault_after.map(|after| SensorFault {
        after,
        outage: options.outage,
        kind: options.fault_kind,
    });
    let platform = Arc::new(Platform::new(
        World::example(),
        World::example_start(),
        fault,
    ));
    let setup = Setup {
        noise: options.noise,
        seed: options.seed,
        goal: options.goal,
    };
    let mut system = robot::wire_robot(&platform, &setup)?;
    let names = [MOTION, RANGES, SIM_RANGES, WANDERER];
    let handles: Vec<coolbot::Handle> = names
        .iter()
        .map(|name| {
            system
                .handle(name)
                .ok_or_else(|| format!("no component {name}"))
        })
        .collect::<Result<_, _>>()?;
    let types = [
        "MotionController",
        "RangeServer",
        "SimRangeServer",
        "Wanderer",
    ];
    let events: Vec<_> = handles.iter().map(coolbot::Handle::subscribe).collect();

    let display = match options.display {
        Display::Auto if std::io::stdout().is_terminal() => Display::Table,
        Display::Auto => Display::Lines,
        other => other,
    };
    let mut supervisor = MobileBaseSupervisor::default();
    let mut faults = 0u64;
    let mut log: Vec<String> = Vec::new();
    let mut previous_cpu: Vec<Duration> = vec![Duration::ZERO; handles.len()];
    let mut last_frame = Instant::now();
    let mut last_line = Duration::ZERO;
    let started = Instant::now();
    let stdout = std::io::stdout();
    if display == Display::Table {
        // Clear the screen once; frames then redraw from the top.
        print!("\x1b[2J");
    }

    let interrupted = loop {
        let at = started.elapsed();
        if options.stop.load(Ordering::Relaxed) {
            break true;
        }
        if at >= options.duration {
            break false;
        }
        supervisor.tick(&mut system, at);
        let mut fresh = supervisor.take_log();
        for (name, receiver) in names.iter().zip(&events) {
            for event in receiver.try_iter() {
                match event {
                    MonitorEvent::State { from, to } => {
                        if matches!(to, State::RunningError | State::StartingError) {
                            faults += 1;
                        }
                        fresh.push(format!("{:6.2}s {name}: {from} -> {to}", at.as_secs_f64()));
                    }
                    MonitorEvent::Error(Some(error)) => {
                        fresh.push(format!("{:6.2}s {name}: error: {error}", at.as_secs_f64()));
                    }
                    _ => {}
                }
            }
        }
        if display == Display::Lines {
            let mut out = stdout.lock();
            for line in &fresh {
                let _ = writeln!(out, "{line}");
            }
        }
        log.extend(fresh);
        let keep = log.len().saturating_sub(10);
        log.drain(..keep);

        let frame_due = last_frame.elapsed() >= Duration::from_millis(250);
        let line_due = at >= last_line + Duration::from_secs(1);
        if (display == Display::Table && frame_due) || (display == Display::Lines && line_due) {
            let wall = last_frame.elapsed().as_secs_f64().max(1e-3);
            last_frame = Instant::now();
            let rows: Vec<status::Row> = handles
                .iter()
                .zip(types)
                .zip(previous_cpu.iter_mut())
                .map(|((handle, type_name), cpu)| {
                    let monitor = handle.snapshot();
                    let load = monitor.cpu_time.saturating_sub(*cpu).as_secs_f64() / wall;
                    *cpu = monitor.cpu_time;
                    status::Row {
                        type_name,
                        monitor,
                        load,
                    }
                })
                .collect();
            let truth = platform.truth();
            let mut out = stdout.lock();
            if display == Display::Table {
                let header = format!(
                    "CoolBOT mobile base   t={:5.1}s/{:.0}s   supervisor: {} (mode {:?})   pose ({:.2}, {:.2}, {:.0} deg)   distance {:.2} m   contacts {}",
                    at.as_secs_f64(),
                    options.duration.as_secs_f64(),
                    supervisor.state().name(),
                    supervisor.mode,
                    truth.pose.x,
                    truth.pose.y,
                    truth.pose.theta.to_degrees(),
                    truth.distance,
                    truth.contacts,
                );
                let _ = write!(out, "\x1b[H{}\x1b[J", status::table(&header, &rows, &log));
            } else {
                last_line = at;
                let extra = format!(
                    "supervisor={} distance={:.2}m",
                    supervisor.state().name(),
                    truth.distance
                );
                let _ = writeln!(out, "{}", status::line(at, &rows, &extra));
            }
            let _ = out.flush();
        }
        std::thread::sleep(Duration::from_millis(20));
    };

    let monitors: Vec<coolbot::Monitor> = handles.iter().map(coolbot::Handle::snapshot).collect();
    let states_before_shutdown = monitors.iter().map(|m| (m.name.clone(), m.state)).collect();
    let elapsed = started.elapsed();
    let report = system.shutdown();
    let final_states: Vec<(String, State, bool)> = report
        .components
        .iter()
        .map(|c| (c.name.clone(), c.state, c.joined))
        .collect();
    let clean_shutdown = report.clean()
        && report
            .components
            .iter()
            .all(|c| c.joined && c.state == State::Dead);
    let truth = platform.truth();
    let [motion, ranges, sim, wanderer] = [&monitors[0], &monitors[1], &monitors[2], &monitors[3]];
    Ok(Summary {
        elapsed,
        interrupted,
        distance: truth.distance,
        odometry_distance: variable(motion, "distance"),
        min_clearance: truth.min_clearance,
        min_front_clearance: truth.min_front_clearance,
        contacts: truth.contacts,
        emergencies: (variable(ranges, "emergencies") + variable(sim, "emergencies")) as u64,
        halts: variable(motion, "halts") as u64,
        avoidances: variable(wanderer, "avoidances") as u64,
        goals_reached: variable(wanderer, "goals_reached") as u64,
        scans: (
            variable(ranges, "scans") as u64,
            variable(sim, "scans") as u64,
        ),
        faults,
        substitutions: supervisor.substitutions,
        recoveries: supervisor.recoveries,
        retired: supervisor.retired,
        supervisor: supervisor.state().name().to_owned(),
        emergency_distance: variable(ranges, "emergency_distance"),
        states_before_shutdown,
        final_states,
        clean_shutdown,
    })
}
