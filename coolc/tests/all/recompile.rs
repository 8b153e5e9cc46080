//! Recompiling touches nothing that would not change: a second `coolc compile` of the
//! same descriptions writes no file (so cargo rebuilds nothing), formatted files are
//! taken from the format cache, a generated file edited by hand is restored, and a
//! changed description changes only its own files below the generated header (which
//! names the inputs' hash).

use crate::common;

use std::path::{Path, PathBuf};
use std::time::SystemTime;

use common::{compile, copy_descriptions};

fn modified(path: &Path) -> SystemTime {
    std::fs::metadata(path).unwrap().modified().unwrap()
}

#[test]
fn recompile_writes_only_what_changed() {
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path().join("descriptions");
    std::fs::create_dir_all(&src).unwrap();
    copy_descriptions(&src);
    // A default holding a character other than ASCII: coolc's layout does not
    // measure it, so the types module goes to the formatter.
    let types = src.join("types.cool");
    let mut text = std::fs::read_to_string(&types).unwrap();
    text.push_str("\n/// A temperature.\npacket Reading { value: f64, unit: String = \"°C\" }\n");
    std::fs::write(&types, text).unwrap();
    let out = dir.path().join("fleet");
    let root = src.join("mobile_base.cool");

    let first = compile(&root, &out, "fleet");
    assert!(first.written.iter().any(|p| p == Path::new("Cargo.toml")));
    let cache = std::fs::read_to_string(out.join(".coolc/format-cache")).unwrap();
    assert!(cache.starts_with("coolc format cache 2\t"), "{cache}");
    // The types module is formatted, so the cache lists it; the compound module is
    // written in rustfmt's layout and needs no cache.
    assert!(cache.contains("src/generated/types.rs\t"), "{cache}");
    assert!(!cache.contains("src/generated/mobile_base.rs\t"), "{cache}");

    let watched = [
        "Cargo.toml",
        "src/generated/mod.rs",
        "src/generated/types.rs",
        "src/generated/mobile_base.rs",
        "src/generated/motion_controller.rs",
        ".coolc/format-cache",
        ".coolc/stubs/src/mobile_base.rs",
    ];
    let before: Vec<SystemTime> = watched.iter().map(|p| modified(&out.join(p))).collect();
    let snapshot = |out: &Path| -> Vec<String> {
        watched
            .iter()
            .map(|p| std::fs::read_to_string(out.join(p)).unwrap())
            .collect()
    };
    let contents = snapshot(&out);
    std::thread::sleep(std::time::Duration::from_millis(20));

    let second = compile(&root, &out, "fleet");
    assert!(second.written.is_empty(), "{:?}", second.written);
    let after: Vec<SystemTime> = watched.iter().map(|p| modified(&out.join(p))).collect();
    assert_eq!(before, after, "a recompile touched a file");
    assert_eq!(contents, snapshot(&out));

    // Generated files edited by hand: the cache no longer matches the formatted one,
    // so it is formatted again, and both are rewritten, byte for byte as before.
    for path in ["src/generated/mobile_base.rs", "src/generated/types.rs"] {
        std::fs::write(out.join(path), "// edited\n").unwrap();
    }
    let third = compile(&root, &out, "fleet");
    let mut rewritten = third.written.clone();
    rewritten.sort();
    assert_eq!(
        rewritten,
        [
            Path::new("src/generated/mobile_base.rs"),
            Path::new("src/generated/types.rs")
        ]
    );
    assert_eq!(contents, snapshot(&out));

    // A changed description: every generated file gets the new inputs' hash in its
    // header, and only its own module changes below the header. The others' formatted
    // bodies come from the cache under the new header.
    let motion = src.join("motion_controller.cool");
    let text = std::fs::read_to_string(&motion).unwrap();
    let changed = text.replacen("automaton {", "exception extra;\n    automaton {", 1);
    assert_ne!(changed, text);
    std::fs::write(&motion, changed).unwrap();
    let fourth = compile(&root, &out, "fleet");
    let mut generated: Vec<&Path> = first
        .written
        .iter()
        .map(PathBuf::as_path)
        .filter(|p| p.starts_with("src/generated") || *p == Path::new("build.rs"))
        .collect();
    assert!(generated.len() >= 5, "{generated:?}");
    let mut written: Vec<&Path> = fourth.written.iter().map(PathBuf::as_path).collect();
    generated.sort();
    written.sort();
    assert_eq!(written, generated, "{fourth:?}");
    let body = |text: &str| text.split_once('\n').unwrap().1.to_owned();
    for (path, old) in watched.iter().zip(&contents) {
        let new = std::fs::read_to_string(out.join(path)).unwrap();
        if path.starts_with("src/generated/") && *path != "src/generated/motion_controller.rs" {
            assert_eq!(body(&new), body(old), "{path} changed below its header");
            assert_ne!(new.lines().next(), old.lines().next(), "{path}");
        }
    }
}
