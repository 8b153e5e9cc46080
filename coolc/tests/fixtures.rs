//! Fixture suites: every `tests/data/ok/*.cool` analyzes without a diagnostic, every
//! `tests/data/err/*.cool` yields at least one error, and the rendered diagnostics of
//! each err fixture (no colour, 80 columns) are snapshotted. `import ros` types are
//! found in `tests/data/ros` (`<package>/msg/<Type>.msg`), then among the shipped ones.

use std::path::{Path, PathBuf};

use coolc::{Analysis, RenderOptions};

fn data_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/data")
}

/// Analyzes `path` (absolute) with paths shown relative to `tests/data`.
fn analyze_fixture(path: &Path) -> Analysis {
    let base = data_dir().canonicalize().expect("tests/data exists");
    let path = path.canonicalize().expect("fixture exists");
    let relative = path
        .strip_prefix(&base)
        .expect("fixture under tests/data")
        .to_owned();
    coolc::analyze_with(
        &[relative],
        &|p: &Path| std::fs::read_to_string(base.join(p)),
        &|_| Vec::new(),
        &coolc::ros::Search::new().with_dir("ros"),
    )
}

#[test]
fn ok_fixtures_have_no_diagnostics() {
    insta::glob!("../../tests/data", "ok/*.cool", |path| {
        let analysis = analyze_fixture(path);
        assert!(
            analysis.diagnostics.is_empty(),
            "{}:\n{}",
            path.display(),
            analysis.render(RenderOptions::plain())
        );
    });
}

#[test]
fn err_fixtures_report_errors() {
    insta::glob!("../../tests/data", "err/*.cool", |path| {
        let analysis = analyze_fixture(path);
        assert!(analysis.has_errors(), "{} yields no error", path.display());
        // The fixture is named after the code it exercises.
        let stem = path
            .file_stem()
            .and_then(|s| s.to_str())
            .unwrap_or_default();
        let expected_code = stem.split("__").next().unwrap_or(stem);
        assert!(
            analysis
                .diagnostics
                .iter()
                .any(|d| d.code.as_str().ends_with(&format!("::{expected_code}"))),
            "{} does not report a `{expected_code}` diagnostic:\n{}",
            path.display(),
            analysis.render(RenderOptions::plain())
        );
        insta::assert_snapshot!(analysis.render(RenderOptions::plain()));
    });
}

#[test]
fn warn_fixtures_report_warnings_only() {
    insta::glob!("../../tests/data", "warn/*.cool", |path| {
        let analysis = analyze_fixture(path);
        assert!(
            !analysis.has_errors(),
            "{}:\n{}",
            path.display(),
            analysis.render(RenderOptions::plain())
        );
        let stem = path
            .file_stem()
            .and_then(|s| s.to_str())
            .unwrap_or_default();
        assert!(
            analysis
                .diagnostics
                .iter()
                .any(|d| d.code.as_str().ends_with(&format!("::{stem}"))),
            "{} does not warn `{stem}`",
            path.display()
        );
        insta::assert_snapshot!(analysis.render(RenderOptions::plain()));
    });
}

#[test]
fn every_check_code_has_a_fixture() {
    let mut missing = Vec::new();
    for code in coolc::diagnostics::Code::ALL {
        let name = code.as_str().rsplit("::").next().unwrap_or_default();
        let has_fixture = ["err", "warn"].iter().any(|dir| {
            std::fs::read_dir(data_dir().join(dir))
                .into_iter()
                .flatten()
                .flatten()
                .any(|entry| {
                    let file = entry.file_name().to_string_lossy().into_owned();
                    file == format!("{name}.cool") || file.starts_with(&format!("{name}__"))
                })
        });
        if !has_fixture {
            missing.push(code.as_str());
        }
    }
    assert!(missing.is_empty(), "codes without a fixture: {missing:?}");
}

#[test]
fn json_rendering_carries_code_file_and_position() {
    let path = data_dir().join("err/unexpected_token.cool");
    let analysis = analyze_fixture(&path);
    let json = analysis.render(RenderOptions::json());
    let first: serde_json::Value =
        serde_json::from_str(json.lines().next().expect("one line")).expect("valid json");
    assert_eq!(first["code"], "coolc::syntax::unexpected_token");
    assert_eq!(first["severity"], "error");
    assert_eq!(first["file"], "err/unexpected_token.cool");
    assert!(first["line"].as_u64().is_some_and(|line| line > 0));
}

#[test]
fn a_missing_root_is_a_diagnostic_not_a_panic() {
    let analysis = coolc::analyze(&["nowhere.cool"], &|_: &Path| {
        Err(std::io::Error::from(std::io::ErrorKind::NotFound))
    });
    assert_eq!(analysis.diagnostics.len(), 1);
    assert_eq!(
        analysis.diagnostics[0].code,
        coolc::diagnostics::Code::ImportNotFound
    );
    assert_eq!(analysis.files.len(), analysis.sources.files().len());
}

#[test]
fn shared_imports_load_once_and_ids_follow_load_order() {
    let files = [
        (
            "root.cool",
            "import \"a/left.cool\";\nimport \"a/right.cool\";\n",
        ),
        (
            "a/left.cool",
            "import \"../shared.cool\";\npacket Left { s: Shared }\n",
        ),
        (
            "a/right.cool",
            "import \"./../shared.cool\";\npacket Right { s: Shared }\n",
        ),
        ("shared.cool", "packet Shared { x: f64 }\n"),
    ];
    let loader = |path: &Path| -> std::io::Result<String> {
        files
            .iter()
            .find(|(name, _)| Path::new(name) == path)
            .map(|(_, text)| text.to_string())
            .ok_or_else(|| std::io::Error::from(std::io::ErrorKind::NotFound))
    };
    let analysis = coolc::analyze(&["root.cool"], &loader);
    assert!(
        analysis.diagnostics.is_empty(),
        "{}",
        analysis.render(RenderOptions::plain())
    );
    let paths: Vec<String> = analysis
        .sources
        .files()
        .iter()
        .map(|f| analysis.sources.display_path(f.id))
        .collect();
    assert_eq!(
        paths,
        ["root.cool", "a/left.cool", "shared.cool", "a/right.cool"]
    );
    for (index, file) in analysis.files.iter().enumerate() {
        assert_eq!(file.id.0 as usize, index);
    }
}

#[test]
fn an_unknown_name_in_a_sibling_file_gets_the_import_to_add() {
    // `list` offers the files of a directory; `scan.cool` is next to `robot.cool`
    // but not imported, `other/far.cool` is elsewhere: only the sibling is named.
    let files = [
        (
            "robot.cool",
            "atomic Mapper { input scan: last<LaserScan>; input far: last<Far>; }\n",
        ),
        ("scan.cool", "packet LaserScan { ranges: [f32; 72] }\n"),
        ("other/far.cool", "packet Far { x: f64 }\n"),
    ];
    let loader = |path: &Path| -> std::io::Result<String> {
        files
            .iter()
            .find(|(name, _)| Path::new(name) == path)
            .map(|(_, text)| text.to_string())
            .ok_or_else(|| std::io::Error::from(std::io::ErrorKind::NotFound))
    };
    let list = |dir: &Path| -> Vec<PathBuf> {
        files
            .iter()
            .map(|(name, _)| PathBuf::from(name))
            .filter(|path| path.parent() == Some(dir))
            .collect()
    };
    let analysis = coolc::analyze_with_siblings(&["robot.cool"], &loader, &list);
    let helps: Vec<(String, Option<String>)> = analysis
        .diagnostics
        .iter()
        .map(|d| (d.message.clone(), d.help.clone()))
        .collect();
    assert_eq!(
        helps,
        [
            (
                "unknown type `LaserScan`".to_owned(),
                Some(
                    "`LaserScan` is defined in `scan.cool` next to this file: add `import \"scan.cool\";`"
                        .to_owned()
                )
            ),
            ("unknown type `Far`".to_owned(), None),
        ]
    );
    // The sibling was only scanned: it is not part of the analysis.
    assert_eq!(analysis.files.len(), 1);
}

/// A loader over in-memory files.
fn memory<'a>(files: &'a [(&'a str, &'a str)]) -> impl Fn(&Path) -> std::io::Result<String> + 'a {
    move |path: &Path| {
        files
            .iter()
            .find(|(name, _)| Path::new(name) == path)
            .map(|(_, text)| text.to_string())
            .ok_or_else(|| std::io::Error::from(std::io::ErrorKind::NotFound))
    }
}

#[test]
fn one_ros_type_imported_by_two_files_under_one_name_is_one_definition() {
    // `user.cool` imports only `right.cool`; both `left.cool` and `right.cool` import
    // the same type as `Scan`: the name is seen from `user.cool`, and no duplicate.
    // Another type under the same name is a duplicate.
    let files = [
        (
            "root.cool",
            "import \"left.cool\";\nimport \"user.cool\";\n",
        ),
        (
            "left.cool",
            "import ros \"sensor_msgs/msg/LaserScan\" as Scan;\natomic L { output s: data<Scan>; }\n",
        ),
        (
            "user.cool",
            "import \"right.cool\";\natomic U { input s: last<Scan>; }\n",
        ),
        (
            "right.cool",
            "import ros \"sensor_msgs/msg/LaserScan\" as Scan;\n",
        ),
    ];
    let analysis = coolc::analyze(&["root.cool"], &memory(&files));
    assert!(
        analysis.diagnostics.is_empty(),
        "{}",
        analysis.render(RenderOptions::plain())
    );
    // The `.msg` files read are sources too, each with an (empty) syntax tree: ids
    // stay indices.
    let paths: Vec<String> = analysis
        .sources
        .files()
        .iter()
        .map(|f| analysis.sources.display_path(f.id))
        .collect();
    assert_eq!(
        paths[4..],
        [
            "<shipped>/sensor_msgs/msg/LaserScan.msg",
            "<shipped>/std_msgs/msg/Header.msg",
            "<shipped>/builtin_interfaces/msg/Time.msg",
        ]
    );
    assert_eq!(analysis.files.len(), analysis.sources.files().len());
    for (index, file) in analysis.files.iter().enumerate() {
        assert_eq!(file.id.0 as usize, index);
    }

    let files = [
        (
            "root.cool",
            "import ros \"sensor_msgs/msg/LaserScan\" as Scan;\nimport \"other.cool\";\n",
        ),
        (
            "other.cool",
            "import ros \"sensor_msgs/msg/Imu\" as Scan;\n",
        ),
    ];
    let analysis = coolc::analyze(&["root.cool"], &memory(&files));
    let codes: Vec<&str> = analysis
        .diagnostics
        .iter()
        .map(|d| d.code.as_str())
        .collect();
    assert_eq!(codes, ["coolc::resolve::duplicate"]);
}

#[test]
fn ros_types_are_looked_up_in_the_directories_given_then_among_the_shipped_ones() {
    // A `Header` of the directory's own replaces the shipped one; `analyze` alone
    // knows only the shipped ones.
    let files = [
        (
            "main.cool",
            "import ros \"std_msgs/msg/Header\";\nimport ros \"my_msgs/msg/Reading\";\n",
        ),
        ("dir/std_msgs/msg/Header.msg", "int32 mine\n"),
        (
            "dir/my_msgs/msg/Reading.msg",
            "std_msgs/Header header\nfloat64 value\n",
        ),
    ];
    let search = coolc::ros::Search::new().with_dir("dir");
    let analysis = coolc::analyze_with(&["main.cool"], &memory(&files), &|_| Vec::new(), &search);
    assert!(
        analysis.diagnostics.is_empty(),
        "{}",
        analysis.render(RenderOptions::plain())
    );
    let paths: Vec<String> = analysis.sources.files()[1..]
        .iter()
        .map(|f| analysis.sources.display_path(f.id))
        .collect();
    assert_eq!(
        paths,
        ["dir/std_msgs/msg/Header.msg", "dir/my_msgs/msg/Reading.msg"]
    );
    let analysis = coolc::analyze(&["main.cool"], &memory(&files));
    let messages: Vec<&str> = analysis
        .diagnostics
        .iter()
        .map(|d| d.message.as_str())
        .collect();
    assert_eq!(messages, ["no `.msg` file defines `my_msgs/msg/Reading`"]);
}
