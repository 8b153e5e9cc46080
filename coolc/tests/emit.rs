//! Snapshots of every file `coolc` emits for the example descriptions (the spec's
//! `MotionController`, the ir/us/bumper `RangeServer` and the compound `MobileBase`,
//! plus the `coolc new` starter, and the example robot's own descriptions in
//! `examples/components`), and determinism of emission.

use std::path::Path;

use coolc::emit::{self, FileKind};
use coolc::ir::RuntimeDep;
use coolc::lower;

fn data(name: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(name)
}

fn lower_fixture(root: &str, package: &str) -> coolc::ir::Crate {
    lower_file(&data(root), package)
}

fn lower_file(root: &Path, package: &str) -> coolc::ir::Crate {
    let checked = coolc::analyze(&[root], &|p: &Path| std::fs::read_to_string(p))
        .checked()
        .unwrap_or_else(|analysis| panic!("{}", analysis.render(coolc::RenderOptions::plain())));
    let options = lower::Options {
        package: package.to_owned(),
        runtime: RuntimeDep::Version("0.1".to_owned()),
        sources: vec![root.file_name().unwrap().to_string_lossy().into_owned()],
        inputs: coolc::fingerprint::inputs(checked.sources().files()),
    };
    lower::lower(&checked, &options)
}

fn snapshot_crate(prefix: &str, krate: &coolc::ir::Crate) {
    let files = emit::emit_crate(krate);
    for file in &files {
        let name = format!("{prefix}__{}", file.path.display()).replace(['/', '.'], "_");
        insta::assert_snapshot!(name, file.contents);
    }
    let listing: Vec<String> = files
        .iter()
        .map(|f| {
            let kind = match f.kind {
                FileKind::Generated => "generated",
                FileKind::User => "user",
                FileKind::Manifest => "manifest",
                FileKind::Starter => "starter",
            };
            format!("{kind:9} {}", f.path.display())
        })
        .collect();
    insta::assert_snapshot!(format!("{prefix}__listing"), listing.join("\n"));
}

#[test]
fn mobile_base_and_its_components() {
    let krate = lower_fixture("mobile_base.cool", "mobile-base");
    snapshot_crate("mobile_base", &krate);
}

/// The example robot's own descriptions (`examples/components`, compiled by the
/// `mobile-base` crate's build script), as `coolc compile` would emit them.
#[test]
fn example_robot() {
    let root =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/components/mobile_base.cool");
    let krate = lower_file(&root, "mobile-base");
    snapshot_crate("example_robot", &krate);
}

#[test]
fn starter_component() {
    let checked = coolc::analyze_text("starter.cool", &coolc::cli::starter_description("Starter"))
        .checked()
        .unwrap_or_else(|analysis| panic!("{}", analysis.render(coolc::RenderOptions::plain())));
    let krate = lower::lower(
        &checked,
        &lower::Options {
            package: "starter".to_owned(),
            runtime: RuntimeDep::Version("0.1".to_owned()),
            sources: vec!["starter.cool".to_owned()],
            inputs: coolc::fingerprint::inputs(checked.sources().files()),
        },
    );
    snapshot_crate("starter", &krate);
    let atomic = &krate.atomics[0];
    insta::assert_snapshot!("starter__filled_component", emit::starter_component(atomic));
    insta::assert_snapshot!("starter__main", emit::starter_main(&krate));
}

#[test]
fn emission_is_deterministic() {
    let first = emit::emit_crate(&lower_fixture("mobile_base.cool", "mobile-base"));
    let second = emit::emit_crate(&lower_fixture("mobile_base.cool", "mobile-base"));
    assert_eq!(first, second);
}

#[test]
fn builder_single_file_holds_every_module() {
    let krate = lower_fixture("mobile_base.cool", "mobile-base");
    let text = emit::single_file(&krate);
    for module in krate.module_names() {
        assert!(
            text.contains(&format!("pub mod {module} {{")),
            "module {module} missing"
        );
    }
    assert!(text.contains("pub fn __cool_from_value"));
    let out = tempfile::tempdir().unwrap();
    let written = coolc::Builder::new()
        .out_dir(out.path())
        .cargo_output(false)
        .compile(&[data("mobile_base.cool")])
        .unwrap();
    let on_disk = std::fs::read_to_string(written).unwrap();
    assert!(on_disk.contains("pub mod motion_controller {"));
    assert!(on_disk.contains("pub trait Behavior"));
}

#[test]
fn builder_finds_ros_types_in_the_directories_given() {
    // `coolbot_test/msg/Everything` is in `tests/data/ros` only.
    let dir = tempfile::tempdir().unwrap();
    let robot = dir.path().join("robot.cool");
    std::fs::write(
        &robot,
        "import ros \"coolbot_test/msg/Everything\";\natomic A { input all: last<Everything>; }\n",
    )
    .unwrap();
    let error = coolc::Builder::new()
        .out_dir(dir.path())
        .cargo_output(false)
        .compile(&[&robot])
        .unwrap_err();
    assert!(
        error
            .to_string()
            .contains("no `.msg` file defines `coolbot_test/msg/Everything`"),
        "{error}"
    );
    let error = coolc::Builder::new()
        .out_dir(dir.path())
        .cargo_output(false)
        .ros_path(dir.path().join("elsewhere"))
        .compile(&[&robot])
        .unwrap_err();
    assert!(
        matches!(error, coolc::builder::BuildError::RosPath { .. }),
        "{error}"
    );
    let written = coolc::Builder::new()
        .out_dir(dir.path())
        .cargo_output(false)
        .ros_path(data("ros"))
        .compile(&[&robot])
        .unwrap();
    let text = std::fs::read_to_string(written).unwrap();
    assert!(text.contains("pub type Everything = ros::coolbot_test::Everything;"));
    assert!(text.contains("impl ::coolbot::ros::RosType for Everything"));
}

#[test]
fn ros_types_with_every_msg_feature() {
    // `tests/data/ros_robot/robot.cool` imports the shipped `LaserScan`, `Imu` and
    // `Odometry` and test types with every `.msg` feature (`tests/data/ros` and
    // `tests/data/ros_robot/ros`): the types module is what `ros_crate.rs` builds,
    // runs and checks against rosbags.
    let search = coolc::ros::Search::new()
        .with_dir(data("ros"))
        .with_dir(data("ros_robot/ros"));
    let root = data("ros_robot/robot.cool");
    let read = |p: &Path| std::fs::read_to_string(p);
    let checked = coolc::analyze_with(&[&root], &read, &|_| Vec::new(), &search)
        .checked()
        .unwrap_or_else(|analysis| panic!("{}", analysis.render(coolc::RenderOptions::plain())));
    let options = lower::Options {
        package: "robot".to_owned(),
        runtime: RuntimeDep::Version("0.1".to_owned()),
        sources: vec!["robot.cool".to_owned()],
        inputs: coolc::fingerprint::inputs(&[]),
    };
    let files = emit::emit_crate(&lower::lower(&checked, &options));
    let types = files
        .iter()
        .find(|f| f.path == Path::new("src/generated/types.rs"))
        .unwrap();
    insta::assert_snapshot!(types.contents);
}

#[test]
fn builder_reports_diagnostics() {
    let out = tempfile::tempdir().unwrap();
    let bad = out.path().join("bad.cool");
    std::fs::write(&bad, "atomic Broken { input x: fifo<Twist>(4) }").unwrap();
    let error = coolc::Builder::new()
        .out_dir(out.path())
        .cargo_output(false)
        .compile(&[&bad])
        .unwrap_err();
    let coolc::builder::BuildError::Diagnostics(text) = error else {
        panic!("expected diagnostics, got {error:?}");
    };
    assert!(text.contains("bad.cool"), "{text}");
}

#[test]
fn builder_names_the_import_a_sibling_file_offers() {
    // As `coolc check` does: an unknown type defined in a `.cool` file next to the
    // one using it gets help naming the import to add.
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("scan.cool"),
        "packet LaserScan { ranges: [f32; 72] }\n",
    )
    .unwrap();
    let robot = dir.path().join("robot.cool");
    std::fs::write(&robot, "atomic Mapper { input scan: last<LaserScan>; }\n").unwrap();
    let error = coolc::Builder::new()
        .out_dir(dir.path().join("out"))
        .cargo_output(false)
        .compile(&[&robot])
        .unwrap_err();
    let coolc::builder::BuildError::Diagnostics(text) = error else {
        panic!("expected diagnostics, got {error:?}");
    };
    let words = text.split_whitespace().collect::<Vec<_>>().join(" ");
    assert!(
        words.contains(
            "`LaserScan` is defined in `scan.cool` next to this file: add `import \"scan.cool\";`"
        ),
        "{text}"
    );
}

/// `adaptation { ... }` blocks (`tests/data/tune`, also compiled and run by
/// `generated_crate.rs`): an atomic component's block in its `component_with`, an
/// instance's block merged with its component's, a compound's block and selector in
/// its builder.
#[test]
fn adaptation_blocks() {
    let krate = lower_fixture("tune/tune.cool", "tune");
    let files = emit::emit_crate(&krate);
    for module in ["slow", "frozen", "cell", "still"] {
        let path = format!("src/generated/{module}.rs");
        let file = files
            .iter()
            .find(|f| f.path == Path::new(&path))
            .unwrap_or_else(|| panic!("{path}"));
        insta::assert_snapshot!(format!("tune__{module}"), file.contents);
    }
}

#[test]
fn every_ok_fixture_emits() {
    // The front end's fixture suite: every description that checks must emit (emission
    // parses every Rust file it writes, so a template bug panics here).
    insta::glob!("../../tests/data/ok", "*.cool", |path| {
        let checked = coolc::analyze(&[path], &|p: &Path| std::fs::read_to_string(p))
            .checked()
            .unwrap_or_else(|analysis| {
                panic!("{}", analysis.render(coolc::RenderOptions::plain()))
            });
        let krate = lower::lower(&checked, &lower::Options::default());
        let files = emit::emit_crate(&krate);
        let manifest = &files[0];
        assert_eq!(manifest.path, Path::new("Cargo.toml"));
        assert_eq!(
            manifest.contents.matches("\nserde = ").count()
                + manifest.contents.matches("\nserde=").count(),
            usize::from(!krate.links_crate("serde"))
        );
        for atomic in &krate.atomics {
            let module = format!("src/generated/{}.rs", atomic.module);
            assert!(
                files.iter().any(|f| f.path == Path::new(&module)),
                "{module}"
            );
        }
    });
}

#[test]
fn doc_comments_without_an_item_go_to_the_spec_rustdoc() {
    // `tests/data/ok/doc_comments.cool` documents every construct: those without a
    // Rust item of their own (timing entries, plan steps, transitions, connections,
    // overrides, ...) are listed after their text in the rustdoc of `SPEC`.
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/data/ok/doc_comments.cool");
    let files = emit::emit_crate(&lower_file(&root, "docs"));
    let text = |name: &str| {
        files
            .iter()
            .find(|f| f.path == Path::new("src/generated").join(name))
            .map(|f| f.contents.clone())
            .unwrap()
    };
    let probe = text("probe.rs");
    let spec_doc = |text: &str| -> Vec<String> {
        let end = text.find("pub static SPEC").unwrap();
        let start = text[..end].rfind("\n\n").unwrap();
        text[start..end]
            .lines()
            .filter(|l| {
                l.starts_with("/// `")
                    || l.starts_with("/// state")
                    || l.starts_with("/// instance")
                    || l.starts_with("/// exception")
            })
            .map(str::to_owned)
            .collect()
    };
    assert_eq!(
        spec_doc(&probe),
        [
            "/// `timing`: How the probe keeps time.",
            "/// `period 10ms..20ms`: Fast enough for the controller.",
            "/// `max_response 5ms`: A section may take this long.",
            "/// `priority 2`: Above the default.",
            "/// `quality full, reduced`: Best first.",
            "/// exception `lost`: `retry 3 every 10ms`: Try again soon.",
            "/// exception `lost`: `goto waiting`: Then wait it out.",
            "/// `automaton`: Probing, or waiting for the sensor.",
            "/// `initial probing`: Start by probing.",
            "/// state `waiting`: `after 1s -> probing`: Give it a second.",
        ]
    );
    // Constructs with an item of their own keep their doc there: ports, sections and
    // `may` rules (after the generated line).
    for item in [
        "    /// Readings, one per period.\n    pub out:",
        "enters the state.\n    ///\n    /// Reset the sensor.\n    fn waiting_entry(",
        "period while in the state.\n    ///\n    /// Read the sensor.\n    fn probing_periodic(",
        "leaves the state.\n    ///\n    /// Clean up.\n    fn waiting_exit(",
        "to stay.\n    ///\n    /// Leave when the sensor is lost.\n    fn probing_choose(",
    ] {
        assert!(probe.contains(item), "{item} not in:\n{probe}");
    }
    let station = text("station.rs");
    assert_eq!(
        spec_doc(&station),
        [
            "/// instance `probe`: `period 20ms`: Slower than its default.",
            "/// instance `a`: `scale = 2.0`: Twice as sensitive.",
            "/// `connect probe.out -> a.readings`: Readings to both meters.",
            "/// `redundant a, b`: Either meter will do.",
            "/// `on error probe: restart`: Restart a failed probe.",
            "/// `recovery`: Keep trying for a minute.",
            "/// `retry every 1s`: Every second.",
            "/// `deadline 60s`: For a minute.",
            "/// `supervisor`: Watching the probe.",
            "/// state `watching`: `when probe.state == running_error -> alarmed`: Leave when the probe fails.",
        ]
    );
    assert!(
        station.contains("    ///\n    /// Count the alarm.\n    fn alarmed_entry("),
        "{station}"
    );
    let meter = text("meter.rs");
    assert_eq!(
        spec_doc(&meter),
        [
            "/// state `idle`: `on readings -> idle`: A reading wakes it up.",
            "/// state `idle`: `after 1s -> idle`: So does a second without one.",
        ]
    );
}

/// The generated modules of a crate (`src/generated/*.rs`), one after the other under
/// their paths: what lowering and the templates make of a description.
fn generated_modules(krate: &coolc::ir::Crate) -> String {
    emit::emit_crate(krate)
        .iter()
        .filter(|f| f.kind == FileKind::Generated)
        .map(|f| format!("==> {}\n{}", f.path.display(), f.contents))
        .collect::<Vec<_>>()
        .join("\n")
}

#[test]
fn generated_modules_of_every_ok_fixture() {
    insta::glob!("../../tests/data", "ok/*.cool", |path| {
        let krate = lower_file(path, "fixture");
        insta::assert_snapshot!(generated_modules(&krate));
    });
}

#[test]
fn every_setting_reaches_the_generated_code() {
    // Every fifo policy (and none), a period range in hertz, a priority, a plan's
    // retry delay, sections with and without their own period, an `after`, every
    // error policy, a restart budget and backoff, a recovery block giving one value
    // of two, and an instance's timing override.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("settings.cool");
    std::fs::write(
        &path,
        "packet P { x: u32 }\n\
         atomic Worker {\n\
             input plain: fifo<P>(4);\n\
             input rejecting: fifo<P>(4, reject);\n\
             input dropping: fifo<P>(8, drop_oldest);\n\
             input blocking: fifo<P>(2, block);\n\
             output out: data<P>;\n\
             timing { period 100Hz..20Hz; max_response 3ms; priority 7; quality full, half; }\n\
             exception slip { retry 3 every 250us; goto idle; }\n\
             automaton {\n\
                 initial idle;\n\
                 state idle { entry; periodic 2kHz; after 1500ms without plain -> busy; }\n\
                 state busy { periodic; on blocking -> idle; }\n\
             }\n\
         }\n\
         compound Cell {\n\
             instance a: Worker;\n\
             instance b: Worker { timing { priority 9; period 50ms; } }\n\
             instance c: Worker;\n\
             instance d: Worker;\n\
             instance spare: Worker substitutes c;\n\
             on error a: propagate;\n\
             on error b: restart;\n\
             on error c: substitute;\n\
             on error d: ignore;\n\
             restart { limit 4 in 90s; backoff 20ms..3s; }\n\
             recovery { deadline 2min; }\n\
         }\n",
    )
    .unwrap();
    let krate = lower_file(&path, "settings");
    insta::assert_snapshot!(generated_modules(&krate));
}

/// A doc comment's text that a Rust comment cannot hold as it is (a character that
/// turns the text around, which rustc denies in comments; a carriage return alone) is
/// written as its escape, and the emitted crate parses.
#[test]
fn doc_comments_keep_no_character_rust_refuses_in_a_comment() {
    let dir = tempfile::tempdir().expect("temporary directory");
    let root = dir.path().join("odd.cool");
    std::fs::write(
        &root,
        "/// Turns \u{202E}around\r here.\natomic Odd {\n    timing { period 10ms; }\n}\n",
    )
    .expect("written");
    let krate = lower_file(&root, "odd");
    let files = emit::emit_crate(&krate);
    let generated: String = files.iter().map(|file| file.contents.as_str()).collect();
    assert!(
        generated.contains(r"Turns \u{202e}around\u{d} here."),
        "{generated}"
    );
    assert!(!generated.contains('\u{202E}') && !generated.contains('\r'));
}
