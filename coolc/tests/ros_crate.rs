//! Generated crates with ROS 2 message types (`import ros`) build clippy-clean, are
//! rustfmt-clean and run: a `LaserScan` goes through a port, and through a converter
//! into the project's own packet; the CDR of the generated types (`LaserScan`, `Imu`,
//! `Odometry`, and test types with every `.msg` feature) reads in rosbags to the
//! values set and rosbags' bytes read back to the same values (`tests/data/ros_robot`).
//!
//! The Python with rosbags is `$COOLBOT_PYTHON`, else `target/pyenv/bin/python`;
//! `.ci/run` makes it. Without it the rosbags test fails, saying how to set it up.

mod common;

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
