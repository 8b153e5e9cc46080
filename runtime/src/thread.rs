//! The one place component threads are spawned and joined.

use std::any::Any;
use std::io;
use std::thread::{Builder, JoinHandle};
use std::time::Duration;

/// The stack of every thread the runtime spawns (components, among them the outlets
/// and inlets of `coolbot-zenoh`, execution groups, the recorder): 8 MiB, what a C
/// thread gets on Linux by default (glibc takes `RLIMIT_STACK`), where a Rust thread
/// gets 2 MiB. A packet travels by value: a section that builds one and sends it holds
/// several copies of it on its stack at once, more in a debug build, and 2 MiB gave
/// out at packets of about 64 KiB in a debug build and 192 KiB in a release build.
/// Only the pages a thread touches take memory; the rest is address space.
pub const THREAD_STACK_SIZE: usize = 8 << 20;

/// Spawn a named thread (`cool:<name>`; the OS may truncate the name) with a stack of
/// [`THREAD_STACK_SIZE`].
pub(crate) fn spawn(
    name: &str,
    body: impl FnOnce() + Send + 'static,
) -> io::Result<JoinHandle<()>> {
    Builder::new()
        .name(format!("cool:{name}"))
        .stack_size(THREAD_STACK_SIZE)
        .spawn(body)
}

/// Join a thread; a panic that escaped it (a runtime bug: user code runs under
/// `catch_unwind`) is reported as its message.
pub(crate) fn join(handle: JoinHandle<()>) -> Result<(), String> {
    handle
        .join()
        .map_err(|payload| panic_message(payload.as_ref()))
}

/// The message of a panic payload (what `catch_unwind` or a thread's `join` returns):
/// its text when it has one.
pub fn panic_message(payload: &(dyn Any + Send)) -> String {
    if let Some(message) = payload.downcast_ref::<&str>() {
        (*message).to_owned()
    } else if let Some(message) = payload.downcast_ref::<String>() {
        message.clone()
    } else {
        "panic with a non-string payload".to_owned()
    }
}

/// How a component's `priority` is applied to its OS thread (`docs/runtime.md`,
/// "Priority"). Applying can fail (no `CAP_SYS_NICE` in a container): the component
/// runs on regardless, and this says what holds.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum OsPriority {
    /// Nothing applied: the thread has not started, or the priority is 0 and the thread
    /// keeps the scheduling it was created with.
    Inherited,
    /// Real-time round-robin scheduling (Linux `SCHED_RR`) at this static priority
    /// (1 to 99).
    RoundRobin(i32),
    /// Normal time-sharing scheduling at this nice value (-20, highest, to 19): a
    /// negative priority, a priority of 0 restored, or a positive priority when
    /// real-time scheduling was refused.
    Nice(i32),
    /// The OS refused, or the platform is not supported: why. The thread keeps its
    /// previous scheduling.
    NotApplied(String),
}

/// The timer slack given to component threads (Linux `PR_SET_TIMERSLACK`): how late the
/// kernel may fire the thread's timers to batch wake-ups. The default, 50 us, is most
/// of a 1 kHz component's activation lateness; a component's timers are its deadlines.
pub(crate) const TIMER_SLACK: Duration = Duration::from_micros(1);

/// Set the calling thread's timer slack to [`TIMER_SLACK`] (Linux; elsewhere nothing).
/// False if the OS refused (the thread keeps its slack).
pub(crate) fn set_timer_slack() -> bool {
    #[cfg(target_os = "linux")]
    {
        let nanos = u64::try_from(TIMER_SLACK.as_nanos()).unwrap_or(u64::MAX);
        rustix::thread::set_current_timer_slack(std::num::NonZeroU64::new(nanos)).is_ok()
    }
    #[cfg(not(target_os = "linux"))]
    {
        false
    }
}

pub(crate) use os::{Scheduling, highest_realtime};

/// How `priority` maps onto the OS (`docs/runtime.md`, "Priority").
#[cfg(target_os = "linux")]
mod os {
    use rustix::process::{getpriority_process, setpriority_process};
    use rustix::thread::gettid;
    use thread_priority::{
        NormalThreadSchedulePolicy, RealtimeThreadSchedulePolicy, ThreadPriority,
        ThreadPriorityValue, ThreadSchedulePolicy, set_thread_priority_and_policy,
        thread_native_id,
    };

    use super::OsPriority;

    /// The highest `SCHED_RR` static priority on Linux.
    const RR_MAX: i32 = 99;
    /// The nice range on Linux.
    const NICE_HIGHEST: i32 = -20;
    const NICE_LOWEST: i32 = 19;

    /// A component thread's scheduling: what it was created with and what the runtime
    /// applied. Lives on, and is used only by, the component's own thread.
    pub(crate) struct Scheduling {
        /// The nice value the thread was created with (inherited from its creator).
        base_nice: i32,
        /// Whether the runtime put the thread under `SCHED_RR`.
        realtime: bool,
        /// What holds now.
        current: OsPriority,
    }

    impl Scheduling {
        /// The calling thread's scheduling, as created.
        pub(crate) fn of_current_thread() -> Scheduling {
            Scheduling {
                base_nice: getpriority_process(Some(gettid())).unwrap_or(0),
                realtime: false,
                current: OsPriority::Inherited,
            }
        }

        /// Apply `priority` to the calling thread (which must be the one this was made
        /// on); returns what holds now. Never fails: a refusal is `NotApplied`.
        pub(crate) fn apply(&mut self, priority: i32) -> OsPriority {
            self.current = match priority {
                0 if self.current == OsPriority::Inherited => OsPriority::Inherited,
                0 => self.normal(self.base_nice, ""),
                p if p > 0 => match self.round_robin(p.min(RR_MAX)) {
                    Ok(applied) => applied,
                    Err(refused) => {
                        // Fall back to a nice value below the thread's own.
                        let nice = self
                            .base_nice
                            .saturating_sub(p.min(NICE_LOWEST - NICE_HIGHEST))
                            .max(NICE_HIGHEST);
                        self.normal(nice, &format!("SCHED_RR {}: {refused}; ", p.min(RR_MAX)))
                    }
                },
                p => {
                    let nice = self
                        .base_nice
                        .saturating_add(p.saturating_neg())
                        .min(NICE_LOWEST);
                    self.normal(nice, "")
                }
            };
            self.current.clone()
        }

        fn round_robin(&mut self, level: i32) -> Result<OsPriority, String> {
            let value = u8::try_from(level)
                .ok()
                .and_then(|v| ThreadPriorityValue::try_from(v).ok())
                .ok_or_else(|| format!("priority {level} out of range"))?;
            set_thread_priority_and_policy(
                thread_native_id(),
                ThreadPriority::Crossplatform(value),
                ThreadSchedulePolicy::Realtime(RealtimeThreadSchedulePolicy::RoundRobin),
            )
            .map_err(describe)?;
            self.realtime = true;
            Ok(OsPriority::RoundRobin(level))
        }

        /// Normal scheduling at `nice`; `before` says what was refused first, if
        /// anything (for the `NotApplied` text).
        fn normal(&mut self, nice: i32, before: &str) -> OsPriority {
            if self.realtime {
                // Leave SCHED_RR: `thread-priority` sets a nice value with the policy;
                // ask it for the one wanted, then set it exactly below.
                let nearest = (0..=99u8)
                    .filter_map(|v| ThreadPriorityValue::try_from(v).ok())
                    .map(ThreadPriority::Crossplatform)
                    .min_by_key(|p| {
                        p.to_posix(normal_policy())
                            .map_or(i32::MAX, |n| (n - nice).abs())
                    });
                let left = nearest
                    .ok_or_else(|| "no priority value".to_owned())
                    .and_then(|p| {
                        set_thread_priority_and_policy(thread_native_id(), p, normal_policy())
                            .map_err(describe)
                    });
                if let Err(refused) = left {
                    return OsPriority::NotApplied(format!(
                        "{before}leaving SCHED_RR: {refused}; the thread stays real-time"
                    ));
                }
                self.realtime = false;
            }
            match setpriority_process(Some(gettid()), nice) {
                Ok(()) => OsPriority::Nice(nice),
                Err(errno) => {
                    let now = getpriority_process(Some(gettid())).unwrap_or(self.base_nice);
                    OsPriority::NotApplied(format!(
                        "{before}nice {nice}: {}; the thread keeps nice {now}",
                        std::io::Error::from(errno)
                    ))
                }
            }
        }
    }

    /// Put the calling thread under `SCHED_RR` at the highest priority it is allowed
    /// (99 when privileged, else the `RLIMIT_RTPRIO` soft limit); leave it as it is if
    /// both are refused. Returns the level applied.
    pub(crate) fn highest_realtime() -> Option<i32> {
        let mut scheduling = Scheduling::of_current_thread();
        let limit = rustix::process::getrlimit(rustix::process::Resource::Rtprio)
            .current
            .map_or(RR_MAX, |limit| {
                i32::try_from(limit).unwrap_or(RR_MAX).min(RR_MAX)
            });
        [RR_MAX, limit]
            .into_iter()
            .filter(|level| *level > 0)
            .find(|level| scheduling.round_robin(*level).is_ok())
    }

    fn normal_policy() -> ThreadSchedulePolicy {
        ThreadSchedulePolicy::Normal(NormalThreadSchedulePolicy::Other)
    }

    fn describe(error: thread_priority::Error) -> String {
        match error {
            thread_priority::Error::OS(code) => std::io::Error::from_raw_os_error(code).to_string(),
            other => other.to_string(),
        }
    }
}

/// Other platforms: `priority` is recorded and published, not applied.
#[cfg(not(target_os = "linux"))]
mod os {
    use super::OsPriority;

    /// Real-time scheduling is not applied on this platform.
    pub(crate) fn highest_realtime() -> Option<i32> {
        None
    }

    /// A component thread's scheduling (not changed on this platform).
    pub(crate) struct Scheduling;

    impl Scheduling {
        pub(crate) fn of_current_thread() -> Scheduling {
            Scheduling
        }

        pub(crate) fn apply(&mut self, priority: i32) -> OsPriority {
            if priority == 0 {
                OsPriority::Inherited
            } else {
                OsPriority::NotApplied("not supported on this platform".to_owned())
            }
        }
    }
}
