//! Runs the crate's components as a process an operator can run and stop
//! (`coolbot::process`): for two seconds, or as many as the first argument says
//! (`cargo run -- 30`), or until stopped (`cargo run -- forever`); SIGINT (Ctrl-C) and
//! SIGTERM (`kill`, systemd, docker) stop it earlier, cleanly. Then it prints what
//! the components' monitoring ports show and whether the shutdown was clean. Logs
//! follow `RUST_LOG` (e.g. `RUST_LOG=debug`); a panic the runtime catches in a
//! component prints one line.
//!
//! `coolc` wrote this file when it created the crate and never changes it: it is
//! yours. It starts each component that no compound of the crate instantiated at
//! that time; a component described later is not added here by itself.

use std::process::ExitCode;
use std::time::Duration;

fn main() -> Result<ExitCode, Box<dyn std::error::Error>> {
    let run_for = match std::env::args().nth(1).as_deref() {
        None => Some(Duration::from_secs(2)),
        Some("forever") => None,
        Some(seconds) => Some(
            seconds
                .parse()
                .ok()
                .and_then(|seconds| Duration::try_from_secs_f64(seconds).ok())
                .ok_or_else(|| format!("`{seconds}` is not a number of seconds (or `forever`)"))?,
        ),
    };
    // Logs, SIGINT and SIGTERM, and the panic hook.
    let process = coolbot::process::Process::init()?;
    let mut system = coolbot::System::new();
    let handles: [coolbot::Handle; {{ roots.len() }}] = [
{%- for root in roots %}
        system
            .add({{ root }})
            .map_err(|e| format!("cannot add a component: {e}"))?,
{%- endfor %}
    ];
    coolbot::process::watch_system(&system);
    // Start the components' threads and command them to `running`.
    system.run_all().map_err(|e| format!("cannot start: {e}"))?;
    match run_for {
        Some(duration) => {
            process.wait(duration);
        }
        None => while !process.wait(Duration::from_secs(3600)) {},
    }
    for handle in &handles {
        println!("{:#?}", handle.snapshot());
    }
    let shutdown = process.shutdown(system);
    println!("{:?}", shutdown.report);
    println!("{shutdown}");
    Ok(if shutdown.clean() {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    })
}
