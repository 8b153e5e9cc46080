//! Idle components burn no CPU: a component waiting for input spins a few microseconds
//! after its last piece of work (`docs/runtime.md`, "The thread loop"), then sleeps
//! until something rings; a periodic one sleeps until its deadline. A behavioural
//! property, checked with a generous bound (not a timing benchmark): its own test
//! binary, so that no other test runs in the process meanwhile.

use std::time::Duration;

use coolbot::{Command, Controllable, SectionResult, System};
use coolbot_runtime_tests::generated::{idle_listener, idle_ticker};

/// Components that only wait for input, and periodic ones at 10 ms.
const LISTENERS: usize = 16;
const TICKERS: usize = 4;
/// The idle time measured, and the most CPU all components together may use in it
/// (measured: well under a millisecond; ticker activations cost microseconds each).
const IDLE: Duration = Duration::from_secs(1);
const BOUND: Duration = Duration::from_millis(100);

/// Does nothing in any section (`cool/idle_cpu.cool`).
struct Quiet;

impl idle_listener::Behavior for Quiet {
    fn wait_entry(&mut self, _cx: &mut idle_listener::Cx<'_>) -> SectionResult {
        Ok(())
    }
}

impl idle_ticker::Behavior for Quiet {
    fn tick_periodic(&mut self, _cx: &mut idle_ticker::Cx<'_>) -> SectionResult {
        Ok(())
    }
}

fn process_cpu() -> Duration {
    cpu_time::ProcessTime::now().as_duration()
}

#[test]
fn idle_components_burn_no_cpu() {
    let mut system = System::new();
    let mut handles = Vec::new();
    for index in 0..LISTENERS {
        let component = idle_listener::component(format!("listener{index}"), Quiet);
        handles.push(system.add(component).expect("add"));
    }
    for index in 0..TICKERS {
        let component = idle_ticker::component(format!("ticker{index}"), Quiet);
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
