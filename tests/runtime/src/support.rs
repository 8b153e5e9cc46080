//! What the tests share: a scriptable behaviour for the generated `Worker` (and for
//! any component of the same states and exceptions, `scripted!`), the `Feeder` that
//! hands its outputs to the test, and a rig of one worker fed by one feeder.

use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use coolbot::crossbeam_channel::{self, Receiver};
use coolbot::{Handle, SectionResult, State, System, TaskResult};

use coolbot::port::{DataOut, FifoIn, LastIn, TickIn, TickOut};
use coolbot::{Command, Controllable};

use crate::generated::{feeder, worker};

pub mod compound;

/// What [`Script::hang_in`] returns: dropping it (or sending on it) lets the hung
/// hook return.
pub type Release = crossbeam_channel::Sender<()>;

/// What components did, in the order they did it: lines their code pushes from
/// their threads and the test takes.
#[derive(Clone, Default)]
pub struct Log(Arc<Mutex<Vec<String>>>);

impl Log {
    pub fn push(&self, line: String) {
        self.0
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .push(line);
    }

    /// The lines pushed since the last take.
    pub fn take(&self) -> Vec<String> {
        std::mem::take(
            &mut *self
                .0
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner),
        )
    }
}

/// Panics injected into components' code print one line, without a backtrace: the
/// default hook's backtrace (CI sets `RUST_BACKTRACE=1`) can take longer than a
/// section's `max_response` on a loaded machine, and the section then counts as an
/// overrun instead of the panic a test injected. Other threads' panics (the tests'
/// own) keep the default hook. (Not for a test of another panic hook: this one would
/// take over its lines.)
pub fn quiet_component_panics() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let default = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            let thread = std::thread::current();
            match thread.name() {
                Some(name) if name.starts_with("cool:") => {
                    eprintln!("panic in component thread {name}: {info}");
                }
                _ => default(info),
            }
        }));
    });
}

/// How long tests wait for anything (generous: the machine is shared).
pub const WAIT: Duration = Duration::from_secs(10);

/// Wait until `condition` holds, checking every millisecond (for conditions on test
/// state that no monitoring event announces); panics with `what` after `WAIT`.
pub fn eventually(condition: impl Fn() -> bool, what: &str) {
    let deadline = std::time::Instant::now() + WAIT;
    while !condition() {
        assert!(
            std::time::Instant::now() < deadline,
            "timed out waiting for: {what}"
        );
        std::thread::sleep(Duration::from_millis(1));
    }
}

/// A fault to inject: in which hook, as which exception (None: undeclared), how often.
#[derive(Debug, Clone)]
pub struct Injected {
    pub hook: &'static str,
    pub exception: Option<worker::Exception>,
    pub times: u32,
}

/// What the scripted behaviour does; tests change it while the component runs.
#[derive(Default)]
pub struct Script {
    pub log: Mutex<Vec<String>>,
    pub start_fails: AtomicBool,
    pub start_gate: Mutex<Option<Receiver<()>>>,
    pub panic_in: Mutex<Option<&'static str>>,
    pub fault: Mutex<Option<Injected>>,
    pub end_in_periodic: AtomicBool,
    /// `busy`'s periodic section asks to end before anything else (an injected
    /// fault then fails the section that asked).
    pub end_first: AtomicBool,
    pub sleep_in_periodic: Mutex<Option<Duration>>,
    pub choose_idle: AtomicBool,
    pub received: AtomicU64,
    pub periodics: AtomicU64,
    pub handled: Mutex<Vec<String>>,
    pub injected: AtomicU32,
    /// The `data` fifo's overflow count (`FifoIn::overflows`), as the behaviour last
    /// saw it (each time it drains the fifo).
    pub data_overflows: AtomicU64,
    /// A hook that blocks (once) until the sender is dropped or sends: a section that
    /// hangs past `max_response`. `returned` counts the hung calls that came back.
    pub hang: Mutex<Option<(&'static str, Receiver<()>)>>,
    pub hanging: AtomicBool,
    pub returned: AtomicU32,
    /// Clones of the worker's inputs, handed over by its `start` hook.
    pub inputs: Mutex<Option<WorkerInputs>>,
}

/// Clones of a Worker-shaped component's inputs: the test reads them from its own
/// thread (queue lengths, counters, latest values) without running a section.
#[derive(Clone)]
pub struct WorkerInputs {
    pub data: FifoIn<u64>,
    pub kick: TickIn,
    pub feed: LastIn<u64>,
}

impl Script {
    pub fn new() -> Arc<Script> {
        Arc::new(Script::default())
    }

    /// The log, without periodic sections (their number depends on timing).
    pub fn log(&self) -> Vec<String> {
        self.log
            .lock()
            .unwrap()
            .iter()
            .filter(|entry| !entry.ends_with(".periodic"))
            .cloned()
            .collect()
    }

    /// The whole log, periodic sections included (exact on a virtual clock).
    #[allow(dead_code, reason = "used by the tests on a virtual clock only")]
    pub fn full_log(&self) -> Vec<String> {
        self.log.lock().unwrap().clone()
    }

    /// The worker's inputs (once its `start` hook has run).
    pub fn inputs(&self) -> WorkerInputs {
        self.inputs
            .lock()
            .unwrap()
            .clone()
            .expect("the worker hands its inputs over when it starts")
    }

    pub fn clear_log(&self) {
        self.log.lock().unwrap().clear();
    }

    pub fn panic_in(&self, hook: Option<&'static str>) {
        *self.panic_in.lock().unwrap() = hook;
    }

    pub fn inject(&self, fault: Option<Injected>) {
        *self.fault.lock().unwrap() = fault;
    }

    /// Make `hook` hang (once) until the returned sender sends or is dropped.
    pub fn hang_in(&self, hook: &'static str) -> Release {
        let (release, gate) = crossbeam_channel::bounded(1);
        *self.hang.lock().unwrap() = Some((hook, gate));
        release
    }

    /// Record a hook call; panic or fail if the script says so.
    pub fn hit(&self, hook: &'static str) -> SectionResult {
        self.log.lock().unwrap().push(hook.to_owned());
        let gate = {
            let mut hang = self.hang.lock().unwrap();
            match hang.as_ref() {
                Some((hung, _)) if *hung == hook => hang.take().map(|(_, gate)| gate),
                _ => None,
            }
        };
        if let Some(gate) = gate {
            self.hanging.store(true, Ordering::SeqCst);
            let _ = gate.recv_timeout(Duration::from_secs(60));
            self.hanging.store(false, Ordering::SeqCst);
            self.returned.fetch_add(1, Ordering::SeqCst);
        }
        if *self.panic_in.lock().unwrap() == Some(hook) {
            panic!("boom in {hook}");
        }
        let mut fault = self.fault.lock().unwrap();
        if let Some(injected) = fault.as_mut()
            && injected.hook == hook
            && injected.times > 0
        {
            injected.times -= 1;
            self.injected.fetch_add(1, Ordering::SeqCst);
            return Err(match injected.exception {
                Some(exception) => {
                    coolbot::Fault::exception(exception.index(), format!("injected in {hook}"))
                }
                None => coolbot::Fault::message(format!("injected in {hook}")),
            });
        }
        Ok(())
    }
}

/// The scripted behaviour, for the generated `Worker` and every component declared
/// with its states, `data` fifo, `count` variable and exceptions (`scripted!`).
pub struct Scripted {
    pub script: Arc<Script>,
    /// Dropped with the behaviour: lets tests see that the thread released it.
    pub token: Option<Arc<()>>,
}

impl Scripted {
    /// A behaviour following `script`.
    pub fn new(script: &Arc<Script>) -> Scripted {
        Scripted {
            script: Arc::clone(script),
            token: None,
        }
    }

    fn drained(&self, count: u64, overflows: u64) {
        self.script.received.fetch_add(count, Ordering::SeqCst);
        self.script
            .data_overflows
            .store(overflows, Ordering::SeqCst);
    }

    fn handled(&self, exception: &str, message: &str) {
        self.script
            .handled
            .lock()
            .unwrap()
            .push(format!("{exception}: {message}"));
    }

    fn start_hook(&self) -> SectionResult {
        self.script.hit("start")?;
        let gate = self.script.start_gate.lock().unwrap().take();
        if let Some(gate) = gate {
            let _ = gate.recv_timeout(WAIT);
        }
        if self.script.start_fails.load(Ordering::SeqCst) {
            return Err(coolbot::Fault::message("no device"));
        }
        Ok(())
    }

    /// After a periodic section's hook and drain: the scripted sleep and end.
    fn periodic_rest(&self, rt: &mut coolbot::Context) -> SectionResult {
        let sleep = *self.script.sleep_in_periodic.lock().unwrap();
        if let Some(sleep) = sleep {
            std::thread::sleep(sleep);
        }
        if self.script.end_in_periodic.load(Ordering::SeqCst) {
            rt.set_result(TaskResult::Success("done".to_owned()));
            rt.end();
        }
        Ok(())
    }

    fn choose_idle(&self) -> bool {
        self.script.choose_idle.swap(false, Ordering::SeqCst)
    }
}

/// Implements the `Behavior` of generated module `$module` (shaped like `Worker`:
/// states `idle` and `busy` with `busy`'s entry, periodic, exit and `may -> idle`,
/// inputs `data` (a fifo of `u64`), `kick` (tick) and `feed` (last `u64`), an
/// observable `count`, exceptions `flaky`, `fatal`, `detour`, `wobbly`) for [`Scripted`]. Invoked here, next to the generated code: a test crate
/// may not implement the library's trait for the library's type.
macro_rules! scripted {
    ($module:path) => {
        const _: () = {
            use $module as m;
            impl m::Behavior for $crate::support::Scripted {
                fn start(&mut self, cx: &mut m::Cx<'_>) -> ::coolbot::SectionResult {
                    *self.script.inputs.lock().unwrap() = Some($crate::support::WorkerInputs {
                        data: cx.inputs.data.clone(),
                        kick: cx.inputs.kick.clone(),
                        feed: cx.inputs.feed.clone(),
                    });
                    self.start_hook()
                }
                fn stop(&mut self, _cx: &mut m::Cx<'_>) {
                    let _ = self.script.hit("stop");
                }
                fn idle_entry(&mut self, _cx: &mut m::Cx<'_>) -> ::coolbot::SectionResult {
                    self.script.hit("idle.entry")
                }
                fn busy_entry(&mut self, cx: &mut m::Cx<'_>) -> ::coolbot::SectionResult {
                    self.script.hit("busy.entry")?;
                    let drained = cx.inputs.data.drain().count() as u64;
                    cx.vars.count += drained;
                    self.drained(drained, cx.inputs.data.overflows());
                    Ok(())
                }
                fn busy_periodic(&mut self, cx: &mut m::Cx<'_>) -> ::coolbot::SectionResult {
                    if self
                        .script
                        .end_first
                        .load(::std::sync::atomic::Ordering::SeqCst)
                    {
                        cx.rt.end();
                    }
                    self.script.hit("busy.periodic")?;
                    self.script
                        .periodics
                        .fetch_add(1, ::std::sync::atomic::Ordering::SeqCst);
                    let drained = cx.inputs.data.drain().count() as u64;
                    cx.vars.count += drained;
                    self.drained(drained, cx.inputs.data.overflows());
                    self.periodic_rest(cx.rt)
                }
                fn busy_exit(&mut self, _cx: &mut m::Cx<'_>) -> ::coolbot::SectionResult {
                    self.script.hit("busy.exit")
                }
                fn busy_choose(&mut self, _cx: &mut m::Cx<'_>) -> Option<m::BusyMay> {
                    self.choose_idle().then_some(m::BusyMay::Idle)
                }
                fn on_flaky(&mut self, _cx: &mut m::Cx<'_>, message: &str) {
                    self.handled("flaky", message);
                }
                fn on_fatal(&mut self, _cx: &mut m::Cx<'_>, message: &str) {
                    self.handled("fatal", message);
                }
                fn on_detour(&mut self, _cx: &mut m::Cx<'_>, message: &str) {
                    self.handled("detour", message);
                }
                fn on_wobbly(&mut self, _cx: &mut m::Cx<'_>, message: &str) {
                    self.handled("wobbly", message);
                }
            }
        };
    };
}

scripted!(crate::generated::worker);
scripted!(crate::generated::goto_worker);
scripted!(crate::generated::ignore_worker);
scripted!(crate::generated::degrade_worker);
scripted!(crate::generated::plain_worker);
scripted!(crate::generated::ua_never_worker);
scripted!(crate::generated::ua_after30ms_worker);
scripted!(crate::generated::ua_watchdog_worker);
scripted!(crate::generated::ua_after1s_worker);
scripted!(crate::generated::ua_timerless_worker);
scripted!(crate::generated::os_reject_worker);
scripted!(crate::generated::os_drop_oldest_worker);
scripted!(crate::generated::os_block_worker);
scripted!(crate::generated::deep_worker);
scripted!(crate::generated::blocking_worker);

/// A `Worker` named `name` following `script`.
pub fn worker(name: &str, script: &Arc<Script>) -> coolbot::Component {
    worker::component(name, Scripted::new(script))
}

/// The `Feeder`'s behaviour: when it starts, it hands clones of its output ports to
/// the test, which then sends on them from its own thread.
pub struct Tap {
    ports: crossbeam_channel::Sender<Feeder>,
}

impl Tap {
    /// A tap, and where the `Feeder` running it hands its ports over when it starts.
    pub fn new() -> (Tap, Receiver<Feeder>) {
        let (ports, handed) = crossbeam_channel::bounded(1);
        (Tap { ports }, handed)
    }
}

impl feeder::Behavior for Tap {
    fn start(&mut self, cx: &mut feeder::Cx<'_>) -> SectionResult {
        // A restarted feeder starts again: the test kept the first hand-over.
        let _ = self.ports.try_send(Feeder {
            kick: cx.outputs.kick.clone(),
            data: cx.outputs.data.clone(),
            feed: cx.outputs.feed.clone(),
        });
        Ok(())
    }
}

/// The name of a rig's worker.
pub const WORKER: &str = "w";

/// A system with one Worker-shaped component `w` (in `ready` once started, or
/// wherever `start` led) fed by a `Feeder` `f`: `f.kick -> w.kick`, `f.data -> w.data`,
/// `f.feed -> w.feed`.
pub struct Rig {
    pub system: System,
    pub handle: Handle,
    pub script: Arc<Script>,
    feeder: std::sync::OnceLock<Feeder>,
    ports: Receiver<Feeder>,
}

/// Clones of the feeder's outputs: tests send on them from their own thread.
pub struct Feeder {
    pub kick: TickOut,
    pub data: DataOut<u64>,
    pub feed: DataOut<u64>,
}

impl Rig {
    /// A `Worker` following `script`, added without starting the system.
    pub fn unstarted(script: Arc<Script>) -> Rig {
        let component = worker(WORKER, &script);
        Rig::with(System::new(), script, component)
    }

    /// `component` (named `w`, shaped like `Worker`: `scripted!`), added to `system`
    /// with its feeder, without starting the system.
    pub fn with(mut system: System, script: Arc<Script>, component: coolbot::Component) -> Rig {
        assert_eq!(component.name(), WORKER, "a rig's worker is named `w`");
        let handle = system.add(component).expect("add");
        let (hand_over, ports) = crossbeam_channel::bounded(1);
        system
            .add(feeder::component("f", Tap { ports: hand_over }))
            .expect("add feeder");
        system.connect("f.kick", "w.kick").expect("connect kick");
        system.connect("f.data", "w.data").expect("connect data");
        system.connect("f.feed", "w.feed").expect("connect feed");
        Rig {
            system,
            handle,
            script,
            feeder: std::sync::OnceLock::new(),
            ports,
        }
    }

    /// The feeder's outputs (once the system has started: its `start` hands them over).
    pub fn feeder(&self) -> &Feeder {
        self.feeder.get_or_init(|| {
            self.ports
                .recv_timeout(WAIT)
                .expect("the feeder hands its ports over when the system starts")
        })
    }

    /// Add and start the worker, and wait for it to leave `starting`.
    pub fn started(script: Arc<Script>) -> Rig {
        Rig::start(Rig::unstarted(script))
    }

    /// Start a rig made with `unstarted_with`.
    pub fn start(mut rig: Rig) -> Rig {
        rig.system.start().expect("start");
        rig.handle
            .wait_for(|m| m.state != State::Starting, WAIT)
            .expect("left starting");
        rig
    }

    /// Command the worker.
    pub fn command(&self, target: Controllable) -> Result<(), coolbot::Rejected> {
        self.handle.command(Command::SetState(target))
    }

    /// From `ready`: running, then a kick into `busy`.
    pub fn run_busy(&self) {
        self.command(Controllable::Running).expect("running");
        self.wait_user("idle");
        self.feeder().kick.emit();
        self.wait_user("busy");
        self.sync();
    }

    /// A round trip through the control port: the worker's thread answers it only
    /// after the call it is in (here, `busy`'s entry section) has returned.
    pub fn sync(&self) {
        self.handle.command(Command::SetPriority(0)).expect("sync");
    }

    pub fn wait_state(&self, state: State) -> coolbot::Monitor {
        self.handle
            .wait_state(state, WAIT)
            .unwrap_or_else(|t| panic!("{t}"))
    }

    pub fn wait_user(&self, user: &str) -> coolbot::Monitor {
        self.handle
            .wait_for(
                |m| m.user_state.as_deref() == Some(user) && m.state == State::Running,
                WAIT,
            )
            .unwrap_or_else(|t| panic!("{t}"))
    }
}
