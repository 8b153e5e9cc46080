//! Idle-time detection (paper 3.6): "a lowest priority test component for idle CPU
//! intervals". Promotion back towards nominal needs spare time; a component's own short
//! sections say that *it* has time to spare, not that the processor has. The probe
//! says the latter.
//!
//! The probe is one thread per process, under Linux's `SCHED_IDLE` policy (elsewhere,
//! or when refused, the lowest nice value): the scheduler gives it a CPU only when no
//! other thread of any priority wants one. It asks for the CPU every
//! [`IdleConfig::interval`] by sleeping until its next tick, and notes how late it got
//! it. A wake-up within [`IdleConfig::prompt`] of its tick means a CPU had an idle
//! interval at that moment; a late one means every CPU was busy. The share of prompt
//! wake-ups over the last [`IdleConfig::window`] ticks is the idle share
//! ([`IdleProbe::share`]); the processor has spare time while it is at least
//! [`IdleConfig::min_share`].
//!
//! It never spins: it costs one wake-up per interval (100 a second by default), a few
//! microseconds of CPU each, and it runs only while some component adapts (it is
//! started by the first [`IdleProbe::shared`] and stops when the last handle drops).
//! `benches/adapt.rs` measures its CPU share.
//!
//! On a [`crate::VirtualClock`] there is no probe: the test says whether the processor
//! is idle ([`crate::VirtualClock::set_idle`]).
//!
//! [`IdleEstimator`] is the probe's arithmetic, free of threads and clocks.

use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError, Weak};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// The probe's settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IdleConfig {
    /// How often the probe asks for the CPU. Default 10 ms.
    pub interval: Duration,
    /// A wake-up at most this late found an idle CPU. Default 1 ms.
    pub prompt: Duration,
    /// The ticks the idle share is computed over. Default 50 (half a second).
    pub window: u32,
    /// The idle share from which the processor has spare time. Default 0.2.
    pub min_share: f64,
}

impl Default for IdleConfig {
    fn default() -> IdleConfig {
        IdleConfig {
            interval: Duration::from_millis(10),
            prompt: Duration::from_millis(1),
            window: 50,
            min_share: 0.2,
        }
    }
}

/// The probe's arithmetic: wake-up latenesses in, the idle share out.
#[derive(Debug, Clone)]
pub struct IdleEstimator {
    config: IdleConfig,
    /// Whether each of the last `window` ticks was prompt.
    recent: VecDeque<bool>,
    prompt: usize,
}

impl IdleEstimator {
    /// An estimator that has seen nothing yet.
    pub fn new(config: IdleConfig) -> IdleEstimator {
        IdleEstimator {
            config,
            recent: VecDeque::new(),
            prompt: 0,
        }
    }

    /// One wake-up, `lateness` after its tick.
    pub fn observe(&mut self, lateness: Duration) {
        let prompt = lateness <= self.config.prompt;
        self.recent.push_back(prompt);
        self.prompt += usize::from(prompt);
        while self.recent.len() > self.config.window.max(1) as usize {
            if self.recent.pop_front() == Some(true) {
                self.prompt -= 1;
            }
        }
    }

    /// The share of prompt wake-ups in the window; `None` before the first one.
    pub fn share(&self) -> Option<f64> {
        (!self.recent.is_empty()).then(|| self.prompt as f64 / self.recent.len() as f64)
    }

    /// Whether the processor has spare time: the share reached
    /// [`IdleConfig::min_share`]. Before any wake-up the probe knows nothing and does
    /// not stand in the way (true).
    pub fn idle(&self) -> bool {
        self.share()
            .is_none_or(|share| share >= self.config.min_share)
    }
}

/// What the probe thread publishes.
#[derive(Debug, Default)]
struct Readings {
    /// The idle share in millionths, or `u64::MAX` before the first tick.
    share: AtomicU64,
    idle: AtomicBool,
    wakes: AtomicU64,
    late: AtomicU64,
    /// The probe thread's own CPU time, in nanoseconds.
    cpu_nanos: AtomicU64,
    stop: AtomicBool,
}

/// The running probe; stopped and joined when the last [`IdleProbe`] drops.
#[derive(Debug)]
struct Running {
    readings: Arc<Readings>,
    thread: Mutex<Option<JoinHandle<()>>>,
}

impl Drop for Running {
    fn drop(&mut self) {
        self.readings.stop.store(true, Ordering::Release);
        let thread = self
            .thread
            .get_mut()
            .unwrap_or_else(PoisonError::into_inner)
            .take();
        if let Some(thread) = thread {
            thread.thread().unpark();
            let _ = crate::thread::join(thread);
        }
    }
}

/// A handle on the process's idle probe. Cheap to clone.
#[derive(Debug, Clone)]
pub struct IdleProbe {
    running: Arc<Running>,
}

/// The process's probe, while some handle on it lives.
static SHARED: Mutex<Weak<Running>> = Mutex::new(Weak::new());

impl IdleProbe {
    /// The process's probe with the default settings, started if no handle on it
    /// lives. `None` if its thread could not be spawned (promotion then goes by the
    /// components' own section times, as without a probe).
    pub fn shared() -> Option<IdleProbe> {
        let mut shared = SHARED.lock().unwrap_or_else(PoisonError::into_inner);
        if let Some(running) = shared.upgrade() {
            return Some(IdleProbe { running });
        }
        let probe = IdleProbe::start(IdleConfig::default()).ok()?;
        *shared = Arc::downgrade(&probe.running);
        Some(probe)
    }

    /// A probe of its own with `config` (tests and benches; components use
    /// [`IdleProbe::shared`]).
    pub fn start(config: IdleConfig) -> std::io::Result<IdleProbe> {
        let readings = Arc::new(Readings {
            share: AtomicU64::new(u64::MAX),
            idle: AtomicBool::new(true),
            ..Readings::default()
        });
        let theirs = Arc::clone(&readings);
        let thread = crate::thread::spawn("idle-probe", move || probe(config, &theirs))?;
        Ok(IdleProbe {
            running: Arc::new(Running {
                readings,
                thread: Mutex::new(Some(thread)),
            }),
        })
    }

    /// Whether the processor had spare time over the last window (true before the
    /// first tick).
    pub fn idle(&self) -> bool {
        self.running.readings.idle.load(Ordering::Acquire)
    }

    /// The share of the last window's wake-ups that found an idle CPU; `None` before
    /// the first.
    pub fn share(&self) -> Option<f64> {
        match self.running.readings.share.load(Ordering::Acquire) {
            u64::MAX => None,
            millionths => Some(millionths as f64 / 1e6),
        }
    }

    /// Wake-ups so far, and how many of them were late.
    pub fn wakes(&self) -> (u64, u64) {
        let readings = &self.running.readings;
        (
            readings.wakes.load(Ordering::Acquire),
            readings.late.load(Ordering::Acquire),
        )
    }

    /// The CPU time the probe's thread used so far.
    pub fn cpu_time(&self) -> Duration {
        Duration::from_nanos(self.running.readings.cpu_nanos.load(Ordering::Acquire))
    }
}

/// The probe thread's body.
fn probe(config: IdleConfig, readings: &Readings) {
    lowest_priority();
    let interval = config.interval.max(Duration::from_micros(100));
    let mut estimator = IdleEstimator::new(config);
    let mut tick = crate::time::later(Instant::now(), interval);
    while !readings.stop.load(Ordering::Acquire) {
        let now = Instant::now();
        if now < tick {
            // Parked, not slept, so that the last handle's drop can wake it at once.
            std::thread::park_timeout(tick - now);
            continue;
        }
        let lateness = now - tick;
        estimator.observe(lateness);
        readings.wakes.fetch_add(1, Ordering::Relaxed);
        if lateness > config.prompt {
            readings.late.fetch_add(1, Ordering::Relaxed);
        }
        if let Some(share) = estimator.share() {
            readings
                .share
                .store((share * 1e6) as u64, Ordering::Release);
        }
        readings.idle.store(estimator.idle(), Ordering::Release);
        if let Ok(cpu) = cpu_time::ThreadTime::try_now() {
            let nanos = u64::try_from(cpu.as_duration().as_nanos()).unwrap_or(u64::MAX);
            readings.cpu_nanos.store(nanos, Ordering::Release);
        }
        // The next tick after now: ticks missed while the CPU was busy are not
        // made up for (one late wake-up says enough).
        tick = crate::time::later(tick, interval);
        if tick <= now {
            tick = crate::time::later(now, interval);
        }
    }
}

/// Put the calling thread at the lowest priority the OS has (`SCHED_IDLE` on Linux,
/// else nice 19); leave it as it is if refused.
fn lowest_priority() {
    #[cfg(target_os = "linux")]
    {
        use thread_priority::{
            NormalThreadSchedulePolicy, ThreadPriority, ThreadSchedulePolicy,
            set_thread_priority_and_policy, thread_native_id,
        };
        let idle = set_thread_priority_and_policy(
            thread_native_id(),
            ThreadPriority::Min,
            ThreadSchedulePolicy::Normal(NormalThreadSchedulePolicy::Idle),
        );
        if idle.is_err() {
            let _ = rustix::process::setpriority_process(Some(rustix::thread::gettid()), 19);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ms(n: u64) -> Duration {
        Duration::from_millis(n)
    }

    #[test]
    fn the_share_counts_prompt_wake_ups_over_the_window() {
        let mut estimator = IdleEstimator::new(IdleConfig {
            window: 4,
            min_share: 0.5,
            ..IdleConfig::default()
        });
        assert_eq!(estimator.share(), None);
        assert!(
            estimator.idle(),
            "an estimator that saw nothing does not block"
        );
        estimator.observe(ms(5));
        assert_eq!(estimator.share(), Some(0.0));
        assert!(!estimator.idle());
        estimator.observe(Duration::from_micros(200));
        assert_eq!(estimator.share(), Some(0.5));
        assert!(estimator.idle());
        for _ in 0..3 {
            estimator.observe(ms(3));
        }
        // The window holds the last four: one prompt, three late.
        assert_eq!(estimator.share(), Some(0.25));
        assert!(!estimator.idle());
        for _ in 0..4 {
            estimator.observe(Duration::ZERO);
        }
        assert_eq!(estimator.share(), Some(1.0));
    }

    #[test]
    fn the_probe_wakes_and_stops_with_its_last_handle() {
        let probe = IdleProbe::start(IdleConfig {
            interval: Duration::from_millis(1),
            ..IdleConfig::default()
        })
        .expect("spawn");
        let deadline = Instant::now() + Duration::from_secs(20);
        while probe.wakes().0 < 3 {
            assert!(Instant::now() < deadline, "the probe never woke");
            std::thread::park_timeout(Duration::from_millis(5));
        }
        assert!(probe.share().is_some());
        let readings = Arc::clone(&probe.running.readings);
        drop(probe);
        // Dropping the last handle joined the thread, which held the other reference.
        assert_eq!(Arc::strong_count(&readings), 1);
    }

    #[test]
    fn shared_handles_share_one_probe() {
        let a = IdleProbe::shared().expect("spawn");
        let b = IdleProbe::shared().expect("spawn");
        assert!(Arc::ptr_eq(&a.running, &b.running));
    }
}
