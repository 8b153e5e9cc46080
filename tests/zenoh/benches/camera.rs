//! A camera driver in a process of its own on the same host, streaming 640 x 480 RGB
//! images (921,600 bytes) at 30 Hz to a detector in the robot's process: `Vision`
//! (`cool/camera.cool`), written from `docs/distribution.md` ("A driver in a process
//! of its own"). The drivers process is `drivers-under-test --node drivers --serve`,
//! as the starter `main` runs one; this process is the robot, which places the camera
//! there.
//!
//! The same system runs twice, alternated, on two robot nodes that differ in one
//! setting: shared memory on (the default: the images go through shared memory), and
//! off (`transport/shared_memory/enabled` false, the images over the loopback link, as
//! to another host). For each: the CPU time of both processes (`/proc/<pid>/stat`,
//! every thread, the dead ones included) per image the detector took, over a window
//! after a warm-up, and how many images the camera sent and the detector took and
//! found intact. No goal: it shows what isolating a camera costs.
//!
//! `cargo bench -p coolbot-zenoh-tests --bench camera` (add `-- --quick` for a smoke
//! run: a window of 3 s instead of 10 s).

use std::sync::Arc;
use std::time::{Duration, Instant};

use coolbot::{Handle, System};
use coolbot_zenoh::{Node, Placer};
use coolbot_zenoh_tests::camera::Parts;
use coolbot_zenoh_tests::dying::counted;
use coolbot_zenoh_tests::generated::vision;
use coolbot_zenoh_tests::isolation::registry;
use coolbot_zenoh_tests::support::{NodeProcess, PATIENCE, free_port, wait_until};

/// What one window measured.
struct Window {
    /// Images the camera sent, and the detector took, in the window.
    sent: u64,
    seen: u64,
    /// Images the detector found damaged, since the start.
    bad: u64,
    /// CPU time of the robot's process (the detector) and the drivers process (the
    /// camera) in the window.
    robot: Duration,
    drivers: Duration,
    /// The window's length.
    wall: Duration,
}

impl Window {
    fn per_image(&self, cpu: Duration) -> Duration {
        cpu / u32::try_from(self.seen.max(1)).unwrap_or(u32::MAX)
    }
}

/// Clock ticks a second, as `/proc/<pid>/stat` counts CPU time.
fn clock_ticks() -> u64 {
    std::process::Command::new("getconf")
        .arg("CLK_TCK")
        .output()
        .ok()
        .and_then(|out| String::from_utf8(out.stdout).ok())
        .and_then(|text| text.trim().parse().ok())
        .unwrap_or(100)
}

/// CPU time (user and system) of process `pid` so far, every thread counted.
fn process_cpu(pid: u32, ticks: u64) -> Duration {
    let Ok(stat) = std::fs::read_to_string(format!("/proc/{pid}/stat")) else {
        return Duration::ZERO;
    };
    // After the command's closing parenthesis: state is field 3, utime 14, stime 15.
    let Some((_, rest)) = stat.rsplit_once(')') else {
        return Duration::ZERO;
    };
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let spent: u64 = [11, 12]
        .iter()
        .filter_map(|&i| fields.get(i)?.parse::<u64>().ok())
        .sum();
    Duration::from_nanos(spent.saturating_mul(1_000_000_000) / ticks.max(1))
}

/// The robot's node, listening on a free loopback port, shared memory on or off.
fn robot_node(name: &str, shared_memory: bool) -> (Node, String) {
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let mut config = coolbot_zenoh::peer_config(std::slice::from_ref(&endpoint), &[], false)
        .expect("a configuration");
    config
        .insert_json5(
            "transport/shared_memory/enabled",
            if shared_memory { "true" } else { "false" },
        )
        .expect("the shared-memory setting");
    let node = Node::open(name, config)
        .expect("the node opens")
        .with_state_directory(None);
    (node, endpoint)
}

/// The vision system running: its camera on a fresh drivers process, its detector
/// here, images arriving.
struct Running {
    node: Arc<Node>,
    drivers: NodeProcess,
    system: System,
    camera: Handle,
    detector: Handle,
    _placer: coolbot::remote::Installed,
}

fn start(name: &str, shared_memory: bool) -> Running {
    let (node, endpoint) = robot_node(name, shared_memory);
    let node = Arc::new(node);
    let drivers = NodeProcess::start(
        env!("CARGO_BIN_EXE_drivers-under-test"),
        &["--node", "drivers", "--serve", "--connect", &endpoint],
        "drivers",
        &node,
    );
    let placer = Placer::new(Arc::clone(&node), registry()).install();
    let mut system = System::new();
    let vision = system
        .add(vision::component("vision", Parts).expect("the vision system builds"))
        .expect("added");
    system.run_all().expect("runs");
    let camera = vision.instance("camera").expect("the camera's proxy");
    let detector = vision.instance("detector").expect("the detector");
    // Warm-up: a second of images.
    assert!(
        wait_until(PATIENCE, || counted(&detector.snapshot(), "seen") >= 30),
        "no images reach the detector"
    );
    Running {
        node,
        drivers,
        system,
        camera,
        detector,
        _placer: placer,
    }
}

fn measure(running: &Running, window: Duration, ticks: u64) -> Window {
    let drivers_pid = running.drivers.id();
    let robot_pid = std::process::id();
    let counts = || {
        (
            counted(&running.camera.snapshot(), "frames"),
            counted(&running.detector.snapshot(), "seen"),
        )
    };
    let (sent0, seen0) = counts();
    let (robot0, drivers0) = (
        process_cpu(robot_pid, ticks),
        process_cpu(drivers_pid, ticks),
    );
    let started = Instant::now();
    std::thread::sleep(window);
    let (robot1, drivers1) = (
        process_cpu(robot_pid, ticks),
        process_cpu(drivers_pid, ticks),
    );
    let wall = started.elapsed();
    let (sent1, seen1) = counts();
    Window {
        sent: sent1.saturating_sub(sent0),
        seen: seen1.saturating_sub(seen0),
        bad: counted(&running.detector.snapshot(), "bad"),
        robot: robot1.saturating_sub(robot0),
        drivers: drivers1.saturating_sub(drivers0),
        wall,
    }
}

fn stop(running: Running) {
    let Running {
        node,
        drivers,
        system,
        _placer,
        ..
    } = running;
    let report = system.shutdown();
    assert!(report.clean(), "shutdown: {report:?}");
    drop(_placer);
    drop(drivers);
    drop(node);
}

fn ms(d: Duration) -> String {
    format!("{:.2} ms", d.as_secs_f64() * 1e3)
}

fn main() {
    if std::env::args().any(|arg| arg == "--list") {
        println!("camera: benchmark");
        return;
    }
    let quick = std::env::args().any(|arg| arg == "--quick")
        || std::env::var("COOLBOT_BENCH_QUICK").is_ok_and(|v| !v.is_empty() && v != "0");
    let window = if quick {
        Duration::from_secs(3)
    } else {
        Duration::from_secs(10)
    };
    let ticks = clock_ticks();
    let rounds = 2;
    let mut shared = Vec::new();
    let mut linked = Vec::new();
    for round in 0..rounds {
        for shared_memory in [true, false] {
            let name = format!(
                "robot-{round}-{}",
                if shared_memory { "shm" } else { "link" }
            );
            let running = start(&name, shared_memory);
            let measured = measure(&running, window, ticks);
            let received = running.node.shared_memory().received;
            stop(running);
            if shared_memory {
                assert!(received > 0, "no image arrived in shared memory");
                shared.push(measured);
            } else {
                assert_eq!(received, 0, "an image arrived in shared memory with it off");
                linked.push(measured);
            }
        }
    }
    let sum = |windows: &[Window], f: fn(&Window) -> Duration| -> Duration {
        windows.iter().map(f).sum()
    };
    let total = |windows: &[Window]| -> Window {
        Window {
            sent: windows.iter().map(|w| w.sent).sum(),
            seen: windows.iter().map(|w| w.seen).sum(),
            bad: windows.iter().map(|w| w.bad).sum(),
            robot: sum(windows, |w| w.robot),
            drivers: sum(windows, |w| w.drivers),
            wall: sum(windows, |w| w.wall),
        }
    };
    let (s, l) = (total(&shared), total(&linked));
    let ratio = |a: Duration, b: Duration| a.as_secs_f64() / b.as_secs_f64().max(1e-12);
    println!(
        "### A camera in a process of its own: 640 x 480 RGB at 30 Hz to a detector ({} run, {rounds} windows of {:?} per side, alternated)\n",
        if quick { "quick" } else { "full" },
        window
    );
    println!("| figure | shared memory | over the link | ratio |");
    println!("|---|---|---|---|");
    for (figure, a, b) in [
        (
            "CPU per image, both processes",
            s.per_image(s.robot + s.drivers),
            l.per_image(l.robot + l.drivers),
        ),
        (
            "CPU per image, the drivers process (camera)",
            s.per_image(s.drivers),
            l.per_image(l.drivers),
        ),
        (
            "CPU per image, the robot's process (detector)",
            s.per_image(s.robot),
            l.per_image(l.robot),
        ),
    ] {
        println!("| {figure} | {} | {} | {:.2}x |", ms(a), ms(b), ratio(a, b));
    }
    for (side, w) in [("shared memory", &s), ("over the link", &l)] {
        println!(
            "\n{side}: the camera sent {} images, the detector took {} ({:.1} a second), {} damaged; CPU {:.1} % of a core",
            w.sent,
            w.seen,
            w.seen as f64 / w.wall.as_secs_f64(),
            w.bad,
            100.0 * (w.robot + w.drivers).as_secs_f64() / w.wall.as_secs_f64()
        );
    }
    assert_eq!(s.bad + l.bad, 0, "damaged images");
}
