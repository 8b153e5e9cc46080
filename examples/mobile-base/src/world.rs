//! The simulated world and platform: a 2-D room with walls and obstacles, a
//! differential-drive robot in it, and its ir/us/bumper sensor suite.
//!
//! This is the "hardware" the components drive: `MotionController` moves the
//! [`Platform`], `RangeServer` reads its sensors, `SimRangeServer` computes the same
//! readings from the map and the odometry. The platform also keeps the ground truth
//! the summary and the tests check (distance, clearance, contacts).

use std::f64::consts::PI;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Mutex, MutexGuard, PoisonError};
use std::time::{Duration, Instant};

use coolbot::{Clock, NotSettled};

/// The robot's radius (m): it is a disc.
pub const ROBOT_RADIUS: f64 = 0.18;
/// Number of infrared beams, fanned over the front half.
pub const IR_BEAMS: usize = 8;
/// Number of ultrasonic beams, all around.
pub const US_BEAMS: usize = 8;
/// A bumper is pressed when an obstacle is this close to the rim (m).
pub const CONTACT_DISTANCE: f64 = 0.005;

/// The heading of infrared beam `i` relative to the robot's heading (rad): from
/// straight right (-90 degrees) to straight left (+90 degrees).
pub fn ir_angle(i: usize) -> f64 {
    -PI / 2.0 + PI * i as f64 / (IR_BEAMS - 1) as f64
}

/// The heading of ultrasonic beam `i` relative to the robot's heading (rad): every
/// 45 degrees counter-clockwise from straight ahead.
pub fn us_angle(i: usize) -> f64 {
    2.0 * PI * i as f64 / US_BEAMS as f64
}

/// The heading of bumper `i` (front, left, back, right) relative to the robot (rad).
pub fn bumper_angle(i: usize) -> f64 {
    PI / 2.0 * i as f64
}

/// A pose in the world frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    /// x (m).
    pub x: f64,
    /// y (m).
    pub y: f64,
    /// Heading (rad), normalised to (-pi, pi].
    pub theta: f64,
}

/// Normalises an angle to (-pi, pi].
pub fn wrap_angle(angle: f64) -> f64 {
    let mut a = angle % (2.0 * PI);
    if a <= -PI {
        a += 2.0 * PI;
    } else if a > PI {
        a -= 2.0 * PI;
    }
    a
}

/// One obstacle: an axis-aligned box (walls are thin boxes) or a round pillar.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Obstacle {
    /// An axis-aligned rectangle.
    Box {
        /// Lower-left corner.
        min: (f64, f64),
        /// Upper-right corner.
        max: (f64, f64),
    },
    /// A disc.
    Pillar {
        /// Centre.
        center: (f64, f64),
        /// Radius (m).
        radius: f64,
    },
}

impl Obstacle {
    /// Distance from `(x, y)` to the obstacle's surface (negative inside).
    pub fn distance(&self, x: f64, y: f64) -> f64 {
        match *self {
            Obstacle::Box { min, max } => {
                let dx = (min.0 - x).max(x - max.0);
                let dy = (min.1 - y).max(y - max.1);
                let outside = (dx.max(0.0).powi(2) + dy.max(0.0).powi(2)).sqrt();
                let inside = dx.max(dy).min(0.0);
                outside + inside
            }
            Obstacle::Pillar { center, radius } => {
                ((x - center.0).powi(2) + (y - center.1).powi(2)).sqrt() - radius
            }
        }
    }

    /// Distance along the ray from `(x, y)` in direction `angle` to the obstacle, if
    /// the ray hits it.
    pub fn ray(&self, x: f64, y: f64, angle: f64) -> Option<f64> {
        let (dx, dy) = (angle.cos(), angle.sin());
        match *self {
            Obstacle::Box { min, max } => {
                // Slab method: intersect the parameter intervals of both axes.
                let mut near = f64::NEG_INFINITY;
                let mut far = f64::INFINITY;
                for (origin, dir, lo, hi) in [(x, dx, min.0, max.0), (y, dy, min.1, max.1)] {
                    if dir.abs() < 1e-12 {
                        if origin < lo || origin > hi {
                            return None;
                        }
                    } else {
                        let (t1, t2) = ((lo - origin) / dir, (hi - origin) / dir);
                        near = near.max(t1.min(t2));
                        far = far.min(t1.max(t2));
                    }
                }
                if near > far || far < 0.0 {
                    None
                } else {
                    Some(near.max(0.0))
                }
            }
            Obstacle::Pillar { center, radius } => {
                let (ox, oy) = (x - center.0, y - center.1);
                let b = ox * dx + oy * dy;
                let c = ox * ox + oy * oy - radius * radius;
                let disc = b * b - c;
                if disc < 0.0 {
                    return None;
                }
                let t = -b - disc.sqrt();
                if t >= 0.0 {
                    Some(t)
                } else if c <= 0.0 {
                    Some(0.0)
                } else {
                    None
                }
            }
        }
    }
}

/// The static map: a rectangular room and what stands in it.
#[derive(Clone, Debug, PartialEq)]
pub struct World {
    /// Room width along x (m).
    pub width: f64,
    /// Room height along y (m).
    pub height: f64,
    /// Walls and obstacles.
    pub obstacles: Vec<Obstacle>,
}

impl World {
    /// The example room: 6 m by 4 m, walls all around, a table, a partition and two
    /// pillars.
    pub fn example() -> World {
        let (w, h, t) = (6.0, 4.0, 0.1);
        World {
            width: w,
            height: h,
            obstacles: vec![
                Obstacle::Box {
                    min: (-t, -t),
                    max: (w + t, 0.0),
                },
                Obstacle::Box {
                    min: (-t, h),
                    max: (w + t, h + t),
                },
                Obstacle::Box {
                    min: (-t, -t),
                    max: (0.0, h + t),
                },
                Obstacle::Box {
                    min: (w, -t),
                    max: (w + t, h + t),
                },
                Obstacle::Box {
                    min: (2.0, 1.3),
                    max: (2.7, 2.0),
                },
                Obstacle::Box {
                    min: (4.2, 2.6),
                    max: (4.4, h),
                },
                Obstacle::Pillar {
                    center: (1.2, 3.0),
                    radius: 0.25,
                },
                Obstacle::Pillar {
                    center: (4.6, 1.1),
                    radius: 0.3,
                },
            ],
        }
    }

    /// Where the robot starts in [`World::example`].
    pub fn example_start() -> Pose {
        Pose {
            x: 0.8,
            y: 0.8,
            theta: 0.35,
        }
    }

    /// Distance from `(x, y)` to the nearest obstacle surface (negative inside one).
    pub fn distance(&self, x: f64, y: f64) -> f64 {
        self.obstacles
            .iter()
            .map(|o| o.distance(x, y))
            .fold(f64::INFINITY, f64::min)
    }

    /// Distance from `(x, y)` along `angle` to the first obstacle, at most `max`.
    pub fn ray(&self, x: f64, y: f64, angle: f64, max: f64) -> f64 {
        self.obstacles
            .iter()
            .filter_map(|o| o.ray(x, y, angle))
            .fold(max, f64::min)
    }

    /// The clearance of a robot at `pose`: distance from its rim to the nearest
    /// obstacle (negative when it overlaps one).
    pub fn clearance(&self, pose: Pose) -> f64 {
        self.distance(pose.x, pose.y) - ROBOT_RADIUS
    }

    /// The clearance ahead of a robot at `pose`: the nearest obstacle from the rim
    /// along the beams that watch the way ahead (the front infrared beams and
    /// straight ahead), up to 10 m.
    pub fn front_clearance(&self, pose: Pose) -> f64 {
        (1..IR_BEAMS - 1)
            .map(ir_angle)
            .chain([0.0])
            .map(|angle| self.ray(pose.x, pose.y, pose.theta + angle, 10.0) - ROBOT_RADIUS)
            .fold(f64::INFINITY, f64::min)
    }

    /// What the sensor suite of a robot at `pose` reads, noise-free: ranges from the
    /// rim, capped at the sensors' maximum ranges.
    pub fn sense(&self, pose: Pose, ir_max: f64, us_max: f64) -> Readings {
        let beam = |relative: f64, max: f64| {
            let range = self.ray(pose.x, pose.y, pose.theta + relative, max + ROBOT_RADIUS);
            (range - ROBOT_RADIUS).clamp(0.0, max)
        };
        let mut readings = Readings::default();
        for (i, r) in readings.ir.iter_mut().enumerate() {
            *r = beam(ir_angle(i), ir_max);
        }
        for (i, r) in readings.us.iter_mut().enumerate() {
            *r = beam(us_angle(i), us_max);
        }
        for (i, b) in readings.bumpers.iter_mut().enumerate() {
            // A bumper covers a quarter of the rim: probe its centre and both edges.
            *b = [-0.6, 0.0, 0.6]
                .iter()
                .any(|edge| beam(bumper_angle(i) + edge, 1.0) <= CONTACT_DISTANCE);
        }
        readings
    }
}

/// One reading of the sensor suite.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Readings {
    /// Infrared ranges from the rim (m).
    pub ir: [f64; IR_BEAMS],
    /// Ultrasonic ranges from the rim (m).
    pub us: [f64; US_BEAMS],
    /// Front, left, back, right contact switches.
    pub bumpers: [bool; 4],
}

/// A seeded random source: SplitMix64, with Gaussian samples by Box-Muller.
#[derive(Clone, Debug)]
pub struct Rng(u64);

impl Rng {
    /// A generator from `seed`; the same seed gives the same sequence.
    pub fn new(seed: u64) -> Rng {
        Rng(seed)
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// A normal sample with mean 0 and standard deviation `sigma`.
    pub fn gaussian(&mut self, sigma: f64) -> f64 {
        let u1 = self.uniform().max(f64::MIN_POSITIVE);
        let u2 = self.uniform();
        sigma * (-2.0 * u1.ln()).sqrt() * (2.0 * PI * u2).cos()
    }
}

/// How an injected sensor fault shows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FaultKind {
    /// Reads time out: the range server raises its `sensor_timeout` exception.
    Raise,
    /// The driver crashes: the range server's section panics.
    Panic,
}

/// A sensor outage: from `after` the start of the run, for `outage`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SensorFault {
    /// When the sensor suite stops answering, from the start of the run.
    pub after: Duration,
    /// How long it stays silent.
    pub outage: Duration,
    /// How the failure shows.
    pub kind: FaultKind,
}

/// A simulated shortage of processor time, from `from` to `until` (since the start of
/// the run): meanwhile the range server's scan processing costs
/// [`OVERLOAD_COST_PER_BEAM`] for every beam it reads, whatever the machine's real
/// load, so that a run shows the same degradation on any machine.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Overload {
    /// When the shortage starts.
    pub from: Duration,
    /// When it ends.
    pub until: Duration,
}

/// What processing one beam of a scan costs the range server while the processor is
/// short: a full scan (8 ir + 8 us beams) takes 112 ms, longer than the longest
/// period its description allows (100 ms); a `half` scan (8 ir + 4 us) takes 84 ms,
/// which fits in it but leaves no spare time, so the server stays at `half` until
/// the shortage ends.
pub const OVERLOAD_COST_PER_BEAM: Duration = Duration::from_millis(7);

/// Ground truth gathered while the robot moves.
#[derive(Clone, Debug, PartialEq)]
pub struct Truth {
    /// The robot's true pose.
    pub pose: Pose,
    /// Distance travelled (m).
    pub distance: f64,
    /// The smallest clearance seen (m).
    pub min_clearance: f64,
    /// The smallest clearance seen ahead (m): along the front beams, as the emergency
    /// stop sees it.
    pub min_front_clearance: f64,
    /// Moves refused because the robot would have entered an obstacle (contacts).
    pub contacts: u64,
}

/// The simulated platform: the world, the robot in it and its sensor suite. Shared by
/// the components that use it (`Arc<Platform>`).
#[derive(Debug)]
pub struct Platform {
    world: World,
    /// The run's clock: the real one, or the virtual clock the robot's system runs on
    /// (tests).
    clock: Clock,
    epoch: Instant,
    fault: Option<SensorFault>,
    overload: Option<Overload>,
    /// An overload switched on by hand ([`Platform::set_overloaded`]).
    overloaded: AtomicBool,
    /// How long the next drive command takes the platform's bus ([`Platform::hiccup`]).
    hiccup: Mutex<Option<Duration>>,
    truth: Mutex<Truth>,
}

/// What one call of [`Platform::drive`] did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Drive {
    /// The pose after the step.
    pub pose: Pose,
    /// The distance covered by the step (m).
    pub moved: f64,
    /// The step was refused: the robot would have hit an obstacle.
    pub blocked: bool,
}

impl Platform {
    /// A platform at `start` in `world`, with an optional sensor fault.
    pub fn new(world: World, start: Pose, fault: Option<SensorFault>) -> Platform {
        let clearance = world.clearance(start);
        let front = world.front_clearance(start);
        Platform {
            world,
            clock: Clock::real(),
            epoch: Instant::now(),
            fault,
            overload: None,
            overloaded: AtomicBool::new(false),
            hiccup: Mutex::new(None),
            truth: Mutex::new(Truth {
                pose: start,
                distance: 0.0,
                min_clearance: clearance,
                min_front_clearance: front,
                contacts: 0,
            }),
        }
    }

    /// The same platform with a simulated processor shortage during `overload`.
    pub fn with_overload(mut self, overload: Option<Overload>) -> Platform {
        self.overload = overload;
        self
    }

    /// The same platform on `clock`: its uptime, its fault and shortage windows and
    /// the time its shortage costs (taken by the sections with `Context::spend`) are
    /// that clock's, and the robot
    /// built on it runs its system on it ([`crate::robot::Robot::start`]). On a virtual
    /// clock the platform reads no real time: a test advances it.
    pub fn with_clock(mut self, clock: Clock) -> Platform {
        self.epoch = clock.now();
        self.clock = clock;
        self
    }

    /// The run's clock (the real one unless [`Platform::with_clock`] said otherwise).
    pub fn clock(&self) -> &Clock {
        &self.clock
    }

    /// The time now on the run's clock.
    pub fn now(&self) -> Instant {
        self.clock.now()
    }

    /// On a virtual clock: moves it on by `by` and waits until every component on it
    /// has settled (`VirtualClock::advance`; one whose section is taking processor
    /// time past the new time, `Context::spend`, and the members of its execution
    /// group, are not waited for). `Ok` at once on the real clock.
    pub fn advance(&self, by: Duration) -> Result<(), NotSettled> {
        match self.clock.as_virtual() {
            Some(clock) => clock.advance(by),
            None => Ok(()),
        }
    }

    /// Switches a simulated processor shortage on or off by hand (tests), besides the
    /// window given to [`Platform::with_overload`].
    pub fn set_overloaded(&self, on: bool) {
        self.overloaded.store(on, Ordering::Relaxed);
        self.tell_idle(!on && !self.overloaded());
    }

    /// On a virtual clock, what the idle probe would say (`VirtualClock::set_idle`): no
    /// spare time while the processor is short. (On the real clock the probe measures
    /// it.)
    fn tell_idle(&self, idle: bool) {
        if let Some(clock) = self.clock.as_virtual() {
            clock.set_idle(idle);
        }
    }

    /// Makes the next drive command take `delay` on the platform's bus (a driver that
    /// hangs once, as a real one does on a bus error): the motion controller's section
    /// spends it (`Context::spend`), and past its `max_response` the section overruns.
    pub fn hiccup(&self, delay: Duration) {
        *self.hiccup.lock().unwrap_or_else(PoisonError::into_inner) = Some(delay);
    }

    /// The time the coming drive command takes on the bus: a hiccup's once, then none.
    pub fn bus_delay(&self) -> Duration {
        self.hiccup
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .take()
            .unwrap_or_default()
    }

    /// The simulated shortage window, if any.
    pub fn overload(&self) -> Option<Overload> {
        self.overload
    }

    /// Whether the processor is short now (within the window, or switched on).
    pub fn overloaded(&self) -> bool {
        let now = self.uptime();
        self.overloaded.load(Ordering::Relaxed)
            || self
                .overload
                .is_some_and(|o| now >= o.from && now < o.until)
    }

    /// What processing a scan of `beams` beams costs now: nothing normally,
    /// [`OVERLOAD_COST_PER_BEAM`] a beam while the processor is short (on a virtual
    /// clock, the idle probe is told meanwhile that the processor has no spare time).
    pub fn processing_cost(&self, beams: usize) -> Duration {
        let overloaded = self.overloaded();
        self.tell_idle(!overloaded);
        if overloaded {
            OVERLOAD_COST_PER_BEAM * u32::try_from(beams).unwrap_or(u32::MAX)
        } else {
            Duration::ZERO
        }
    }

    fn truth_mut(&self) -> MutexGuard<'_, Truth> {
        self.truth.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// The map.
    pub fn world(&self) -> &World {
        &self.world
    }

    /// Time since the platform was powered on (the run's clock).
    pub fn uptime(&self) -> Duration {
        self.clock.now().saturating_duration_since(self.epoch)
    }

    /// A copy of the ground truth.
    pub fn truth(&self) -> Truth {
        self.truth_mut().clone()
    }

    /// Moves the robot with forward speed `linear` and turn rate `angular` for `dt`
    /// seconds (exact arc integration). A step that would make the robot overlap an
    /// obstacle is refused: the robot stays where it is and the contact is counted.
    pub fn drive(&self, linear: f64, angular: f64, dt: f64) -> Drive {
        let mut truth = self.truth_mut();
        let p = truth.pose;
        let next = if angular.abs() < 1e-9 {
            Pose {
                x: p.x + linear * dt * p.theta.cos(),
                y: p.y + linear * dt * p.theta.sin(),
                theta: p.theta,
            }
        } else {
            let radius = linear / angular;
            let theta = p.theta + angular * dt;
            Pose {
                x: p.x + radius * (theta.sin() - p.theta.sin()),
                y: p.y - radius * (theta.cos() - p.theta.cos()),
                theta: wrap_angle(theta),
            }
        };
        let clearance = self.world.clearance(next);
        if clearance < 0.0 {
            truth.contacts += 1;
            return Drive {
                pose: p,
                moved: 0.0,
                blocked: true,
            };
        }
        let moved = ((next.x - p.x).powi(2) + (next.y - p.y).powi(2)).sqrt();
        truth.pose = next;
        truth.distance += moved;
        truth.min_clearance = truth.min_clearance.min(clearance);
        truth.min_front_clearance = truth
            .min_front_clearance
            .min(self.world.front_clearance(next));
        Drive {
            pose: next,
            moved,
            blocked: false,
        }
    }

    /// Whether the sensor suite answers now (false during an injected outage).
    pub fn sensors_answering(&self) -> bool {
        match self.fault {
            Some(fault) => {
                let now = self.uptime();
                now < fault.after || now >= fault.after + fault.outage
            }
            None => true,
        }
    }

    /// The injected fault, if any.
    pub fn fault(&self) -> Option<SensorFault> {
        self.fault
    }

    /// Reads the sensor suite of a robot at `pose`, with Gaussian noise of standard
    /// deviation `noise` on every range. `None` during an outage.
    ///
    /// The pose is the range server's to give (the odometry it hears, which in this
    /// simulation is the true pose): so a sensor board in another process, which no
    /// motion controller drives, reads the world where the robot is.
    pub fn read_sensors(
        &self,
        pose: Pose,
        ir_max: f64,
        us_max: f64,
        noise: f64,
        rng: &mut Rng,
    ) -> Option<Readings> {
        if !self.sensors_answering() {
            return None;
        }
        let mut readings = self.world.sense(pose, ir_max, us_max);
        if noise > 0.0 {
            for r in &mut readings.ir {
                *r = (*r + rng.gaussian(noise)).clamp(0.0, ir_max);
            }
            for r in &mut readings.us {
                *r = (*r + rng.gaussian(noise)).clamp(0.0, us_max);
            }
        }
        Some(readings)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rays_hit_walls_at_the_right_distance() {
        let world = World::example();
        // From the room's lower-left area looking left: the left wall is 0.5 m away.
        let range = world.ray(0.5, 0.5, PI, 10.0);
        assert!((range - 0.5).abs() < 1e-9, "{range}");
        // Looking up from (1.2, 2.0): the pillar at (1.2, 3.0) with radius 0.25.
        let range = world.ray(1.2, 2.0, PI / 2.0, 10.0);
        assert!((range - 0.75).abs() < 1e-9, "{range}");
    }

    #[test]
    fn a_step_into_a_wall_is_refused_and_counted() {
        let start = Pose {
            x: 0.2,
            y: 2.0,
            theta: PI,
        };
        let platform = Platform::new(World::example(), start, None);
        let step = platform.drive(1.0, 0.0, 0.1);
        assert!(step.blocked);
        assert_eq!(step.pose, start);
        assert_eq!(platform.truth().contacts, 1);
        let step = platform.drive(1.0, 0.0, 0.1);
        assert!(step.blocked);
        let back = Platform::new(
            World::example(),
            Pose {
                theta: 0.0,
                ..start
            },
            None,
        );
        assert!(!back.drive(1.0, 0.0, 0.1).blocked);
    }

    #[test]
    fn bumpers_press_on_contact_only() {
        let world = World::example();
        let touching = Pose {
            x: ROBOT_RADIUS + 0.001,
            y: 2.0,
            theta: PI,
        };
        assert_eq!(
            world.sense(touching, 0.8, 3.0).bumpers,
            [true, false, false, false]
        );
        let free = Pose {
            x: 1.0,
            y: 2.0,
            theta: PI,
        };
        assert_eq!(world.sense(free, 0.8, 3.0).bumpers, [false; 4]);
    }

    #[test]
    fn seeded_noise_repeats() {
        let mut a = Rng::new(3);
        let mut b = Rng::new(3);
        let xs: Vec<f64> = (0..5).map(|_| a.gaussian(0.1)).collect();
        let ys: Vec<f64> = (0..5).map(|_| b.gaussian(0.1)).collect();
        assert_eq!(xs, ys);
        assert!(xs.iter().any(|x| *x != 0.0));
    }

    #[test]
    fn scans_cost_time_only_while_the_processor_is_short() {
        let platform = Platform::new(World::example(), World::example_start(), None);
        assert!(!platform.overloaded());
        assert_eq!(platform.processing_cost(16), Duration::ZERO);
        platform.set_overloaded(true);
        assert_eq!(platform.processing_cost(16), Duration::from_millis(112));
        assert_eq!(platform.processing_cost(12), Duration::from_millis(84));
        platform.set_overloaded(false);
        // A window that has not started yet, and one that is over.
        let later = Overload {
            from: Duration::from_secs(3600),
            until: Duration::from_secs(7200),
        };
        let platform = Platform::new(World::example(), World::example_start(), None)
            .with_overload(Some(later));
        assert!(!platform.overloaded());
        let over = Overload {
            from: Duration::ZERO,
            until: Duration::ZERO,
        };
        let platform =
            Platform::new(World::example(), World::example_start(), None).with_overload(Some(over));
        assert!(!platform.overloaded());
        let now = Overload {
            from: Duration::ZERO,
            until: Duration::from_secs(3600),
        };
        let platform =
            Platform::new(World::example(), World::example_start(), None).with_overload(Some(now));
        assert!(platform.overloaded());
    }
}
