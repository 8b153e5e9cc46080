//! The starter `main` coolc writes, built with the `network` feature, as an operator
//! runs it: one binary as two processes, `--node station --serve` and `--node robot`.
//! The robot's compound places its `on "station"` instance on the station (through the
//! registry the starter main builds), `coolctl` sees both nodes' components, and
//! SIGTERM stops each process cleanly (the station then reaps what it built for the
//! robot: its instance is dead).
//!
//! The crate is built in the workspace's target directory with the workspace's
//! `Cargo.lock`, profile and feature sets ([`WORKSPACE_FEATURES`]), so that the network
//! layer `cargo test --workspace` has built already is reused rather than built again.

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use coolbot_zenoh::ctl::{Ctl, Listed};
use rustix::process::{Pid, Signal, kill_process};

/// Generous: the machine is shared and may be loaded.
const PATIENCE: Duration = Duration::from_secs(60);

const DESCRIPTION: &str = r#"
/// Beats once a period.
atomic Beat {
    output beat: tick;
    timing { period 50ms; }
    automaton {
        initial beating;
        state beating { periodic; }
    }
}

/// One beat here, one on the station.
compound Duo {
    instance here: Beat;
    instance there: Beat on "station";
}
"#;

fn repository() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .canonicalize()
        .unwrap()
}

fn free_port() -> u16 {
    coolbot_zenoh::free_loopback_port()
}

/// Test only, not what coolc writes: dependencies that give the crates this crate
/// shares with the workspace the feature sets `cargo test --workspace` resolves for
/// them, so that Cargo reuses the workspace's build of Zenoh and its stack. Cargo
/// resolves features per build: a crate whose features differ (tokio without
/// `test-util`, say) is another build of it, and so is every crate above it (all of
/// Zenoh). The workspace's come from its members' dev-dependencies, which
/// `cargo test --workspace` unifies too:
///
/// - tokio's `test-util` and tungstenite's defaults: `coolbot-zenoh`'s dev-dependencies;
/// - regex-automata's and regex-syntax's: insta and proptest, dev-dependencies of coolc
///   and others (and tempfile's, through insta);
/// - toml_edit's defaults: coolc, a dependency of `coolbot-tests`;
/// - for the build's host (proc macros and build scripts): coolc as the members'
///   build-dependency (askama: winnow's `simd`; toml_edit; serde_json) with its
///   dev-dependency insta (tempfile: fastrand's and once_cell's `std`).
///
/// Renamed (`ws-…`), so that the generated code cannot use them by their names, and
/// never built for their own sake: Cargo links the workspace's builds and a crate
/// without a build script builds no build-dependencies. The declarations only make the
/// build faster: if they no longer resolve, the crate is built as coolc wrote it, and
/// if the workspace's features drift from them, Zenoh is compiled again (slower, as
/// before). `coolbot` and `coolbot-zenoh` are compiled for this crate whatever it
/// declares (Cargo hashes a path dependency's location relative to the workspace).
const WORKSPACE_FEATURES: (&str, &str) = (
    "ws-tokio = { package = \"tokio\", version = \"1\", features = [\"test-util\"] }
ws-tungstenite = { package = \"tungstenite\", version = \"0.30\" }
ws-insta = { package = \"insta\", version = \"1.49\", features = [\"glob\", \"json\"] }
ws-proptest = { package = \"proptest\", version = \"1.12\", default-features = false, features = [\"std\", \"bit-set\"] }
ws-toml_edit = { package = \"toml_edit\", version = \"0.25\" }
",
    "
[build-dependencies]
ws-askama = { package = \"askama\", version = \"0.16\" }
ws-insta = { package = \"insta\", version = \"1.49\", features = [\"glob\", \"json\"] }
ws-serde_json = { package = \"serde_json\", version = \"1\" }
ws-toml_edit = { package = \"toml_edit\", version = \"0.25\" }
",
);

/// Writes the crate `package` for `description` into `dir` as `coolc compile` into a
/// new directory does (with the starter `main`), replaces the user files `user`
/// (`(file in src/, text)`), and builds it with `--features network`. Returns the
/// binary.
fn build(
    dir: &Path,
    package: &str,
    description: &str,
    user: &[(&str, &str)],
) -> std::path::PathBuf {
    let file = format!("{package}.cool");
    let checked = coolc::analyze_text(&file, description)
        .checked()
        .unwrap_or_else(|analysis| panic!("{}", analysis.render(coolc::RenderOptions::plain())));
    let options = coolc::lower::Options {
        package: package.to_owned(),
        runtime: coolc::ir::RuntimeDep::Path(repository().join("runtime").display().to_string()),
        sources: vec![file.clone()],
        inputs: coolc::fingerprint::inputs(checked.sources().files()),
    };
    coolc::merge::write_crate(dir, &coolc::lower::lower(&checked, &options)).unwrap();
    for (name, text) in user {
        std::fs::write(dir.join("src").join(name), text).unwrap();
    }
    let manifest = std::fs::read_to_string(dir.join("Cargo.toml")).unwrap();
    assert!(
        manifest.contains("[features]\nnetwork = [\"dep:coolbot-zenoh\"]"),
        "{manifest}"
    );
    // The workspace's profile (a user may add one: the manifest keeps it) and lock.
    let profile = "\n[profile.dev]\ndebug = \"line-tables-only\"\n\n[profile.dev.package.\"*\"]\ndebug = false\n";
    let manifest = manifest + profile;
    std::fs::copy(repository().join("Cargo.lock"), dir.join("Cargo.lock")).unwrap();
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    // The workspace's feature sets, if Cargo resolves them with the crates of the lock.
    let (dependencies, build_dependencies) = WORKSPACE_FEATURES;
    assert!(manifest.contains("\n[dependencies]\n"), "{manifest}");
    let sharing = manifest.replacen(
        "\n[dependencies]\n",
        &format!("\n[dependencies]\n{dependencies}"),
        1,
    ) + build_dependencies;
    std::fs::write(dir.join("Cargo.toml"), &sharing).unwrap();
    let resolved = Command::new(&cargo)
        .args([
            "tree",
            "--quiet",
            "--offline",
            "--features",
            "network",
            "--depth",
            "0",
        ])
        .current_dir(dir)
        .output()
        .unwrap();
    if !resolved.status.success() {
        eprintln!(
            "the workspace's feature sets do not resolve (built as coolc wrote it, Zenoh again):\n{}",
            String::from_utf8_lossy(&resolved.stderr)
        );
        std::fs::write(dir.join("Cargo.toml"), &manifest).unwrap();
        std::fs::copy(repository().join("Cargo.lock"), dir.join("Cargo.lock")).unwrap();
    }
    let target = repository().join("target");
    let output = Command::new(cargo)
        .args(["build", "--quiet", "--features", "network"])
        .current_dir(dir)
        .env("CARGO_TARGET_DIR", &target)
        .env_remove("RUSTFLAGS")
        .output()
        .unwrap();
    assert!(
        output.status.success(),
        "cargo build --features network failed:\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
    target.join("debug").join(package)
}

/// A process of the test: killed when dropped (a failing test leaves none behind).
struct Process(Child);

impl Drop for Process {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

impl std::ops::Deref for Process {
    type Target = Child;
    fn deref(&self) -> &Child {
        &self.0
    }
}

impl std::ops::DerefMut for Process {
    fn deref_mut(&mut self) -> &mut Child {
        &mut self.0
    }
}

/// Starts `binary` with `args`; its stdout and stderr lines go to `lines`, tagged.
fn spawn(binary: &Path, who: &'static str, args: &[&str], lines: &mpsc::Sender<String>) -> Process {
    let mut child = Command::new(binary)
        .args(args)
        .env("RUST_LOG", "warn,coolbot_zenoh=info")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the generated binary starts");
    for (stream, tag) in [
        (
            Box::new(child.stdout.take().unwrap()) as Box<dyn std::io::Read + Send>,
            "",
        ),
        (Box::new(child.stderr.take().unwrap()), " stderr"),
    ] {
        let lines = lines.clone();
        std::thread::spawn(move || {
            for line in BufReader::new(stream).lines() {
                let Ok(line) = line else { break };
                let _ = lines.send(format!("{who}{tag}: {line}"));
            }
        });
    }
    Process(child)
}

/// Waits for a line for which `wanted` holds; the others are kept in `seen`.
fn wait_line(
    lines: &mpsc::Receiver<String>,
    seen: &mut Vec<String>,
    what: &str,
    wanted: impl Fn(&str) -> bool,
) -> String {
    let deadline = Instant::now() + PATIENCE;
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        match lines.recv_timeout(left) {
            Ok(line) if wanted(&line) => return line,
            Ok(line) => seen.push(line),
            Err(error) => panic!(
                "no line {what} within {PATIENCE:?} ({error}); seen:\n{}",
                seen.join("\n")
            ),
        }
    }
}

/// Polls `coolctl list` until `wanted` holds of the components, or panics with the
/// last list.
fn wait_list(ctl: &Ctl, what: &str, wanted: impl Fn(&[Listed]) -> bool) -> Vec<Listed> {
    let deadline = Instant::now() + PATIENCE;
    loop {
        let listed = ctl.components(None).unwrap_or_default();
        if wanted(&listed) {
            return listed;
        }
        assert!(
            Instant::now() < deadline,
            "not {what} within {PATIENCE:?}; listed: {:?}",
            listed
                .iter()
                .map(|l| format!("{}/{} {:?}", l.node, l.path, l.monitor.state))
                .collect::<Vec<_>>()
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

fn stop(child: &mut Process) -> std::process::ExitStatus {
    let pid = Pid::from_child(child);
    kill_process(pid, Signal::TERM).unwrap();
    let deadline = Instant::now() + PATIENCE;
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            return status;
        }
        assert!(
            Instant::now() < deadline,
            "no exit within {PATIENCE:?} of SIGTERM"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn the_starter_main_runs_as_the_robot_or_as_the_station() {
    let dir = tempfile::tempdir().unwrap();
    let binary = build(dir.path(), "duo", DESCRIPTION, &[]);
    let listen = format!("tcp/127.0.0.1:{}", free_port());
    let robot_listen = format!("tcp/127.0.0.1:{}", free_port());
    let (sender, lines) = mpsc::channel();
    let mut seen = Vec::new();

    let network = ["--no-multicast", "--lease", "1s"];
    let mut station = spawn(
        &binary,
        "station",
        &[
            &["--node", "station", "--serve", "--listen", &listen][..],
            &network,
        ]
        .concat(),
        &sender,
    );
    wait_line(&lines, &mut seen, "of the station serving", |l| {
        l == "station: node `station` on the network: serving what other nodes place on it"
    });
    let mut robot = spawn(
        &binary,
        "robot",
        &[
            &[
                "forever",
                "--node",
                "robot",
                "--connect",
                &listen,
                "--listen",
                &robot_listen,
            ][..],
            &network,
        ]
        .concat(),
        &sender,
    );
    wait_line(&lines, &mut seen, "of the robot on the network", |l| {
        l == "robot: node `robot` on the network"
    });

    // coolctl's view: the robot's compound with its local instance and the proxy of
    // the remote one; the station's instance, built for the robot, running.
    let config = coolbot_zenoh::peer_config(&[], &[listen.clone(), robot_listen], false).unwrap();
    let session = coolbot_zenoh::zenoh::Wait::wait(coolbot_zenoh::zenoh::open(config)).unwrap();
    let ctl = Ctl::new(session, Duration::from_secs(2));
    let running = |listed: &[Listed], node: &str, path: &str| {
        listed
            .iter()
            .any(|l| l.node == node && l.path == path && l.monitor.state == coolbot::State::Running)
    };
    let listed = wait_list(&ctl, "both nodes' beats running", |listed| {
        running(listed, "robot", "duo")
            && running(listed, "robot", "duo.here")
            && running(listed, "robot", "duo.there")
            && listed.iter().any(|l| {
                l.node == "station"
                    && l.path.starts_with(&format!(
                        "{}duo-there-",
                        coolbot_zenoh::keys::namespace("robot")
                    ))
            })
    });
    let remote = listed
        .iter()
        .find(|l| {
            l.node == "station"
                && l.path.starts_with(&format!(
                    "{}duo-there-",
                    coolbot_zenoh::keys::namespace("robot")
                ))
        })
        .unwrap();
    assert_eq!(remote.monitor.state, coolbot::State::Running);
    assert_eq!(remote.monitor.user_state.as_deref(), Some("beating"));

    // SIGTERM: the robot shuts down cleanly; the station reaps what it built for it.
    let status = stop(&mut robot);
    wait_line(&lines, &mut seen, "of a clean shutdown", |l| {
        l.starts_with("robot: shutdown clean")
    });
    assert!(status.success(), "{status:?}");
    wait_list(&ctl, "the station's instance reaped", |listed| {
        listed
            .iter()
            .filter(|l| l.node == "station")
            .all(|l| l.monitor.state == coolbot::State::Dead)
    });
    let status = stop(&mut station);
    wait_line(&lines, &mut seen, "of the station stopping", |l| {
        l == "station: node `station` stopped"
    });
    assert!(status.success(), "{status:?}");
    // A compound that stops sends its instances to `dead` before its system stops:
    // nothing to warn about then.
    seen.extend(lines.try_iter());
    let warned: Vec<&String> = seen
        .iter()
        .filter(|l| l.contains("not queued at shutdown"))
        .collect();
    assert!(warned.is_empty(), "{warned:#?}");
    // The robot stopped cleanly and sent what the station built for it to `dead`
    // itself: the station's agent does not report it lost.
    let lost: Vec<&String> = seen
        .iter()
        .filter(|l| l.starts_with("station") && l.contains("here is lost"))
        .collect();
    assert!(lost.is_empty(), "{lost:#?}");

    // The robot alone: its remote instance's node is not there, so the compound
    // cannot start, and the process says so and fails (it does not wait for nothing,
    // nor end as a clean run).
    let mut alone = spawn(
        &binary,
        "alone",
        &[
            &["forever", "--node", "robot", "--connect", &listen][..],
            &network,
        ]
        .concat(),
        &sender,
    );
    let line = wait_line(&lines, &mut seen, "of the start failing", |l| {
        l.starts_with("alone stderr: Error: ")
    });
    assert!(
        line.contains("cannot start: `duo` failed to start: ") && line.contains("`station`"),
        "{line}"
    );
    let deadline = Instant::now() + PATIENCE;
    let status = loop {
        if let Some(status) = alone.try_wait().unwrap() {
            break status;
        }
        assert!(Instant::now() < deadline, "no exit within {PATIENCE:?}");
        std::thread::sleep(Duration::from_millis(20));
    };
    assert!(!status.success(), "{status:?}");
}

const TRIO: &str = r#"
/// Beats once a period.
atomic Beat {
    output beat: tick;
    timing { period 20ms; }
    automaton {
        initial beating;
        state beating { periodic; }
    }
}

/// Counts the beats it hears.
atomic Count {
    input beat: tick;
    observable heard: u64 = 0;
    automaton {
        initial counting;
        state counting { entry; on beat -> counting; }
    }
}

/// A counter behind a compound's exported input and mapped variable.
compound Ear {
    instance count: Count;
    input beat = count.beat;
    observable heard = count.heard;
}

/// A beat on one node heard on another, through this one; a local beat stands in.
compound Trio {
    instance source: Beat on "left";
    instance backup: Beat substitutes source;
    instance sink: Ear on "right";
    connect source.beat -> sink.beat;
    on error source: substitute;
    recovery { retry every 300ms; deadline 120s; }
}
"#;

const BEAT_RS: &str = "use crate::generated::beat::*;

/// Beats.
#[derive(Debug, Default)]
pub struct Beat {}

impl Behavior for Beat {
    fn beating_periodic(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        cx.outputs.beat.emit();
        Ok(())
    }
}
";

const COUNT_RS: &str = "use crate::generated::count::*;

/// Counts.
#[derive(Debug, Default)]
pub struct Count {}

impl Behavior for Count {
    fn counting_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        cx.vars.heard += 1;
        Ok(())
    }
}
";

/// What the sink on `right` has heard (its `heard`), if it is listed.
fn heard(listed: &[Listed]) -> Option<u64> {
    let sink = listed.iter().find(|l| {
        l.node == "right"
            && l.path.starts_with(&format!(
                "{}trio-sink-",
                coolbot_zenoh::keys::namespace("robot")
            ))
            && !l.path.contains('.')
            && !l.path.ends_with("-beat")
    })?;
    let (_, value) = sink
        .monitor
        .variables
        .iter()
        .find(|(name, _)| name == "heard")?;
    u64::try_from(value).ok()
}

/// Waits until the sink has heard more than it had when this was called.
fn hears_on(ctl: &Ctl, what: &str) {
    // What it has heard so far, read from a listing that shows the sink (a listing
    // that missed it would make any count look new).
    let before = heard(&wait_list(ctl, what, |listed| heard(listed).is_some()))
        .expect("the listing shows the sink");
    wait_list(ctl, what, |listed| {
        heard(listed).is_some_and(|now| now > before + 5)
    });
}

/// Three processes of one generated binary: the robot places `source` on `left` and
/// `sink`, a compound, on `right` (built there whole: its supervisor and its
/// counter), and the beats go from one to the other through the robot's proxies. `kill -9` of `left` makes the local `backup` beat for it (the sink goes on
/// hearing); `left` back, the recovery queue builds `source` there again and the
/// backup stands by.
#[test]
fn three_processes_stream_and_the_loss_of_one_is_substituted_then_recovered() {
    trio(1);
}

/// The soak: `left` killed (`kill -9`) and started again 50 times in a row; each time
/// the backup stands in and the source is built on `left` again, and the sink keeps
/// hearing. (What the killed `source` had sent and the network had not delivered dies
/// with it, uncounted: `docs/distribution.md`, "What happens when the network fails".)
#[test]
fn a_node_killed_and_started_again_fifty_times_is_substituted_and_recovered_each_time() {
    trio(50);
}

/// [`three_processes_stream_and_the_loss_of_one_is_substituted_then_recovered`] with
/// `rounds` losses of `left` and returns.
fn trio(rounds: usize) {
    let dir = tempfile::tempdir().unwrap();
    let binary = build(
        dir.path(),
        "trio",
        TRIO,
        &[("beat.rs", BEAT_RS), ("count.rs", COUNT_RS)],
    );
    let [left, right, robot] = [0; 3].map(|_| format!("tcp/127.0.0.1:{}", free_port()));
    let (sender, lines) = mpsc::channel();
    let mut seen = Vec::new();
    let network = ["--no-multicast", "--lease", "1s"];
    // A served node also connects to the robot: started again, it reaches the robot
    // at once (the robot retries its own connection only now and then).
    let serve = |name: &'static str, listen: &str| {
        spawn(
            &binary,
            name,
            &[
                &[
                    "--node",
                    name,
                    "--serve",
                    "--listen",
                    listen,
                    "--connect",
                    &robot,
                ][..],
                &network,
            ]
            .concat(),
            &sender,
        )
    };
    let mut left_node = serve("left", &left);
    let mut right_node = serve("right", &right);
    let mut serving = std::collections::BTreeSet::new();
    while serving.len() < 2 {
        let line = wait_line(&lines, &mut seen, "of a node serving", |l| {
            l.ends_with("on the network: serving what other nodes place on it")
        });
        serving.insert(line);
    }
    let mut robot_node = spawn(
        &binary,
        "robot",
        &[
            &[
                "forever",
                "--node",
                "robot",
                "--connect",
                &left,
                "--connect",
                &right,
                "--listen",
                &robot,
            ][..],
            &network,
        ]
        .concat(),
        &sender,
    );
    let config =
        coolbot_zenoh::peer_config(&[], &[left.clone(), right, robot.clone()], false).unwrap();
    let session = coolbot_zenoh::zenoh::Wait::wait(coolbot_zenoh::zenoh::open(config)).unwrap();
    let ctl = Ctl::new(session, Duration::from_secs(2));
    let state = |listed: &[Listed], path: &str| {
        listed
            .iter()
            .find(|l| l.node == "robot" && l.path == path)
            .map(|l| l.monitor.state)
    };
    use coolbot::State::{Ready, Running};

    // The beats of `left` reach `right`.
    wait_list(
        &ctl,
        "the source and the sink placed and running",
        |listed| {
            state(listed, "trio.source") == Some(Running)
                && state(listed, "trio.sink") == Some(Running)
                && state(listed, "trio.backup") == Some(Ready)
        },
    );
    hears_on(&ctl, "the sink hearing the source's beats");
    // The compound runs on `right` with its own instance; the robot has its proxy.
    let listed = ctl.components(None).unwrap();
    assert!(
        listed.iter().any(|l| l.node == "right"
            && l.path.starts_with(&format!(
                "{}trio-sink-",
                coolbot_zenoh::keys::namespace("robot")
            ))
            && l.path.ends_with(".count")),
        "{:?}",
        listed
            .iter()
            .map(|l| format!("{}/{}", l.node, l.path))
            .collect::<Vec<_>>()
    );

    for round in 1..=rounds {
        // `left` killed: the backup beats for it, and the sink goes on hearing.
        left_node.kill().unwrap();
        left_node.wait().unwrap();
        wait_list(
            &ctl,
            &format!("round {round}: the backup standing in"),
            |listed| state(listed, "trio.backup") == Some(Running),
        );
        hears_on(
            &ctl,
            &format!("round {round}: the sink hearing the backup's beats"),
        );

        // `left` back: `source` is built there again and the backup stands by.
        left_node = serve("left", &left);
        wait_list(
            &ctl,
            &format!("round {round}: the source recovered on left"),
            |listed| {
                state(listed, "trio.source") == Some(Running)
                    && state(listed, "trio.backup") == Some(Ready)
                    && listed.iter().any(|l| {
                        l.node == "left"
                            && l.path.starts_with(&format!(
                                "{}trio-source-",
                                coolbot_zenoh::keys::namespace("robot")
                            ))
                            && l.monitor.state == Running
                    })
            },
        );
        hears_on(
            &ctl,
            &format!("round {round}: the sink hearing the recovered source's beats"),
        );
    }

    for (child, who) in [
        (&mut robot_node, "robot"),
        (&mut left_node, "left"),
        (&mut right_node, "right"),
    ] {
        let status = stop(child);
        assert!(status.success(), "{who}: {status:?}");
    }
    wait_line(&lines, &mut seen, "of the robot's clean shutdown", |l| {
        l.starts_with("robot: shutdown clean")
    });
}
