//! A driver in a process of its own on the same host: the robot's compound (this
//! process, node `robot`) has `instance camera: NativeDriver on "drivers";`, and the
//! node `drivers` is another process (`drivers-under-test --node drivers --serve`,
//! as the starter `main` runs one). When that process dies, whether killed with
//! `kill -9` or of a segmentation fault in the driver's native code, the robot lives
//! on: the death is a fault of the camera's proxy, the compound's spare stands in, and
//! when a drivers process is started again the recovery queue builds the camera there.

use std::os::unix::process::ExitStatusExt;
use std::sync::Arc;

use coolbot::{Command, Handle, State, Step, System, Value};
use coolbot_zenoh::ctl::Ctl;
use coolbot_zenoh::{Node, Placer};
use coolbot_zenoh_tests::camera::Parts as VisionParts;
use coolbot_zenoh_tests::dying::{counted, wait_step};
use coolbot_zenoh_tests::generated::{camera_rig, vision};
use coolbot_zenoh_tests::isolation::{Parts, registry};
use coolbot_zenoh_tests::support::{NodeProcess, PATIENCE, node};

/// SIGKILL and SIGSEGV, as `ExitStatus::signal` reports them.
const SIGKILL: i32 = 9;
const SIGSEGV: i32 = 11;

/// The drivers process, connected to the robot at `endpoint`; the robot sees it.
fn drivers(endpoint: &str, robot: &Node) -> NodeProcess {
    NodeProcess::start(
        env!("CARGO_BIN_EXE_drivers-under-test"),
        &["--node", "drivers", "--serve", "--connect", endpoint],
        "drivers",
        robot,
    )
}

fn frames(handle: &Handle) -> u64 {
    counted(&handle.snapshot(), "frames")
}

/// Waits until the component of `handle` runs and has counted more frames than now.
fn streams(handle: &Handle, what: &str) {
    let before = frames(handle);
    handle
        .wait_for(
            |m| m.state == State::Running && counted(m, "frames") > before + 3,
            PATIENCE,
        )
        .unwrap_or_else(|timeout| panic!("{what} streams: {timeout}"));
}

/// The cameras the drivers process runs for the robot, `(path, state)`.
fn cameras(ctl: &Ctl) -> Vec<(String, State)> {
    ctl.components(Some("drivers"))
        .expect("the drivers node lists")
        .into_iter()
        .filter(|l| {
            l.path.starts_with(&format!(
                "{}rig-camera-",
                coolbot_zenoh::keys::namespace("robot")
            ))
        })
        .map(|l| (l.path, l.monitor.state))
        .collect()
}

/// The robot (this process, node `robot`) with a drivers process, and the rig
/// running: its camera on `drivers`, streaming. The rig, the path of the camera
/// built there, and the drivers process.
struct Robot {
    node: Arc<Node>,
    endpoint: String,
    system: System,
    rig: Handle,
    _placer: coolbot::remote::Installed,
}

fn robot_with_drivers() -> (Robot, NodeProcess, String) {
    let (node, endpoint) = node("robot", &[]);
    let node = Arc::new(node);
    let process = drivers(&endpoint, &node);
    let placer = Placer::new(Arc::clone(&node), registry()).install();
    let mut system = System::new();
    let rig = system
        .add(camera_rig::component("rig", Parts).expect("the rig builds"))
        .expect("added");
    system.run_all().expect("runs");
    streams(&rig.instance("camera").expect("the proxy"), "the camera");
    let built = cameras(&Ctl::new(node.session().clone(), PATIENCE));
    assert_eq!(built.len(), 1, "one camera on `drivers`: {built:?}");
    let robot = Robot {
        node,
        endpoint,
        system,
        rig,
        _placer: placer,
    };
    (robot, process, built[0].0.clone())
}

/// The drivers process is gone: the camera's proxy fails on the loss of its node (its
/// connections closed by the kernel, its liveliness token withdrawn at once, not after
/// a silence), the spare streams, and the robot runs on. A drivers process started
/// again gets the camera back: a new generation, streaming through the proxy.
fn substituted_then_built_again(robot: Robot, first: &str) {
    let Robot {
        node,
        endpoint,
        system,
        rig,
        _placer,
    } = robot;
    let detail = wait_step(&rig, "camera", |s| *s == Step::Failed, "the proxy fails");
    assert!(
        detail.contains("node `drivers` is lost"),
        "the proxy fails on the loss of the node: {detail}"
    );
    wait_step(
        &rig,
        "camera",
        |s| matches!(s, Step::Substituted { by } if by == "spare"),
        "the spare stands in",
    );
    streams(&rig.instance("spare").expect("the spare"), "the spare");
    assert_eq!(rig.state(), State::Running, "the robot runs on");

    let _again = drivers(&endpoint, &node);
    wait_step(
        &rig,
        "camera",
        |s| *s == Step::Recovered,
        "the camera is built again",
    );
    streams(
        &rig.instance("camera").expect("the proxy"),
        "the camera again",
    );
    let now = cameras(&Ctl::new(node.session().clone(), PATIENCE));
    assert!(
        now.iter()
            .any(|(path, state)| path != first && *state == State::Running),
        "a new generation runs on `drivers`: {now:?}"
    );
    rig.instance("spare")
        .expect("the spare")
        .wait_for(|m| m.state == State::Ready, PATIENCE)
        .unwrap_or_else(|timeout| panic!("the spare stands by again: {timeout}"));
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}

#[test]
fn a_drivers_process_killed_with_kill_9_is_substituted_and_its_driver_built_again_when_it_is_back()
{
    let (robot, process, first) = robot_with_drivers();
    let status = process.kill();
    assert_eq!(status.signal(), Some(SIGKILL), "{status:?}");
    substituted_then_built_again(robot, &first);
}

#[test]
fn a_driver_that_segfaults_ends_only_its_process_and_is_substituted_then_built_again() {
    let (robot, process, first) = robot_with_drivers();
    // Through the proxy, as any command: the driver's next period writes through a
    // null pointer. That period may end the process before its node answers the
    // command: then the answer is a rejection that says so.
    let told = robot
        .rig
        .instance("camera")
        .expect("the proxy")
        .command(Command::Set("crash".to_owned(), Value::Bool(true)));
    if let Err(rejected) = told {
        assert!(
            rejected.reason.contains("node `drivers`"),
            "only the node's death keeps the answer back: {rejected:?}"
        );
    }
    let status = process.wait_end();
    assert_eq!(
        status.signal(),
        Some(SIGSEGV),
        "the drivers process dies of a segmentation fault: {status:?}"
    );
    substituted_then_built_again(robot, &first);
}

/// A camera (`cool/camera.cool`) in the drivers process streams its 640 x 480 RGB
/// images to a detector in the robot's process: each image arrives whole, through
/// shared memory (the two nodes are on one host), counted by the robot's node as
/// received there, and read in place.
#[test]
fn a_camera_in_the_drivers_process_streams_whole_images_through_shared_memory() {
    let (node, endpoint) = node("robot", &[]);
    let node = Arc::new(node);
    let _drivers = drivers(&endpoint, &node);
    let placer = Placer::new(Arc::clone(&node), registry()).install();
    let mut system = System::new();
    let vision = system
        .add(vision::component("vision", VisionParts).expect("the vision system builds"))
        .expect("added");
    system.run_all().expect("runs");
    let detector = vision.instance("detector").expect("the detector");
    detector
        .wait_for(|m| counted(m, "seen") >= 5, PATIENCE)
        .unwrap_or_else(|timeout| panic!("images reach the detector: {timeout}"));
    assert_eq!(counted(&detector.snapshot(), "bad"), 0, "every image whole");
    assert!(
        node.shared_memory().received >= 5,
        "the images came through shared memory: {:?}",
        node.shared_memory()
    );
    // Read in place, in shared memory (the camera fills loans of its node's pool).
    assert!(
        counted(&detector.snapshot(), "lent") >= 5,
        "images read in place: {:?}",
        detector.snapshot()
    );
    let report = system.shutdown();
    assert!(report.clean(), "shutdown: {report:?}");
    drop(placer);
}
