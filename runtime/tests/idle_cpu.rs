//! Idle components burn no CPU: a component waiting for input spins a few microseconds
//! after its last piece of work (`docs/runtime.md`, "The thread loop"), then sleeps
//! until something rings; a periodic one sleeps until its deadline. A behavioural
//! property, checked with a generous bound (not a timing benchmark): its own test
//! binary, so that no other test runs in the process meanwhile.

use std::time::Duration;

use coolbot::port::FifoIn;
use coolbot::{
    Automaton, Command, Component, Context, Controllable, Fault, InputKind, InputSpec, OnSpec,
    OverflowPolicy, PeriodicSpec, PortSet, Section, SectionResult, Spec, StateSpec, System,
    TimingSpec, Value,
};

/// Components that only wait for input, and periodic ones at 10 ms.
const LISTENERS: usize = 16;
const TICKERS: usize = 4;
/// The idle time measured, and the most CPU all components together may use in it
/// (measured: well under a millisecond; ticker activations cost microseconds each).
const IDLE: Duration = Duration::from_secs(1);
const BOUND: Duration = Duration::from_millis(100);

struct Quiet(&'static Spec);

impl Automaton for Quiet {
    fn spec(&self) -> &'static Spec {
        self.0
    }
    fn start(&mut self, _cx: &mut Context) -> Result<(), Fault> {
        Ok(())
    }
    fn stop(&mut self, _cx: &mut Context) {}
    fn section(&mut self, _state: usize, _section: Section, _cx: &mut Context) -> SectionResult {
        Ok(())
    }
    fn choose(&mut self, _state: usize, _cx: &mut Context) -> Option<usize> {
        None
    }
    fn exception(&mut self, _exception: usize, _message: &str, _cx: &mut Context) {}
    fn answer(&mut self, _output: usize, _cx: &mut Context) -> SectionResult {
        Ok(())
    }
    fn configure(&mut self, _configuration: &Value) -> Result<(), String> {
        Ok(())
    }
    fn set(&mut self, variable: usize, _value: &Value) -> Result<(), String> {
        Err(format!("no variable #{variable}"))
    }
    fn get(&self, _variable: usize) -> Value {
        Value::Unit
    }
}

static LISTENER: Spec = Spec {
    type_name: "Listener",
    doc: "waits for input",
    states: &[StateSpec {
        name: "wait",
        entry: true,
        exit: false,
        periodic: None,
        on: &[OnSpec { port: 0, target: 0 }],
        after: &[],
        may: &[],
    }],
    initial: 0,
    inputs: &[InputSpec {
        name: "input",
        kind: InputKind::Fifo {
            capacity: 4,
            policy: OverflowPolicy::Reject,
        },
        packet: "u64",
        pull: false,
    }],
    outputs: &[],
    variables: &[],
    exceptions: &[],
    timing: TimingSpec::NONE,
};

static TICKER: Spec = Spec {
    type_name: "Ticker",
    doc: "a periodic section at 10 ms",
    states: &[StateSpec {
        name: "tick",
        entry: false,
        exit: false,
        periodic: Some(PeriodicSpec {
            period: Some(Duration::from_millis(10)),
        }),
        on: &[],
        after: &[],
        may: &[],
    }],
    initial: 0,
    inputs: &[],
    outputs: &[],
    variables: &[],
    exceptions: &[],
    timing: TimingSpec::NONE,
};

fn process_cpu() -> Duration {
    cpu_time::ProcessTime::now().as_duration()
}

#[test]
fn idle_components_burn_no_cpu() {
    let mut system = System::new();
    let mut handles = Vec::new();
    for index in 0..LISTENERS {
        let input = FifoIn::<u64>::new(4, OverflowPolicy::Reject);
        let ports = PortSet::new().input(&input);
        let component = Component::new(
            format!("listener{index}"),
            Box::new(Quiet(&LISTENER)),
            ports,
        );
        handles.push(system.add(component).expect("add"));
    }
    for index in 0..TICKERS {
        let component = Component::new(
            format!("ticker{index}"),
            Box::new(Quiet(&TICKER)),
            PortSet::new(),
        );
        handles.push(system.add(component).expect("add"));
    }
    system.run_all().expect("run");
    // Every component has reached `running` and published its CPU time then.
    let before: Duration = handles.iter().map(|h| h.snapshot().cpu_time).sum();
    let process_before = process_cpu();

    std::thread::sleep(IDLE);

    let process = process_cpu() - process_before;
    // A state change publishes the thread's CPU time before it is announced.
    for handle in &handles {
        handle
            .command(Command::SetState(Controllable::Suspended))
            .expect("suspend");
    }
    let after: Duration = handles.iter().map(|h| h.snapshot().cpu_time).sum();
    let components = after.saturating_sub(before);
    println!(
        "{} components idle for {IDLE:?}: {components:?} of CPU on the monitors, \
         {process:?} for the whole process",
        handles.len()
    );
    assert!(
        components < BOUND,
        "idle components used {components:?} of CPU in {IDLE:?} (monitor cpu_time)"
    );
    assert!(
        process < BOUND,
        "the process used {process:?} of CPU in {IDLE:?} with only idle components"
    );
    assert!(system.shutdown().clean());
}
