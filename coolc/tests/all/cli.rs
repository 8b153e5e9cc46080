//! The `coolc` binary: `--help`, exit codes 0 / 1 / 2, JSON diagnostics, `compile`
//! options, and `coolc new` producing a crate that builds and runs.

use crate::common;

use std::path::Path;
use std::process::{Command, Output};

use common::{cargo, data};

fn coolc(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_coolc"))
        .args(args)
        .current_dir(dir)
        .output()
        .unwrap()
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

const BROKEN: &str = "atomic Broken {\n    input x: fifo<f64>(4)\n}\n";

#[test]
fn help_everywhere() {
    let dir = tempfile::tempdir().unwrap();
    let out = coolc(&["--help"], dir.path());
    assert_eq!(out.status.code(), Some(0));
    let help = text(&out.stdout);
    for command in ["check", "compile", "new", "--message-format"] {
        assert!(help.contains(command), "{command} missing from:\n{help}");
    }
    for command in ["check", "compile", "new"] {
        let out = coolc(&[command, "--help"], dir.path());
        assert_eq!(out.status.code(), Some(0), "{command} --help");
        assert!(
            text(&out.stdout).contains("Usage: coolc"),
            "{command} --help"
        );
    }
    let out = coolc(&["compile", "--help"], dir.path());
    for option in ["--out", "--name", "--runtime-path", "--runtime-version"] {
        assert!(text(&out.stdout).contains(option), "{option}");
    }
}

#[test]
fn ros_types_are_looked_up_in_each_ros_path_given() {
    // `coolbot_test/msg/Everything` is in `tests/data/ros` only.
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("robot.cool"),
        "import ros \"coolbot_test/msg/Everything\";\natomic A { input all: last<Everything>; }\n",
    )
    .unwrap();
    let ros = data("ros");
    let ros = ros.to_str().unwrap();
    let out = coolc(&["check", "robot.cool"], dir.path());
    assert_eq!(out.status.code(), Some(1));
    assert!(
        text(&out.stderr).contains("no `.msg` file defines `coolbot_test/msg/Everything`"),
        "{}",
        text(&out.stderr)
    );
    let out = coolc(
        &[
            "check",
            "--ros-path",
            "elsewhere",
            "--ros-path",
            ros,
            "robot.cool",
        ],
        dir.path(),
    );
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains("--ros-path elsewhere: not a directory"));
    std::fs::create_dir(dir.path().join("elsewhere")).unwrap();
    let out = coolc(
        &[
            "check",
            "--ros-path",
            "elsewhere",
            "--ros-path",
            ros,
            "robot.cool",
        ],
        dir.path(),
    );
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let out = coolc(
        &["compile", "robot.cool", "-o", "out", "--ros-path", ros],
        dir.path(),
    );
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let types = std::fs::read_to_string(dir.path().join("out/src/generated/types.rs")).unwrap();
    assert!(types.contains("pub mod coolbot_test {"), "{types}");
}

#[test]
fn exit_codes() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("broken.cool"), BROKEN).unwrap();
    let ok = data("mobile_base.cool");
    let ok = ok.to_str().unwrap();

    let out = coolc(&["check", ok], dir.path());
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let stderr = text(&out.stderr);
    assert!(
        stderr.contains("coolc: 4 description file(s) checked: no error"),
        "mobile_base.cool and its three imports: {stderr}"
    );
    assert!(stderr.ends_with("checked: no error\n"), "{stderr}");

    let out = coolc(&["check", "broken.cool"], dir.path());
    assert_eq!(out.status.code(), Some(1));
    let stderr = text(&out.stderr);
    assert!(stderr.contains("broken.cool"), "{stderr}");
    assert!(!stderr.contains('\u{1b}'), "colour on a pipe: {stderr}");

    let out = coolc(&["check", "missing.cool"], dir.path());
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains("missing.cool"));

    for usage in [
        &["frobnicate"][..],
        &["check"],
        &["compile", ok],
        &["--message-format", "xml", "check", ok],
    ] {
        let out = coolc(usage, dir.path());
        assert_eq!(out.status.code(), Some(2), "{usage:?}");
    }
    // A failed compile writes nothing.
    let out = coolc(&["compile", "broken.cool", "-o", "out"], dir.path());
    assert_eq!(out.status.code(), Some(1));
    assert!(!dir.path().join("out").exists());
}

#[test]
fn json_diagnostics() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("broken.cool"), BROKEN).unwrap();
    let out = coolc(
        &["check", "--message-format", "json", "broken.cool"],
        dir.path(),
    );
    assert_eq!(out.status.code(), Some(1));
    let stdout = text(&out.stdout);
    let lines: Vec<&str> = stdout.lines().collect();
    assert!(!lines.is_empty());
    for line in lines {
        let value: serde_json::Value = serde_json::from_str(line).unwrap();
        assert!(value.is_object(), "{line}");
        assert!(line.contains("broken.cool"), "{line}");
    }
}

#[test]
fn compile_writes_a_crate() {
    let dir = tempfile::tempdir().unwrap();
    let ok = data("mobile_base.cool");
    let out = coolc(
        &[
            "compile",
            ok.to_str().unwrap(),
            "-o",
            "base",
            "--name",
            "my-base",
            "--runtime-version",
            "0.1",
        ],
        dir.path(),
    );
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let manifest = std::fs::read_to_string(dir.path().join("base/Cargo.toml")).unwrap();
    assert!(manifest.contains("name = \"my-base\""), "{manifest}");
    assert!(manifest.contains("coolbot = \"0.1\""), "{manifest}");
    for file in [
        "src/lib.rs",
        "src/generated/motion_controller.rs",
        "src/motion_controller.rs",
        "build.rs",
    ] {
        assert!(dir.path().join("base").join(file).exists(), "{file}");
    }
    // By default the runtime is this repository's, by path.
    let out = coolc(
        &["compile", ok.to_str().unwrap(), "-o", "base2"],
        dir.path(),
    );
    assert_eq!(out.status.code(), Some(0));
    let manifest = std::fs::read_to_string(dir.path().join("base2/Cargo.toml")).unwrap();
    assert!(manifest.contains("name = \"base2\""), "{manifest}");
    assert!(manifest.contains("coolbot = { path = "), "{manifest}");
}

#[test]
fn new_crate_builds_and_runs() {
    let dir = tempfile::tempdir().unwrap();
    let out = coolc(&["new", "blinker"], dir.path());
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let krate = dir.path().join("blinker");
    assert!(krate.join("components/blinker.cool").exists());

    // The starter description checks and recompiles in place without changes to the
    // filled-in user file.
    let user_file = std::fs::read_to_string(krate.join("src/blinker.rs")).unwrap();
    let out = coolc(&["compile", "components/blinker.cool", "-o", "."], &krate);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    assert_eq!(
        std::fs::read_to_string(krate.join("src/blinker.rs")).unwrap(),
        user_file
    );

    let stdout = cargo(&krate, &["run", "--quiet"]);
    // Each component's monitoring snapshot, in a few lines.
    assert!(
        stdout.contains("blinker: running in `done`, succeeded: counted 10 periods"),
        "{stdout}"
    );

    // The test `coolc new` wrote drives the component in its generated harness.
    assert!(krate.join("tests/blinker.rs").exists());
    let stdout = cargo(&krate, &["test", "--test", "blinker"]);
    assert!(
        stdout.contains("test counts_its_periods_then_finishes ... ok"),
        "{stdout}"
    );

    // A second `new` on the same directory is a usage error.
    let out = coolc(&["new", "blinker"], dir.path());
    assert_eq!(out.status.code(), Some(2));
}

#[test]
fn without_rustfmt_the_output_still_builds() {
    // `RUSTFMT` names a program that does not exist: coolc falls back to
    // `prettyplease` for generated files and the templates' layout for user files.
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_coolc"))
        .args(["new", "plain"])
        .current_dir(dir.path())
        .env("RUSTFMT", dir.path().join("no-such-rustfmt"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let generated =
        std::fs::read_to_string(dir.path().join("plain/src/generated/plain.rs")).unwrap();
    assert!(generated.starts_with("// @generated by coolc"));
    cargo(&dir.path().join("plain"), &["build", "--quiet"]);
}

#[test]
fn new_rejects_names_cargo_rejects() {
    let dir = tempfile::tempdir().unwrap();
    for (name, why) in [
        ("3d", "the name cannot start with a digit"),
        ("type", "it is a Rust keyword"),
        ("", "the name cannot be empty"),
        (
            "my robot",
            "only ASCII letters, digits, `-` and `_` may be used",
        ),
        ("a.b", "only ASCII letters, digits, `-` and `_` may be used"),
        ("-x", "the name must start with a letter or `_`"),
        (
            "test",
            "it is the name of a crate of Rust's standard library",
        ),
        (
            "coolbot",
            "it is the name of a dependency of the generated crate",
        ),
        (
            "serde",
            "it is the name of a dependency of the generated crate",
        ),
    ] {
        let out = coolc(&["new", "--", name], dir.path());
        assert_eq!(
            out.status.code(),
            Some(2),
            "{name:?}: {}",
            text(&out.stderr)
        );
        let stderr = text(&out.stderr);
        assert!(
            stderr.contains(&format!("invalid package name `{name}`: {why}")),
            "{name:?}: {stderr}"
        );
        assert_eq!(stderr.trim_end().lines().count(), 1, "{stderr}");
    }
    // Nothing was created.
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
}

/// A file reached through two paths (a root given relative and absolute, a directory
/// reached through a symbolic link) is one file, loaded once: no duplicate definitions.
#[test]
fn a_file_reached_through_two_paths_is_loaded_once() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir(dir.path().join("shared")).unwrap();
    std::fs::write(dir.path().join("shared/b.cool"), "packet B { x: u8 }\n").unwrap();
    std::fs::write(
        dir.path().join("a.cool"),
        "import \"shared/b.cool\";\npacket A { b: B }\n",
    )
    .unwrap();
    let absolute = dir.path().join("shared/b.cool");
    let out = coolc(&["check", "a.cool", absolute.to_str().unwrap()], dir.path());
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    #[cfg(unix)]
    {
        std::os::unix::fs::symlink("shared", dir.path().join("link")).unwrap();
        std::fs::write(
            dir.path().join("a.cool"),
            "import \"shared/b.cool\";\nimport \"link/b.cool\";\npacket A { b: B }\n",
        )
        .unwrap();
        let out = coolc(&["check", "a.cool"], dir.path());
        assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    }
}

#[test]
fn an_unknown_name_defined_next_door_names_the_import() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("scan.cool"),
        "packet LaserScan { ranges: [f32; 72] }\natomic Lidar { output scan: data<LaserScan>; }\n",
    )
    .unwrap();
    std::fs::write(
        dir.path().join("robot.cool"),
        "atomic Mapper { input scan: last<LaserScan>; }\ncompound Robot { instance lidar: Lidar; }\n",
    )
    .unwrap();
    let out = coolc(&["check", "robot.cool"], dir.path());
    assert_eq!(out.status.code(), Some(1));
    let stderr = text(&out.stderr);
    for name in ["LaserScan", "Lidar"] {
        assert!(
            stderr.contains(&format!(
                "`{name}` is defined in `scan.cool` next to this file: add `import \"scan.cool\";`"
            )),
            "{stderr}"
        );
    }
    // With the import, it checks.
    std::fs::write(
        dir.path().join("robot.cool"),
        "import \"scan.cool\";\natomic Mapper { input scan: last<LaserScan>; }\ncompound Robot { instance lidar: Lidar; }\n",
    )
    .unwrap();
    let out = coolc(&["check", "robot.cool"], dir.path());
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
}

#[test]
fn a_name_loaded_but_not_imported_gives_the_import_line_from_the_importing_file() {
    // `vision/camera.cool` uses `Image` of `types/shared.cool` without importing it;
    // the cell imports both, from a third directory: the help's path is the one to
    // write in `vision/camera.cool`, whatever the working directory.
    let dir = tempfile::tempdir().unwrap();
    let cell = dir.path().join("cell");
    for sub in ["types", "vision"] {
        std::fs::create_dir_all(cell.join(sub)).unwrap();
    }
    std::fs::write(
        cell.join("types/shared.cool"),
        "packet Image { pixels: [u8] }\n",
    )
    .unwrap();
    let camera = "atomic Camera { output frame: data<Image>; }\n";
    std::fs::write(cell.join("vision/camera.cool"), camera).unwrap();
    std::fs::write(
        cell.join("cell.cool"),
        "import \"types/shared.cool\";\nimport \"vision/camera.cool\";\ncompound Cell { instance camera: Camera; }\n",
    )
    .unwrap();
    let out = coolc(&["check", "cell/cell.cool"], dir.path());
    assert_eq!(out.status.code(), Some(1));
    let stderr = text(&out.stderr);
    assert!(
        stderr.contains("`Image` is defined in `../types/shared.cool`: add `import \"../types/shared.cool\";` to this"),
        "{stderr}"
    );
    // Run from `cell/nested/`, with the camera reached through `..`: the path is
    // still the one that leads from `vision/` to the types.
    let nested = cell.join("nested");
    std::fs::create_dir_all(&nested).unwrap();
    std::fs::write(
        nested.join("cell.cool"),
        "import \"../types/shared.cool\";\nimport \"../vision/camera.cool\";\ncompound Cell { instance camera: Camera; }\n",
    )
    .unwrap();
    let out = coolc(&["check", "cell.cool"], &nested);
    assert_eq!(out.status.code(), Some(1));
    let stderr = text(&out.stderr);
    assert!(
        stderr.contains("add `import \"../types/shared.cool\";` to this"),
        "{stderr}"
    );
    // The line pasted, it checks.
    std::fs::write(
        cell.join("vision/camera.cool"),
        format!("import \"../types/shared.cool\";\n{camera}"),
    )
    .unwrap();
    let out = coolc(&["check", "cell/cell.cool"], dir.path());
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
}

#[test]
fn the_name_and_runtime_given_once_are_kept() {
    let dir = tempfile::tempdir().unwrap();
    let ok = data("motion_controller.cool");
    let ok = ok.to_str().unwrap();
    let first = [
        "compile",
        ok,
        "-o",
        "base",
        "--name",
        "my-base",
        "--runtime-version",
        "0.1",
    ];
    let out = coolc(&first, dir.path());
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let written = std::fs::read_to_string(dir.path().join("base/Cargo.toml")).unwrap();
    assert!(written.contains("name = \"my-base\""), "{written}");

    // Without --name and runtime options: nothing in the manifest changes.
    let out = coolc(&["compile", ok, "-o", "base"], dir.path());
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    assert_eq!(
        std::fs::read_to_string(dir.path().join("base/Cargo.toml")).unwrap(),
        written
    );
    // From inside the crate (`-o .`) too.
    let base = dir.path().join("base");
    let out = coolc(&["compile", ok, "-o", "."], &base);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    assert_eq!(
        std::fs::read_to_string(base.join("Cargo.toml")).unwrap(),
        written
    );

    // A new name and runtime given: they replace the old ones, in place.
    let out = coolc(
        &[
            "compile",
            ok,
            "-o",
            "base",
            "--name",
            "other",
            "--runtime-version",
            "0.2",
        ],
        dir.path(),
    );
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    assert_eq!(
        std::fs::read_to_string(base.join("Cargo.toml")).unwrap(),
        written
            .replace("name = \"my-base\"", "name = \"other\"")
            .replace("coolbot = \"0.1\"", "coolbot = \"0.2\"")
            .replace(
                "coolbot-zenoh = { version = \"0.1\"",
                "coolbot-zenoh = { version = \"0.2\""
            )
    );
}

/// Every file under `dir` with its bytes and modification time.
fn tree(dir: &Path) -> Vec<(std::path::PathBuf, Vec<u8>, std::time::SystemTime)> {
    let mut files = Vec::new();
    let mut pending = vec![dir.to_path_buf()];
    while let Some(next) = pending.pop() {
        for entry in std::fs::read_dir(&next).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                pending.push(path);
            } else {
                let modified = std::fs::metadata(&path).unwrap().modified().unwrap();
                files.push((path.clone(), std::fs::read(&path).unwrap(), modified));
            }
        }
    }
    files.sort();
    files
}

#[test]
fn compile_check_lists_what_would_change_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let description = dir.path().join("lamp.cool");
    let lamp = "atomic Lamp {\n    observable level: u32 = 0;\n    automaton { initial off; state off { entry; } }\n}\n";
    std::fs::write(&description, lamp).unwrap();

    // No crate yet: every file would be written.
    let out = coolc(
        &["compile", "--check", "lamp.cool", "-o", "lamp"],
        dir.path(),
    );
    assert_eq!(out.status.code(), Some(1), "{}", text(&out.stderr));
    assert!(!dir.path().join("lamp").exists());
    let listed = text(&out.stdout);
    for file in [
        "Cargo.toml",
        "src/main.rs",
        "tests/components.rs",
        "src/generated/lamp.rs",
        "src/lamp.rs",
    ] {
        assert!(
            listed
                .lines()
                .any(|l| Path::new(l) == Path::new("lamp").join(file)),
            "{file} not listed:\n{listed}"
        );
    }

    let out = coolc(&["compile", "lamp.cool", "-o", "lamp"], dir.path());
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let header = std::fs::read_to_string(dir.path().join("lamp/src/generated/lamp.rs")).unwrap();
    let header = header.lines().next().unwrap().to_owned();
    assert!(
        header.starts_with(&format!(
            "// @generated by coolc {} from lamp.cool; inputs fnv1a64:",
            env!("CARGO_PKG_VERSION")
        )),
        "{header}"
    );

    // Up to date: exit 0, nothing listed.
    let out = coolc(
        &["compile", "--check", "lamp.cool", "-o", "lamp"],
        dir.path(),
    );
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    assert_eq!(text(&out.stdout), "");
    assert!(
        text(&out.stderr).contains("up to date"),
        "{}",
        text(&out.stderr)
    );

    // The description changes (a new state, a new dependency): the generated files,
    // the user file that gets a stub and the manifest are listed; nothing is written.
    let changed = lamp
        .replace(
            "state off { entry; }",
            "state off { entry; after 1s -> on; }\n        state on { entry; }",
        )
        .replace(
            "    observable",
            "    link crate \"ryu\" = \"1\";\n    observable",
        );
    std::fs::write(&description, changed).unwrap();
    let before = tree(&dir.path().join("lamp"));
    let out = coolc(
        &["compile", "--check", "lamp.cool", "-o", "lamp"],
        dir.path(),
    );
    assert_eq!(out.status.code(), Some(1), "{}", text(&out.stderr));
    assert_eq!(tree(&dir.path().join("lamp")), before, "--check wrote");
    let listed: Vec<String> = text(&out.stdout).lines().map(str::to_owned).collect();
    let expected: Vec<String> = [
        "Cargo.toml",
        "src/generated/lamp.rs",
        "src/generated/mod.rs",
        "src/generated/types.rs",
        "src/lamp.rs",
    ]
    .iter()
    .map(|f| Path::new("lamp").join(f).display().to_string())
    .collect();
    assert_eq!(listed, expected);

    // After the compile, up to date again; the new header names other inputs.
    let out = coolc(&["compile", "lamp.cool", "-o", "lamp"], dir.path());
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let new_header =
        std::fs::read_to_string(dir.path().join("lamp/src/generated/lamp.rs")).unwrap();
    assert_ne!(new_header.lines().next().unwrap(), header);
    let out = coolc(
        &["compile", "--check", "lamp.cool", "-o", "lamp"],
        dir.path(),
    );
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stdout));
}

#[test]
fn compile_check_in_json_lists_stale_files_as_json_lines() {
    let dir = tempfile::tempdir().unwrap();
    let description = dir.path().join("lamp.cool");
    let lamp = "atomic Lamp {\n    automaton { initial off; state off { entry; } }\n}\n";
    std::fs::write(&description, lamp).unwrap();
    let check = &[
        "compile",
        "--check",
        "--message-format",
        "json",
        "lamp.cool",
        "-o",
        "lamp",
    ];
    // One object per line: the reason, the path, the change (and the stubs added).
    let lines = |out: &Output| -> Vec<serde_json::Value> {
        text(&out.stdout)
            .lines()
            .map(|line| serde_json::from_str(line).unwrap_or_else(|e| panic!("{e}: {line}")))
            .collect()
    };

    let out = coolc(check, dir.path());
    assert_eq!(out.status.code(), Some(1), "{}", text(&out.stderr));
    let listed = lines(&out);
    assert!(
        listed
            .iter()
            .all(|l| l["reason"] == "stale_file" && l["change"] == "write")
    );
    let manifest = Path::new("lamp").join("Cargo.toml").display().to_string();
    assert!(
        listed.iter().any(|l| l["path"] == manifest.as_str()),
        "{listed:?}"
    );

    let out = coolc(&["compile", "lamp.cool", "-o", "lamp"], dir.path());
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let out = coolc(check, dir.path());
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    assert_eq!(text(&out.stdout), "");

    // A new state with an entry section: the user file would get its stub.
    let changed = lamp.replace(
        "state off { entry; }",
        "state off { entry; after 1s -> on; }\n        state on { entry; }",
    );
    std::fs::write(&description, changed).unwrap();
    let out = coolc(check, dir.path());
    assert_eq!(out.status.code(), Some(1), "{}", text(&out.stderr));
    let user = Path::new("lamp").join("src/lamp.rs").display().to_string();
    let stubs = lines(&out)
        .into_iter()
        .find(|l| l["path"] == user.as_str())
        .expect("the user file is listed");
    assert_eq!(stubs["change"], "add_stubs");
    assert_eq!(stubs["methods"], serde_json::json!(["on_entry"]));
}

#[test]
fn compile_into_a_new_directory_writes_a_main_and_tests_that_run() {
    // The example descriptions (a compound over two atomics, a converter), into `gen`:
    // a keyword of Rust 2024, so no crate name; the package is named `cool-gen`, and
    // the compile says so. The generated `main.rs` starts the compound, the one
    // component nothing instantiates.
    let dir = tempfile::tempdir().unwrap();
    common::copy_descriptions(dir.path());
    let out = coolc(&["compile", "mobile_base.cool", "-o", "gen"], dir.path());
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let stderr = text(&out.stderr);
    assert!(
        stderr.contains(
            "`gen` cannot name the package (it is a Rust keyword): it is named `cool-gen`"
        ),
        "{stderr}"
    );
    let robot = dir.path().join("gen");
    let manifest = std::fs::read_to_string(robot.join("Cargo.toml")).unwrap();
    assert!(manifest.contains("name = \"cool-gen\""), "{manifest}");
    let main = std::fs::read_to_string(robot.join("src/main.rs")).unwrap();
    let compact: String = main.split_whitespace().collect();
    assert!(
        compact.contains(
            "::cool_gen::generated::mobile_base::component::<::cool_gen::converters::Convert"
        ),
        "{main}"
    );
    // The compound's instances are not started on their own; with the `network`
    // feature every atomic type is registered for other nodes to place.
    let (roots, registry) = main.split_once("fn registry()").expect("a registry");
    assert!(!roots.contains("motion_controller::component("), "{main}");
    assert!(registry.contains("motion_controller::register("), "{main}");
    let stdout = cargo(&robot, &["run", "--quiet"]);
    assert!(
        stdout.contains("ComponentReport { name: \"mobile_base\""),
        "{stdout}"
    );
    // A test per atomic component, in its harness, from the stubs as written.
    let stdout = cargo(&robot, &["test", "--test", "components"]);
    for test in [
        "motion_controller",
        "range_server",
        "sim_range_server",
        "gyro",
        "planner",
        "follower",
    ] {
        assert!(
            stdout.contains(&format!(
                "test {test}_runs_for_a_second_without_error ... ok"
            )),
            "{stdout}"
        );
    }

    // A later compile never writes them again, not even when they are gone.
    std::fs::remove_file(robot.join("src/main.rs")).unwrap();
    std::fs::remove_file(robot.join("tests/components.rs")).unwrap();
    let out = coolc(&["compile", "mobile_base.cool", "-o", "gen"], dir.path());
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    assert!(!robot.join("src/main.rs").exists());
    assert!(!robot.join("tests/components.rs").exists());
    // The name is the manifest's now: nothing more is said about it.
    assert!(!text(&out.stderr).contains("cannot name the package"));
}

#[test]
fn compile_checks_the_package_name_as_new_does() {
    let dir = tempfile::tempdir().unwrap();
    let ok = data("mobile_base.cool");
    let ok = ok.to_str().unwrap();
    // A name given that cargo would refuse is a usage error, and nothing is written.
    for (name, why) in [
        ("type", "it is a Rust keyword"),
        ("3d", "the name cannot start with a digit"),
        (
            "std",
            "it is the name of a crate of Rust's standard library",
        ),
        (
            "Coolbot",
            "as a package name it is `coolbot`, and it is the name of a dependency of the generated crate",
        ),
        (
            "Type",
            "as a package name it is `type`, and it is a Rust keyword",
        ),
        (
            "Gen",
            "as a package name it is `gen`, and it is a Rust keyword",
        ),
        (
            "type-",
            "as a package name it is `type`, and it is a Rust keyword",
        ),
    ] {
        let out = coolc(&["compile", ok, "-o", "out", "--name", name], dir.path());
        assert_eq!(out.status.code(), Some(2), "{name}");
        let stderr = text(&out.stderr);
        assert!(
            stderr.contains(&format!("invalid package name `{name}` (--name): {why}")),
            "{stderr}"
        );
        assert!(!dir.path().join("out").exists(), "{name}");
    }
    // A directory whose name cannot be a package's gives one that can.
    for (out_dir, package) in [
        ("3d", "cool-3d"),
        ("async", "cool-async"),
        ("test", "cool-test"),
    ] {
        let out = coolc(&["compile", ok, "-o", out_dir], dir.path());
        assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
        let manifest =
            std::fs::read_to_string(dir.path().join(out_dir).join("Cargo.toml")).unwrap();
        assert!(
            manifest.contains(&format!("name = \"{package}\"")),
            "{manifest}"
        );
    }
}

#[test]
fn a_compile_that_leaves_out_a_description_of_the_crate_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let out = coolc(&["new", "blinker"], dir.path());
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let krate = dir.path().join("blinker");
    let blinker = std::fs::read_to_string(krate.join("components/blinker.cool")).unwrap();
    std::fs::write(
        krate.join("components/pulse.cool"),
        blinker.replace("Blinker", "Pulse"),
    )
    .unwrap();
    // Only the new description: the blinker's generated module would go while its
    // user file stays, and its description is still there. Nothing is written.
    let before = tree(&krate);
    let out = coolc(&["compile", "components/pulse.cool", "-o", "."], &krate);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stderr));
    let stderr = text(&out.stderr);
    assert!(
        stderr.contains(
            "this compile would remove src/generated/blinker.rs (which src/blinker.rs uses), \
             and components/blinker.cool in the crate is not among its descriptions: compile \
             every description of the crate together (coolc compile components/pulse.cool \
             components/blinker.cool -o .)"
        ),
        "{stderr}"
    );
    assert_eq!(tree(&krate), before, "nothing written");
    // Both descriptions: compiled together.
    let out = coolc(
        &[
            "compile",
            "components/pulse.cool",
            "components/blinker.cool",
            "-o",
            ".",
        ],
        &krate,
    );
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    assert!(krate.join("src/generated/pulse.rs").is_file());
    // The blinker's description deleted: its component goes, as before (its user file
    // is the user's to remove).
    std::fs::remove_file(krate.join("components/blinker.cool")).unwrap();
    let out = coolc(&["compile", "components/pulse.cool", "-o", "."], &krate);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let stderr = text(&out.stderr);
    assert!(
        stderr.contains("removed src/generated/blinker.rs (no longer generated)")
            && stderr.contains("src/blinker.rs belongs to a component that is no longer described"),
        "{stderr}"
    );
    assert!(!krate.join("src/generated/blinker.rs").exists());
    // A component whose module is a keyword (`r#loop`), compiled with a draft lying
    // elsewhere in the crate: nothing would be removed, nothing is refused.
    std::fs::write(
        krate.join("components/loop.cool"),
        blinker.replace("Blinker", "Loop"),
    )
    .unwrap();
    let both = [
        "compile",
        "components/pulse.cool",
        "components/loop.cool",
        "-o",
        ".",
    ];
    let out = coolc(&both, &krate);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    std::fs::create_dir_all(krate.join("drafts")).unwrap();
    std::fs::write(krate.join("drafts/draft.cool"), "atomic Draft {}\n").unwrap();
    let out = coolc(&both, &krate);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    assert!(krate.join("src/generated/loop.rs").is_file());
}

#[test]
fn an_atomic_component_made_a_compound_is_told_its_old_block_is_left() {
    let dir = tempfile::tempdir().unwrap();
    let out = coolc(&["new", "scanbot"], dir.path());
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let krate = dir.path().join("scanbot");
    std::fs::write(
        krate.join("components/scanbot.cool"),
        "packet Twist { v: f64, w: f64 }\n\
         atomic Lidar { output scan: data<Twist>; }\n\
         atomic Avoider { input scan: fifo<Twist>(4); }\n\
         compound Scanbot {\n    instance lidar: Lidar;\n    instance avoider: Avoider;\n    \
         connect lidar.scan -> avoider.scan;\n}\n",
    )
    .unwrap();
    let out = coolc(&["compile", "components/scanbot.cool", "-o", "."], &krate);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let stderr = text(&out.stderr);
    assert!(
        stderr.contains(
            "warning: src/scanbot.rs implements `Behavior` for a component that no longer has it"
        ) && stderr.contains(".coolc/stubs/src/main.rs")
            && stderr.contains(".coolc/stubs/tests/components.rs"),
        "{stderr}"
    );
    // The compound's own blocks were added; an atomic's file gets no such warning.
    let user = std::fs::read_to_string(krate.join("src/scanbot.rs")).unwrap();
    assert!(
        user.contains("impl Supervisor for") && user.contains("impl Parts for"),
        "{user}"
    );
    assert!(!stderr.contains("src/lidar.rs implements"), "{stderr}");
}
