//! Regeneration never destroys user code: generate, fill in a stub, add a state (and
//! an exception and a component) to the description, regenerate. The filled code is
//! byte-for-byte intact, the new stubs are there, and the crate builds.

use crate::common;

use std::path::Path;

use common::{cargo, compile};

const V1: &str = "\
/// A lamp.
atomic Lamp {
    observable level: u32 = 0;
    timing { period 20ms; }
    automaton {
        initial off;
        state off { entry; }
    }
}
";

const V2: &str = "\
/// A lamp.
atomic Lamp {
    observable level: u32 = 0;
    timing { period 20ms; }
    exception flicker \"the bulb flickers\";
    automaton {
        initial off;
        state off { entry; after 50ms -> lit; }
        state lit { entry; periodic; }
    }
}

/// A switch.
atomic Switch {
    output toggle: tick;
    automaton { initial idle; state idle { entry; } }
}
";

/// V2 without the exception.
fn v3() -> String {
    V2.replace("    exception flicker \"the bulb flickers\";\n", "")
}

const FILLED_BODY: &str = "        // Filled in by hand: keep me exactly as I am.\n        cx.vars.level = 7 ;   // odd spacing on purpose\n        Ok(())\n";

/// Replaces the body of the generated `off_entry` stub with hand-written code.
fn fill_off_entry(text: &str) -> String {
    let start = text.find("fn off_entry").expect("off_entry stub");
    let open = start + text[start..].find("{\n").unwrap() + 2;
    let close = open + text[open..].find("    }\n").unwrap();
    let mut filled = String::new();
    filled.push_str(&text[..open]);
    filled.push_str(FILLED_BODY);
    filled.push_str(&text[close..]);
    // Plus code of the user's own outside the impl block.
    filled.push_str(
        "\n/// A helper of mine.\npub fn brightness(level: u32) -> u32 {\n    level * 10\n}\n",
    );
    filled
}

/// Asserts that `new` is `old` with text inserted at one place only.
fn assert_only_inserted(old: &str, new: &str) -> String {
    let prefix = old
        .bytes()
        .zip(new.bytes())
        .take_while(|(a, b)| a == b)
        .count();
    let suffix = old
        .bytes()
        .rev()
        .zip(new.bytes().rev())
        .take_while(|(a, b)| a == b)
        .count();
    assert!(
        prefix + suffix >= old.len(),
        "user text was changed, not only added to:\n--- old\n{old}\n--- new\n{new}"
    );
    let prefix = prefix.min(old.len());
    new[prefix..new.len() - (old.len() - prefix)].to_owned()
}

fn write(path: &Path, text: &str) {
    std::fs::write(path, text).unwrap();
}

#[test]
fn regeneration_keeps_user_code_and_adds_new_stubs() {
    let dir = tempfile::tempdir().unwrap();
    let description = dir.path().join("lamp.cool");
    let krate = dir.path().join("lamp");

    write(&description, V1);
    let report = compile(&description, &krate, "lamp");
    assert!(report.added.is_empty());
    let user_file = krate.join("src/lamp.rs");
    let generated = std::fs::read_to_string(&user_file).unwrap();
    assert!(generated.contains("fn off_entry"));
    assert!(!generated.contains("fn lit_entry"));

    let filled = fill_off_entry(&generated);
    write(&user_file, &filled);
    let lib_before = std::fs::read_to_string(krate.join("src/lib.rs")).unwrap();

    write(&description, V2);
    let report = compile(&description, &krate, "lamp");
    let regenerated = std::fs::read_to_string(&user_file).unwrap();
    let inserted = assert_only_inserted(&filled, &regenerated);
    assert!(regenerated.contains(FILLED_BODY));
    for stub in ["fn lit_entry", "fn lit_periodic", "fn on_flicker"] {
        assert!(inserted.contains(stub), "{stub} not inserted: {inserted}");
    }
    assert!(!inserted.contains("fn off_entry"));
    assert_eq!(
        report.added,
        [
            ("src/lib.rs".into(), vec!["switch".to_owned()]),
            (
                "src/lamp.rs".into(),
                vec![
                    "lit_entry".to_owned(),
                    "lit_periodic".to_owned(),
                    "on_flicker".to_owned()
                ]
            ),
        ]
    );
    // The new component gets its module declared and its user file written.
    let lib_after = std::fs::read_to_string(krate.join("src/lib.rs")).unwrap();
    assert_eq!(
        assert_only_inserted(&lib_before, &lib_after),
        "pub mod switch;\n"
    );
    assert!(krate.join("src/switch.rs").exists());
    // The latest stubs are kept for reference.
    assert!(
        std::fs::read_to_string(krate.join(".coolc/stubs/src/lamp.rs"))
            .unwrap()
            .contains("fn lit_periodic")
    );

    cargo(&krate, &["build", "--quiet"]);

    // A member removed from the description is reported; the user's method stays.
    write(&description, &v3());
    let report = compile(&description, &krate, "lamp");
    assert!(report.added.is_empty());
    assert_eq!(std::fs::read_to_string(&user_file).unwrap(), regenerated);
    assert_eq!(report.warnings.len(), 1, "{:?}", report.warnings);
    assert!(
        report.warnings[0].contains("on_flicker"),
        "{:?}",
        report.warnings
    );

    // A component removed from the description loses its generated module; its user
    // file stays.
    write(&description, &v3().replace("atomic Switch", "atomic Other"));
    let report = compile(&description, &krate, "lamp");
    assert_eq!(report.removed, [Path::new("src/generated/switch.rs")]);
    assert!(
        report.warnings.iter().any(|w| w.contains("src/switch.rs")),
        "{:?}",
        report.warnings
    );
    assert!(krate.join("src/switch.rs").exists());
    assert!(krate.join("src/generated/other.rs").exists());

    // Compiling again with nothing changed rewrites nothing.
    let report = compile(&description, &krate, "lamp");
    assert!(report.written.is_empty(), "{:?}", report.written);
}

const COMPOUND_V1: &str = "\
/// A lamp.
atomic Lamp {
    observable level: u32 = 0;
    timing { period 20ms; }
    automaton { initial off; state off { entry; } }
}

/// Lamps under a supervisor.
compound Room {
    instance main: Lamp;
    supervisor {
        initial dark;
        state dark { entry; when main.level > 3 -> lit; }
        state lit { }
    }
}
";

/// A supervisor section filled in by hand.
const MINE: &str = "        let _ = cx.view.state(\"main\"); // mine\n        Ok(())\n";

/// V1 with a new supervisor section, a new state and a new instance.
fn compound_v2() -> String {
    COMPOUND_V1
        .replace("state lit { }", "state lit { exit; periodic 50ms; }")
        .replace(
            "    instance main: Lamp;\n",
            "    instance main: Lamp;\n    instance spare: Lamp substitutes main;\n",
        )
}

#[test]
fn regeneration_adds_supervisor_sections_and_parts_to_compounds() {
    let dir = tempfile::tempdir().unwrap();
    let description = dir.path().join("room.cool");
    let krate = dir.path().join("room");

    write(&description, COMPOUND_V1);
    compile(&description, &krate, "room");
    let user_file = krate.join("src/room.rs");
    let generated = std::fs::read_to_string(&user_file).unwrap();
    assert!(generated.contains("impl Supervisor for RoomSupervisor"));
    assert!(generated.contains("fn dark_entry"));
    assert!(!generated.contains("fn lit_exit"));

    // The user fills in the supervisor's entry section.
    let start = generated.find("fn dark_entry").unwrap();
    let open = start + generated[start..].find("{\n").unwrap() + 2;
    let close = open + generated[open..].find("    }\n").unwrap();
    let filled = format!("{}{MINE}{}", &generated[..open], &generated[close..]);
    write(&user_file, &filled);

    write(&description, &compound_v2());
    let report = compile(&description, &krate, "room");
    let regenerated = std::fs::read_to_string(&user_file).unwrap();
    assert!(regenerated.contains(MINE));
    // Two insertion points (the two impl blocks); everything else is kept.
    let supervisor_end = regenerated.find("impl Parts for").unwrap();
    let (supervisor_part, parts_part) = regenerated.split_at(supervisor_end);
    let (old_supervisor, old_parts) = filled.split_at(filled.find("impl Parts for").unwrap());
    let inserted = assert_only_inserted(old_supervisor, supervisor_part);
    assert!(inserted.contains("fn lit_periodic"), "{inserted}");
    assert!(inserted.contains("fn lit_exit"), "{inserted}");
    let inserted = assert_only_inserted(old_parts, parts_part);
    assert!(inserted.contains("fn spare"), "{inserted}");
    assert_eq!(
        report.added,
        [(
            "src/room.rs".into(),
            vec![
                "lit_periodic".to_owned(),
                "lit_exit".to_owned(),
                "spare".to_owned()
            ]
        )]
    );
    assert!(report.warnings.is_empty(), "{:?}", report.warnings);
    cargo(&krate, &["build", "--quiet"]);
}

#[test]
fn a_compound_user_file_without_a_supervisor_block_gets_one_appended() {
    // A user file as the previous coolc wrote it: `impl Parts` only, no supervisor.
    let dir = tempfile::tempdir().unwrap();
    let description = dir.path().join("room.cool");
    let krate = dir.path().join("room");
    write(&description, COMPOUND_V1);
    compile(&description, &krate, "room");
    let user_file = krate.join("src/room.rs");
    let generated = std::fs::read_to_string(&user_file).unwrap();
    let struct_start = generated
        .find("/// What `Room`'s supervisor keeps")
        .expect("the supervisor struct");
    let parts_start = generated.find("/// The behaviours").expect("the parts");
    let supervisor_stub = generated.find("    fn supervisor(&mut self)").unwrap();
    let stub_end = supervisor_stub + generated[supervisor_stub..].find("    }\n").unwrap() + 6;
    let old = format!(
        "{}{}{}\n// A helper of mine.\npub fn mine() -> u32 {{\n    7\n}}\n",
        &generated[..struct_start],
        &generated[parts_start..supervisor_stub],
        &generated[stub_end..].trim_start_matches('\n'),
    );
    assert!(!old.contains("Supervisor for"), "{old}");
    write(&user_file, &old);

    let report = compile(&description, &krate, "room");
    assert!(report.warnings.is_empty(), "{:?}", report.warnings);
    let regenerated = std::fs::read_to_string(&user_file).unwrap();
    // The supervisor's struct and block appended at the end; the `supervisor()` stub
    // inserted into `impl Parts`; nothing else changed.
    let appended_at = regenerated
        .rfind("/// What `Room`'s supervisor keeps")
        .expect("appended");
    let (head, appended) = regenerated.split_at(appended_at);
    assert!(appended.contains("pub struct RoomSupervisor"), "{appended}");
    assert!(
        appended.contains("impl Supervisor for RoomSupervisor"),
        "{appended}"
    );
    assert!(appended.contains("fn dark_entry"), "{appended}");
    let head = head
        .strip_suffix('\n')
        .expect("a blank line before the block");
    let inserted = assert_only_inserted(&old, head);
    assert!(inserted.contains("fn supervisor(&mut self)"), "{inserted}");
    assert!(!inserted.contains("Supervisor for"), "{inserted}");
    cargo(&krate, &["build", "--quiet"]);
}

/// What a user adds to the generated `Cargo.toml`: a dependency of theirs (with a
/// comment) inside `[dependencies]`, and after it dev-dependencies, a binary, a
/// feature and a profile.
const USER_DEPENDENCY: &str =
    "# Mine: the tool in src/bin uses it.\nitoa = { version = \"1\" } # keep this comment\n";
/// A feature of the user's, in the `[features]` table the first compile wrote (which
/// holds coolc's `network`).
const USER_FEATURE: &str = "extra = [] # mine\n";
const NETWORK_FEATURE: &str = "[features]\nnetwork = [\"dep:coolbot-zenoh\"]\n";
const USER_TABLES: &str = "\
# Mine, all of it.
[dev-dependencies]
tempfile = \"3\"

[[bin]]
name = \"lamp-tool\"
path = \"src/bin/tool.rs\"

[profile.release]
debug = true # for perf
";

/// `Cargo.toml` parsed.
fn manifest(krate: &Path) -> toml_edit::DocumentMut {
    std::fs::read_to_string(krate.join("Cargo.toml"))
        .unwrap()
        .parse()
        .unwrap()
}

#[test]
fn the_manifest_keeps_what_the_user_wrote_and_follows_link_crate() {
    let dir = tempfile::tempdir().unwrap();
    let description = dir.path().join("lamp.cool");
    let krate = dir.path().join("lamp");
    write(&description, V1);
    compile(&description, &krate, "lamp");

    // The user edits the manifest: a dependency inside [dependencies] (right after
    // its header) and tables of their own at the end.
    let generated = std::fs::read_to_string(krate.join("Cargo.toml")).unwrap();
    let at = generated.find("[dependencies]\n").unwrap() + "[dependencies]\n".len();
    let edited = format!(
        "{}{USER_DEPENDENCY}{}\n{USER_TABLES}",
        &generated[..at],
        &generated[at..]
    );
    assert!(edited.contains(NETWORK_FEATURE), "{edited}");
    let edited = edited.replace(NETWORK_FEATURE, &format!("{NETWORK_FEATURE}{USER_FEATURE}"));
    write(&krate.join("Cargo.toml"), &edited);
    std::fs::create_dir_all(krate.join("src/bin")).unwrap();
    write(&krate.join("src/bin/tool.rs"), "fn main() {}\n");

    // Nothing in the descriptions changed: the manifest is not touched.
    let report = compile(&description, &krate, "lamp");
    assert!(report.written.is_empty(), "{:?}", report.written);
    assert_eq!(
        std::fs::read_to_string(krate.join("Cargo.toml")).unwrap(),
        edited
    );

    // A `link crate` added: coolc's entries change, the user's bytes do not.
    let linked = V1.replace(
        "    observable level",
        "    link crate \"ryu\" = { version = \"1\", default_features = false };\n    observable level",
    );
    write(&description, &linked);
    let report = compile(&description, &krate, "lamp");
    assert!(
        report.written.iter().any(|p| p == Path::new("Cargo.toml")),
        "{:?}",
        report.written
    );
    assert!(report.warnings.is_empty(), "{:?}", report.warnings);
    let updated = std::fs::read_to_string(krate.join("Cargo.toml")).unwrap();
    assert!(updated.contains(USER_DEPENDENCY), "{updated}");
    assert!(updated.ends_with(&format!("\n{USER_TABLES}")), "{updated}");
    let doc = manifest(&krate);
    assert_eq!(
        doc["dependencies"]["ryu"].to_string().trim(),
        "{ version = \"1\", default-features = false }"
    );
    assert_eq!(
        doc["package"]["metadata"]["coolc"]["dependencies"]
            .to_string()
            .trim(),
        "[\"serde\", \"ryu\"]"
    );
    assert_eq!(doc["package"]["name"].as_str(), Some("lamp"));
    // The only differences from the edited file: the new entry and the list.
    let without_coolc = updated
        .replace("ryu = { version = \"1\", default-features = false }\n", "")
        .replace("[\"serde\", \"ryu\"]", "[\"serde\"]");
    assert_eq!(without_coolc, edited);
    // Cargo reads it: the package, its binaries and features.
    let metadata = cargo(&krate, &["metadata", "--no-deps", "--format-version", "1"]);
    for needle in [
        "\"lamp-tool\"",
        "\"extra\"",
        "\"itoa\"",
        "\"ryu\"",
        "\"tempfile\"",
    ] {
        assert!(
            metadata.contains(needle),
            "{needle} missing from {metadata}"
        );
    }

    // The version changes: coolc's entry follows, in place.
    write(
        &description,
        &linked.replace(
            "{ version = \"1\", default_features = false }",
            "{ version = \"1.0\", default_features = false }",
        ),
    );
    compile(&description, &krate, "lamp");
    let bumped = std::fs::read_to_string(krate.join("Cargo.toml")).unwrap();
    assert_eq!(
        bumped,
        updated.replace(
            "version = \"1\", default-features",
            "version = \"1.0\", default-features"
        )
    );

    // The `link crate` removed: its entry goes, and the file is what the user wrote.
    write(&description, V1);
    let report = compile(&description, &krate, "lamp");
    assert!(report.warnings.is_empty(), "{:?}", report.warnings);
    assert_eq!(
        std::fs::read_to_string(krate.join("Cargo.toml")).unwrap(),
        edited
    );
}

#[test]
fn a_link_crate_naming_a_user_dependency_takes_it_over_with_a_warning() {
    let dir = tempfile::tempdir().unwrap();
    let description = dir.path().join("lamp.cool");
    let krate = dir.path().join("lamp");
    write(&description, V1);
    compile(&description, &krate, "lamp");
    let generated = std::fs::read_to_string(krate.join("Cargo.toml")).unwrap();
    // At the end of [dependencies], before coolc's [features].
    assert!(generated.contains("\n\n[features]\n"), "{generated}");
    let edited = generated.replacen(
        "\n\n[features]\n",
        "\n# My own ryu.\nryu = \"1.0.5\"\n\n[features]\n",
        1,
    );
    write(&krate.join("Cargo.toml"), &edited);

    write(
        &description,
        &V1.replace(
            "    observable level",
            "    link crate \"ryu\" = \"1\";\n    observable level",
        ),
    );
    let report = compile(&description, &krate, "lamp");
    assert_eq!(report.warnings.len(), 1, "{:?}", report.warnings);
    assert!(
        report.warnings[0].contains("`ryu`") && report.warnings[0].contains("\"1.0.5\""),
        "{:?}",
        report.warnings
    );
    let updated = std::fs::read_to_string(krate.join("Cargo.toml")).unwrap();
    assert!(
        updated.contains("# My own ryu.\nryu = \"1\"\n"),
        "{updated}"
    );
    // Now coolc's: removing the `link crate` removes it, the comment above it stays.
    write(&description, V1);
    compile(&description, &krate, "lamp");
    let removed = std::fs::read_to_string(krate.join("Cargo.toml")).unwrap();
    assert!(!removed.contains("ryu ="), "{removed}");
    assert!(removed.contains("# My own ryu.\n"), "{removed}");
}

#[test]
fn a_manifest_that_does_not_parse_is_left_alone_with_a_warning() {
    let dir = tempfile::tempdir().unwrap();
    let description = dir.path().join("lamp.cool");
    let krate = dir.path().join("lamp");
    write(&description, V1);
    compile(&description, &krate, "lamp");
    let broken = "[package\nname = \"lamp\"\n";
    write(&krate.join("Cargo.toml"), broken);
    let report = compile(&description, &krate, "lamp");
    assert_eq!(
        std::fs::read_to_string(krate.join("Cargo.toml")).unwrap(),
        broken
    );
    assert!(!report.written.iter().any(|p| p == Path::new("Cargo.toml")));
    assert_eq!(report.warnings.len(), 1, "{:?}", report.warnings);
    assert!(
        report.warnings[0].starts_with("Cargo.toml was not updated: it does not parse as TOML")
            && report.warnings[0].contains("[package.metadata.coolc]"),
        "{}",
        report.warnings[0]
    );
}
