//! Our RIHS01 hashes against an implementation we did not write: rosbags' (PyPI,
//! 0.11.x), for every shipped type (its built-in ROS 2 Jazzy type store) and for test
//! types with every `.msg` feature (registered in rosbags from the same `.msg` text).
//!
//! The Python with rosbags is `$COOLBOT_PYTHON`, else `target/pyenv/bin/python`;
//! `.ci/run` makes it. Without it these tests fail, saying how to set it up.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use coolc::ast::Span;
use coolc::ros::{Search, TypeName, Wanted, load};
use coolc::{RenderOptions, SourceMap};

const SETUP: &str = "the ROS 2 interoperability tests need a Python with rosbags 0.11:
    python3 -m venv target/pyenv
    target/pyenv/bin/pip install rosbags==0.11.9
then run the tests from the repository root, or set COOLBOT_PYTHON to that python";

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn python() -> PathBuf {
    if let Some(python) = std::env::var_os("COOLBOT_PYTHON") {
        return python.into();
    }
    let venv = root().join("target/pyenv/bin/python");
    if venv.exists() {
        return venv;
    }
    panic!("COOLBOT_PYTHON is not set and target/pyenv does not exist: {SETUP}");
}

/// rosbags' hashes of `names`, after registering `register` (type name to `.msg` text)
/// in its Jazzy type store.
fn rosbags_hashes(
    register: &BTreeMap<String, String>,
    names: &[String],
) -> BTreeMap<String, String> {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/ros/rosbags_hash.py");
    let python = python();
    let mut child = Command::new(&python)
        .arg(&script)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|error| panic!("cannot run {}: {error}; {SETUP}", python.display()));
    let request = serde_json::json!({ "register": register, "hash": names });
    child
        .stdin
        .take()
        .unwrap()
        .write_all(request.to_string().as_bytes())
        .unwrap();
    let output = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        output.status.success(),
        "{} failed: {stderr}\n{SETUP}",
        python.display()
    );
    let answer: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    let version = answer["rosbags"].as_str().unwrap();
    assert!(version.starts_with("0.11."), "rosbags {version}; {SETUP}");
    serde_json::from_value(answer["hashes"].clone()).unwrap()
}

/// Our hashes of `names` (each looked up through `search`), and each one's hashed
/// JSON for messages.
fn our_hashes(search: &Search, names: &[String]) -> BTreeMap<String, (String, String)> {
    let mut sources = SourceMap::new();
    let wanted: Vec<Wanted<'_>> = names
        .iter()
        .map(|name| Wanted {
            name,
            file: sources.add(format!("{name}.cool"), name.as_str()),
            span: Span::new(0, name.len()),
        })
        .collect();
    let interfaces = load(search, &wanted, &mut sources, &|path: &Path| {
        std::fs::read_to_string(path)
    });
    assert!(
        !interfaces.has_errors(),
        "{}",
        coolc::diagnostics::render(&sources, &interfaces.diagnostics, RenderOptions::plain())
    );
    names
        .iter()
        .map(|name| {
            let description = interfaces
                .description(&TypeName::parse(name).unwrap())
                .unwrap();
            let hash = coolc::ros::TypeHash::of(&description).to_string();
            (
                name.clone(),
                (hash, coolc::ros::hash::hashed_json(&description)),
            )
        })
        .collect()
}

fn assert_same(ours: &BTreeMap<String, (String, String)>, theirs: &BTreeMap<String, String>) {
    assert_eq!(ours.len(), theirs.len());
    for (name, (hash, json)) in ours {
        assert_eq!(
            Some(hash),
            theirs.get(name),
            "{name}: ours differs from rosbags'; we hashed {json}"
        );
    }
}

#[test]
fn every_shipped_type_hashes_as_rosbags_jazzy_store_does() {
    let names: Vec<String> = coolc::ros::shipped::names()
        .map(|name| name.to_string())
        .collect();
    assert_eq!(names.len(), 17);
    let ours = our_hashes(&Search::new(), &names);
    let theirs = rosbags_hashes(&BTreeMap::new(), &names);
    assert_same(&ours, &theirs);
    // One known value, so that a change in both would still be seen.
    assert_eq!(
        ours["sensor_msgs/msg/LaserScan"].0,
        "RIHS01_64c191398013af96509d518dac71d5164f9382553fce5c1f8cca5be7924bd828"
    );
}

#[test]
fn types_with_every_feature_hash_as_rosbags_does() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/ros");
    let types = ["Everything", "Inner", "Nothing"];
    let register: BTreeMap<String, String> = types
        .iter()
        .map(|name| {
            let path = dir.join(format!("coolbot_test/msg/{name}.msg"));
            let text = std::fs::read_to_string(&path).unwrap();
            (format!("coolbot_test/msg/{name}"), text)
        })
        .collect();
    let names: Vec<String> = register.keys().cloned().collect();
    let ours = our_hashes(&Search::new().with_dir(&dir), &names);
    let theirs = rosbags_hashes(&register, &names);
    assert_same(&ours, &theirs);
}
