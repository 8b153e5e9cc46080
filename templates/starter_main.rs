{#- Written in rustfmt's layout: see coolc/src/layout.rs (`l`). -#}
//! Runs the crate's components as a process an operator can run and stop
//! (`coolbot::process`): for two seconds, or as many as the first argument says
//! (`cargo run -- 30`), or until stopped (`cargo run -- forever`); SIGINT (Ctrl-C) and
//! SIGTERM (`kill`, systemd, docker) stop it earlier, cleanly. Then it prints what
//! the components' monitoring ports show and whether the shutdown was clean. Logs
//! follow `RUST_LOG` (e.g. `RUST_LOG=debug`); a panic the runtime catches in a
//! component prints one line.
//!
//! Built with the `network` feature (`cargo run --features network -- forever --node
//! robot`), `--node NAME` puts the process on the network as a Zenoh node:
//! `coolctl` lists, watches and commands every component; the `on "node"` instances
//! of the crate's compounds run on their nodes; and other nodes may place instances
//! of the crate's components on this one. The same binary started with `--node
//! station --serve` runs only what other nodes place on it. The options are those of
//! `coolbot_zenoh::network::USAGE` (`--listen`, `--connect`, `--config FILE` for TLS
//! and access rules, `--insecure`, `--multicast`, `--lease`, `--silence`); without a
//! security file the node stays on loopback.
//!
//! A driver whose native library may crash (a camera SDK, a serial driver written in
//! C) runs in a process of its own on the same host, so that its segmentation fault
//! or abort ends that process and not the robot: describe it `instance camera: Camera
//! on "drivers";` (with `instance spare: Camera substitutes camera;`, `on error
//! camera: substitute;` and a `recovery` deadline long enough for the process to
//! come back), and start this binary twice:
//!
//! ```sh
//! cargo run --features network -- --node drivers --serve --listen tcp/127.0.0.1:7447
//! cargo run --features network -- forever --node robot --connect tcp/127.0.0.1:7447
//! ```
//!
//! When the drivers process dies (`kill -9`, a segmentation fault), the robot runs on:
//! its kernel closes the process's connections, and the camera's proxy fails at once
//! with "node `drivers` is lost". The compound's policy acts (`substitute`: the spare
//! takes the camera's place; `restart`: the camera is commanded back to `running`
//! within the restart budget, which brings it back only if the process is back by
//! then), and when the drivers process is started again the recovery queue builds
//! the camera there. Without `--node`, the camera runs in this process as any
//! instance does.
//!
//! `coolc` wrote this file when it created the crate and never changes it: it is
//! yours. It starts each component that no compound of the crate instantiated at
//! that time; a component described later is not added here by itself.

use std::process::ExitCode;
use std::time::Duration;

fn main() -> Result<ExitCode, Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    // `--node NAME` and the other network options, taken out of the arguments.
    #[cfg(feature = "network")]
    let (node, args) = {
        let mut args = args;
        let node =
            coolbot_zenoh::network::NodeOptions::take_args(&mut args).map_err(|e| e.to_string())?;
        (node, args)
    };
    if let Some(flag) = args.iter().find(|arg| arg.starts_with("--")) {
        return Err(match flag.split('=').next() {
            Some(
                "--node" | "--serve" | "--listen" | "--connect" | "--multicast" | "--no-multicast"
                | "--lease" | "--silence" | "--config" | "--insecure",
            ) => {
                format!(
                    "`{flag}`: this build has no network support; build with `--features network`"
                )
            }
            _ => format!("unknown option `{flag}`"),
        }
        .into());
    }
    let run_for = match args.first().map(String::as_str) {
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
    let process = coolbot::process::Process::init().map_err(|e| coolbot::Chain(&e).to_string())?;
    // On the network with `--node`, before the components are built: the placer it
    // installs on this thread puts the compounds' `on "node"` instances on their nodes.
    #[cfg(feature = "network")]
    let network = match node {
        Some(options) => {
            let network =
                coolbot_zenoh::network::Network::open(&options, registry()).map_err(|e| {
                    format!(
                        "node `{}` cannot open: {}",
                        options.name,
                        coolbot::Chain(&e)
                    )
                })?;
            if options.serve {
                println!(
                    "node `{}` on the network: serving what other nodes place on it",
                    network.name()
                );
                while !process.wait(Duration::from_secs(3600)) {}
                println!("node `{}` stopped", network.name());
                return Ok(ExitCode::SUCCESS);
            }
            Some(network)
        }
        None => None,
    };
    let mut system = coolbot::System::new();
{{ l.handles(&starter.roots) }}
    coolbot::process::watch_system(&system);
    #[cfg(feature = "network")]
    if let Some(network) = &network {
        network.expose_system(&system).map_err(|e| {
            format!(
                "node `{}` cannot expose the components: {}",
                network.name(),
                coolbot::Chain(&e)
            )
        })?;
        println!("node `{}` on the network", network.name());
    }
    // Start the components' threads and command them to `running`.
    system
        .run_all()
        .map_err(|e| format!("cannot start: {}", coolbot::Chain(&e)))?;
    // A component that could not start (`starting_error`: its `start` failed, or an
    // instance's node was not there) ends the run with its reason.
    if let Some(failed) = handles
        .iter()
        .find(|handle| handle.state() == coolbot::State::StartingError)
    {
        let reason = failed.snapshot().error.unwrap_or_default();
        let name = failed.name().to_owned();
        println!("{}", process.shutdown(system));
        return Err(format!("cannot start: `{name}` failed to start: {reason}").into());
    }
    match run_for {
        Some(duration) => {
            process.wait(duration);
        }
        None => while !process.wait(Duration::from_secs(3600)) {},
    }
    for handle in &handles {
        println!("{}", handle.snapshot());
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

/// The component types other nodes may place on this one (with the `network`
/// feature), atomic and compound, each built from its default behaviour or parts;
/// the types of the ports bridged for the `on "node"` instances placed from here.
#[cfg(feature = "network")]
fn registry() -> coolbot_zenoh::agent::Registry {
    let mut registry = coolbot_zenoh::agent::Registry::new();
{%- for registration in starter.registrations %}
{{ l.body_statement(registration) }}
{%- endfor %}
    registry
}
