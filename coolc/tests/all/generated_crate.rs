//! The generated crate for the examples (MotionController, RangeServer, MobileBase)
//! with filled-in stubs builds clippy-clean under `-D warnings`, is rustfmt-clean,
//! and runs on the runtime: components start, move through their user automata,
//! exchange packets over the connections `MobileBase` declares (one through a
//! converter), and publish variables on their monitoring ports; a compound exporting
//! poster, tick and pull outputs is read as its atomic instance would be.

use crate::common;

use common::{compile, copy_descriptions, data, fill_check_and_run, lint};

#[test]
fn generated_crate_builds_and_runs() {
    let dir = tempfile::tempdir().unwrap();
    let descriptions = dir.path().join("cool");
    let krate = dir.path().join("fleet");
    std::fs::create_dir_all(&descriptions).unwrap();
    copy_descriptions(&descriptions);
    compile(&descriptions.join("mobile_base.cool"), &krate, "fleet");

    // The untouched stubs (SimRangeServer, Gyro) must build as generated.
    fill_check_and_run(
        &krate,
        "filled",
        &[
            "range_server.rs",
            "planner.rs",
            "converters.rs",
            "motion_controller.rs",
            "follower.rs",
        ],
        &[
            "mobile_base_instances_run_and_talk",
            "a_range_server_alone_in_its_harness_streams_and_retries_on_the_virtual_clock",
            "a_planner_answers_a_pull_and_a_follower_gets_its_answer_in_their_harnesses",
        ],
    );
}

/// `extern packet X = "path";` lines rewritten to a std type, so a fixture that names
/// crates the test cannot fetch still builds.
fn with_std_externs(text: &str) -> String {
    text.lines()
        .map(
            |line| match line.trim_start().strip_prefix("extern packet ") {
                Some(rest) => {
                    let name = rest.split('=').next().unwrap_or_default().trim();
                    format!("extern packet {name} = \"std::vec::Vec<u8>\";\n")
                }
                None => format!("{line}\n"),
            },
        )
        .collect()
}

#[test]
fn every_construct_generates_a_clippy_clean_crate() {
    // The front end's fixture using every construct of the language, generated with
    // its untouched stubs: the whole crate must build warning-free.
    let dir = tempfile::tempdir().unwrap();
    let ok = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/data/ok");
    for name in ["every_construct.cool", "types.cool"] {
        let text = std::fs::read_to_string(ok.join(name)).unwrap();
        std::fs::write(dir.path().join(name), with_std_externs(&text)).unwrap();
    }
    let krate = dir.path().join("every");
    compile(&dir.path().join("every_construct.cool"), &krate, "every");
    lint(&krate);
}

#[test]
fn a_compound_hierarchy_runs_and_survives_a_leaf_fault() {
    // `Plant` nests the `Cell` compound (a substitute, exported ports, mapped
    // variables, supervisor rules over own and instance variables); `Probe` has rules
    // of every form over every readable type; `Gate` moves on a packet at an exported
    // input; `Pair` is a redundant group; `Ticker`'s rule reads a `local` variable
    // its periodic section changes; `Swap`'s rule over a mapped variable reads the
    // substitute standing in; `Source` keeps a `local`; `Labels` carries an extern
    // packet; `Slowpoke` has a timing block of its own. The filled user files and the run tests are
    // in `tests/data/plant`.
    let dir = tempfile::tempdir().unwrap();
    let description = dir.path().join("plant.cool");
    std::fs::copy(data("plant/plant.cool"), &description).unwrap();
    let krate = dir.path().join("plant");
    compile(&description, &krate, "plant");
    fill_check_and_run(
        &krate,
        "plant",
        &[
            "source.rs",
            "worker.rs",
            "sink.rs",
            "cell.rs",
            "plant.rs",
            "gauge.rs",
            "probe.rs",
            "gate.rs",
            "pair.rs",
            "ticker.rs",
            "swap.rs",
            "restarter.rs",
            "labeler.rs",
            "reader.rs",
            "labels.rs",
            "slowpoke.rs",
        ],
        &[
            "a_failed_leaf_is_substituted_and_the_supervisors_follow",
            "rules_read_every_kind_of_value",
            "a_supervisor_moves_on_a_packet_at_an_exported_input",
            "a_redundant_group_keeps_the_stream_when_a_member_fails",
            "a_rule_reading_a_local_variable_fires_after_the_section_that_changed_it",
            "a_rule_over_a_mapped_variable_reads_the_substitute_standing_in",
            "the_restart_budget_of_the_description_bounds_the_restarts",
            "an_atomic_local_variable_is_kept_between_sections_and_never_published",
            "an_extern_packet_is_carried_like_a_packet",
            "a_compounds_own_timing_applies_to_its_thread_sections_and_quality",
        ],
    );
}

#[test]
fn arrays_of_any_length_build_default_and_round_trip() {
    // `tests/data/arrays`: arrays longer than serde's and `Default`'s 32 elements in
    // packets (plain, nested, optional, in lists, of strings), in a configuration and
    // in variables, with and without written defaults, and `[u8]` as one slice; the
    // run tests check defaults, serde round trips (a `[u8]` in the bytes of a
    // sequence) and a running system that carries them.
    let dir = tempfile::tempdir().unwrap();
    let description = dir.path().join("arrays.cool");
    std::fs::copy(data("arrays/arrays.cool"), &description).unwrap();
    let krate = dir.path().join("arrays");
    compile(&description, &krate, "arrays");
    fill_check_and_run(
        &krate,
        "arrays",
        &["scanner.rs", "recorder.rs", "rig.rs"],
        &[
            "long_arrays_get_their_defaults",
            "long_arrays_round_trip_through_serde",
            "byte_lists_encode_as_sequences_of_their_bytes_do",
            "long_arrays_flow_through_a_running_system",
            "a_supervisor_sets_a_long_array_through_its_typed_handle",
        ],
    );
}

#[test]
fn compounds_with_converters_nest_three_levels_deep() {
    // `tests/data/nest`: `Fleet` nests `Robot`, which nests `Base` (with an override
    // of its mapped `gain`), whose follower reaches its drive through a converter.
    let dir = tempfile::tempdir().unwrap();
    let description = dir.path().join("nest.cool");
    std::fs::copy(data("nest/nest.cool"), &description).unwrap();
    let krate = dir.path().join("nest");
    compile(&description, &krate, "nest");
    fill_check_and_run(
        &krate,
        "nest",
        &["follower.rs", "drive.rs", "converters.rs"],
        &["converters_reach_compounds_nested_three_deep"],
    );
}

#[test]
fn adaptation_blocks_take_effect_at_run_time() {
    // `tests/data/tune`: a tuned component degrades, one with `adaptation { off; }`
    // keeps its period under the same violations, a compound's instance blocks
    // replace their components' tuning (seen in the detectors' settling periods), and
    // a compound turned off degrades none of its late instances.
    let dir = tempfile::tempdir().unwrap();
    let description = dir.path().join("tune.cool");
    std::fs::copy(data("tune/tune.cool"), &description).unwrap();
    let krate = dir.path().join("tune");
    compile(&description, &krate, "tune");
    fill_check_and_run(
        &krate,
        "tune",
        &["slow.rs", "frozen.rs", "cell.rs", "still.rs"],
        &[
            "off_means_no_degradation_and_tuning_sets_the_detector",
            "instance_blocks_replace_their_components_tuning",
            "a_compound_turned_off_degrades_none_of_its_instances",
        ],
    );
}

#[test]
fn a_compound_exports_poster_tick_and_pull_outputs() {
    // `Unit` exports its sensor's poster output, tick output and `pull` data output;
    // `Station` connects a watcher to them as it would to the sensor. The filled user
    // files and the run test are in `tests/data/exports`.
    let dir = tempfile::tempdir().unwrap();
    let description = dir.path().join("exports.cool");
    std::fs::copy(data("exports/exports.cool"), &description).unwrap();
    let krate = dir.path().join("exports");
    compile(&description, &krate, "exports");
    fill_check_and_run(
        &krate,
        "exports",
        &["sensor.rs", "watcher.rs", "unit.rs", "station.rs"],
        &["a_watcher_reads_a_compound_as_it_reads_an_atomic_sensor"],
    );
}

#[test]
fn a_warehouse_robot_written_from_the_reference_builds_and_runs() {
    // Four description files (types, sensors, drive, warehouse) importing each other:
    // a 72-beam scan packet, doc comments in timing blocks, a converter inside the
    // nested `Base` of a three-level hierarchy, a camera fanning out to two redundant
    // detectors' queues, an exported poster read by a console outside the robot, a
    // lidar with a spare, and a supervisor that stops the base by suspending it. The
    // filled user files and the run test are in `tests/data/warehouse`.
    let dir = tempfile::tempdir().unwrap();
    let descriptions = dir.path().join("cool");
    std::fs::create_dir_all(&descriptions).unwrap();
    for name in ["types.cool", "sensors.cool", "drive.cool", "warehouse.cool"] {
        std::fs::copy(data("warehouse").join(name), descriptions.join(name)).unwrap();
    }
    let krate = dir.path().join("warehouse");
    compile(&descriptions.join("warehouse.cool"), &krate, "warehouse");
    fill_check_and_run(
        &krate,
        "warehouse",
        &[
            "lidar.rs",
            "camera.rs",
            "detector.rs",
            "pan_tilt.rs",
            "follower.rs",
            "drive.rs",
            "converters.rs",
            "base.rs",
            "perception.rs",
            "navigation.rs",
            "warehouse.rs",
            "console.rs",
        ],
        &["the_warehouse_robot_runs_as_described"],
    );
}

#[test]
fn the_linted_build_of_a_generated_crate_fails_on_a_clippy_warning() {
    // The tests lint generated crates in the build that runs them
    // (`common::gen_cargo_linted`): a crate with a clippy warning (a `clone` of a
    // `Copy` value) must not build there, or that lint would check nothing.
    let dir = tempfile::tempdir().unwrap();
    let krate = dir.path().join("lint-probe");
    std::fs::create_dir_all(krate.join("src")).unwrap();
    std::fs::write(
        krate.join("Cargo.toml"),
        "[package]\nname = \"lint-probe\"\nversion = \"0.1.0\"\nedition = \"2024\"\n",
    )
    .unwrap();
    std::fs::write(
        krate.join("src/lib.rs"),
        "pub fn copied(x: &u32) -> u32 {\n    x.clone()\n}\n",
    )
    .unwrap();
    let output = common::gen_cargo_linted(&krate)
        .args(["build", "--quiet"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success(), "{stderr}");
    assert!(
        stderr.contains("clippy::clone") && stderr.contains("implied by `-D warnings`"),
        "{stderr}"
    );
}
