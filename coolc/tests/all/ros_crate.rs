//! Generated crates with ROS 2 message types (`import ros`) build clippy-clean, are
//! rustfmt-clean and run: a `LaserScan` goes through a port, and through a converter
//! into the project's own packet; the CDR of the generated types (`LaserScan`, `Imu`,
//! `Odometry`, and test types with every `.msg` feature) reads in rosbags to the
//! values set and rosbags' bytes read back to the same values (`tests/data/ros_robot`).
//!
//! The Python with rosbags is `$COOLBOT_PYTHON`, else `target/pyenv/bin/python`;
//! `.ci/run` makes it. Without it the rosbags test fails, saying how to set it up.

use crate::common;

use std::ffi::OsStr;
use std::path::{Path, PathBuf};

use common::{compile_with, data, fill_check_and_run_with_env};

const SETUP: &str = "the ROS 2 interoperability tests need a Python with rosbags 0.11:
    python3 -m venv target/pyenv
    target/pyenv/bin/pip install rosbags==0.11.9
then run the tests from the repository root, or set COOLBOT_PYTHON to that python";

fn python() -> PathBuf {
    if let Some(python) = std::env::var_os("COOLBOT_PYTHON") {
        return python.into();
    }
    let venv = Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/pyenv/bin/python");
    if venv.exists() {
        return venv;
    }
    panic!("COOLBOT_PYTHON is not set and target/pyenv does not exist: {SETUP}");
}

/// Copies the `.msg` packages under `from` into `to`.
fn copy_packages(from: &Path, to: &Path) {
    for package in std::fs::read_dir(from).unwrap().flatten() {
        if !package.path().is_dir() {
            continue;
        }
        let msg = to.join(package.file_name()).join("msg");
        std::fs::create_dir_all(&msg).unwrap();
        for file in std::fs::read_dir(package.path().join("msg"))
            .unwrap()
            .flatten()
        {
            std::fs::copy(file.path(), msg.join(file.file_name())).unwrap();
        }
    }
}

#[test]
fn a_robot_sends_ros_types_through_ports_and_speaks_cdr_with_rosbags() {
    let python = python();
    let dir = tempfile::tempdir().unwrap();
    // The test types: `coolbot_test` (every `.msg` feature, also hashed against
    // rosbags in `ros_rosbags.rs`) and `robot_msgs` (`char`, keyword field names).
    let ros = dir.path().join("ros");
    copy_packages(&data("ros"), &ros);
    copy_packages(&data("ros_robot/ros"), &ros);
    let description = dir.path().join("robot.cool");
    std::fs::copy(data("ros_robot/robot.cool"), &description).unwrap();
    let krate = dir.path().join("robot");
    compile_with(
        &description,
        &krate,
        "robot",
        &coolc::ros::Search::new().with_dir(&ros),
    );
    let manifest = krate.join("Cargo.toml");
    let mut text = std::fs::read_to_string(&manifest).unwrap();
    text.push_str("\n[dev-dependencies]\nserde_json = \"1\"\n");
    std::fs::write(&manifest, text).unwrap();
    fill_check_and_run_with_env(
        &krate,
        "ros_robot",
        &["laser.rs", "planner.rs", "logger.rs", "converters.rs"],
        &[
            "a_scan_reaches_the_planner_through_its_converter_and_the_logger_as_sent",
            "the_laser_alone_sends_its_scans_in_its_harness",
            "each_type_carries_its_names_hash_constants_and_defaults",
            "a_value_over_a_bound_of_its_msg_is_refused_when_decoded",
            "cdr_of_the_generated_types_reads_in_rosbags_and_back",
        ],
        &[
            ("COOLBOT_PYTHON", python.as_os_str()),
            ("COOLBOT_TEST_MSGS", OsStr::new(&ros)),
        ],
    );
}

/// The fenced blocks of `text` under the heading `heading` (up to the next heading of
/// its level): `(info string, body)`.
fn blocks_under(text: &str, heading: &str) -> Vec<(String, String)> {
    let start = text
        .find(&format!("\n{heading}\n"))
        .unwrap_or_else(|| panic!("no section {heading:?}"));
    let rest = &text[start + heading.len() + 2..];
    let end = rest.find("\n## ").unwrap_or(rest.len());
    let mut blocks = Vec::new();
    let mut open: Option<(String, String)> = None;
    for line in rest[..end].lines() {
        match (&mut open, line.strip_prefix("```")) {
            (None, Some(info)) => open = Some((info.to_owned(), String::new())),
            (Some(_), Some(_)) => blocks.extend(open.take()),
            (Some((_, body)), None) => {
                body.push_str(line);
                body.push('\n');
            }
            (None, None) => {}
        }
    }
    blocks
}

#[test]
fn the_imu_description_of_the_ros_docs_checks_builds_and_runs() {
    // `docs/ros2.md`, "A description with ROS 2 types": its description imports
    // `sensor_msgs/msg/Imu` and converts it to a packet of its own; its Rust blocks
    // (each opening with the comment `// <path>`) are the crate's files.
    let docs = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/ros2.md");
    let text = std::fs::read_to_string(docs).unwrap();
    let blocks = blocks_under(&text, "## A description with ROS 2 types");
    let dir = tempfile::tempdir().unwrap();
    let description = dir.path().join("navigation.cool");
    let cool: Vec<&String> = blocks
        .iter()
        .filter(|(info, _)| info == "cool")
        .map(|(_, body)| body)
        .collect();
    assert_eq!(cool.len(), 1, "one description in the section");
    std::fs::write(&description, cool[0]).unwrap();
    let krate = dir.path().join("imu-nav");
    compile_with(&description, &krate, "imu-nav", &coolc::ros::Search::new());
    let mut files = Vec::new();
    for (_, body) in blocks.iter().filter(|(info, _)| info == "rust") {
        let path = body
            .lines()
            .next()
            .and_then(|line| line.strip_prefix("// "))
            .unwrap_or_else(|| panic!("a rust block opens with `// <path>`:\n{body}"));
        let file = krate.join(path);
        std::fs::create_dir_all(file.parent().unwrap()).unwrap();
        std::fs::write(&file, body).unwrap();
        files.push(path.to_owned());
    }
    assert_eq!(
        files,
        [
            "src/converters.rs",
            "src/imu_driver.rs",
            "src/compass.rs",
            "tests/navigation.rs"
        ]
    );
    common::cargo(&krate, &["fmt", "--check"]);
    common::lint(&krate);
    let output = common::cargo_linted(&krate, &["test", "--test", "navigation"]);
    for test in [
        "the_compass_turns_with_the_imu",
        "an_imu_reading_is_what_ros_2_sends",
    ] {
        assert!(output.contains(&format!("test {test} ... ok")), "{output}");
    }
}
