//! `coolc::Builder` from a real build script: a crate whose `build.rs` compiles a
//! description into `OUT_DIR`, includes it, implements the behavior, and runs the
//! component in its own test; a broken description fails the build showing the
//! rendered diagnostic.

use crate::common;

use std::path::Path;

use common::{cargo, runtime};
use coolc::ir::RuntimeDep;

const LAMP: &str = "\
atomic Lamp {
    observable level: u32 = 0;
    timing { period 10ms; }
    automaton {
        initial dark;
        state dark { entry; may -> lit; }
        state lit { periodic; }
    }
}
";

const LIB: &str = r#"
pub mod generated {
    include!(concat!(env!("OUT_DIR"), "/cool.rs"));
}

use generated::lamp::{Behavior, Cx, DarkMay};

#[derive(Default)]
pub struct Lamp;

impl Behavior for Lamp {
    fn dark_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        cx.vars.level = 1;
        Ok(())
    }

    fn dark_choose(&mut self, _cx: &mut Cx<'_>) -> Option<DarkMay> {
        Some(DarkMay::Lit)
    }

    fn lit_periodic(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        cx.vars.level += 1;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn lamp_lights_up() {
        let mut system = coolbot::System::new();
        let lamp = system.add(super::generated::lamp::component("lamp", super::Lamp)).unwrap();
        system.run_all().unwrap();
        lamp.wait_for(
            |m| {
                m.user_state.as_deref() == Some("lit")
                    && m.variables.iter().any(|(n, v)| n == "level" && matches!(v, coolbot::Value::UInt(l) if *l >= 5))
            },
            std::time::Duration::from_secs(20),
        )
        .unwrap();
        system.shutdown();
    }
}
"#;

#[test]
fn builder_in_a_build_script() {
    let dir = tempfile::tempdir().unwrap();
    let krate = dir.path();
    let RuntimeDep::Path(runtime) = runtime() else {
        unreachable!()
    };
    let coolc = Path::new(env!("CARGO_MANIFEST_DIR"))
        .canonicalize()
        .unwrap();
    std::fs::write(
        krate.join("Cargo.toml"),
        format!(
            "[package]\nname = \"lamp\"\nversion = \"0.1.0\"\nedition = \"2024\"\n\n\
             [dependencies]\ncoolbot = {{ path = {runtime:?} }}\n\
             serde = {{ version = \"1\", features = [\"derive\"] }}\n\n\
             [build-dependencies]\ncoolc = {{ path = {:?} }}\n",
            coolc.display().to_string()
        ),
    )
    .unwrap();
    std::fs::write(
        krate.join("build.rs"),
        "fn main() {\n    coolc::Builder::new().compile(&[\"lamp.cool\"]).unwrap();\n}\n",
    )
    .unwrap();
    std::fs::write(krate.join("lamp.cool"), LAMP).unwrap();
    std::fs::create_dir_all(krate.join("src")).unwrap();
    std::fs::write(krate.join("src/lib.rs"), LIB).unwrap();

    let output = cargo(krate, &["test", "--lib"]);
    assert!(
        output.contains("test tests::lamp_lights_up ... ok"),
        "{output}"
    );

    // A broken description fails the build with the rendered diagnostic.
    std::fs::write(
        krate.join("lamp.cool"),
        LAMP.replace("initial dark;", "initial dark"),
    )
    .unwrap();
    let failed = common::gen_cargo(krate).args(["build"]).output().unwrap();
    assert!(!failed.status.success());
    let stderr = String::from_utf8_lossy(&failed.stderr);
    assert!(stderr.contains("coolc::syntax"), "{stderr}");
    assert!(stderr.contains("lamp.cool"), "{stderr}");
}

/// The compile-fail cases' crate (`tests/compile-fail`) holds the code `coolc`
/// generates from its `gate.cool` checked in, so that the build of the cases needs no
/// `coolc`: it must be what `coolc` generates today. With `COOLC_BLESS=1` the test
/// writes it instead (then run the cases, with `COOLC_BLESS=1` too if their messages
/// moved).
#[test]
fn generated_code_of_the_compile_fail_cases_is_current() {
    let crate_dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/compile-fail");
    let out = tempfile::tempdir().expect("temporary directory");
    let description = crate_dir.join("gate.cool");
    let generated = coolc::Builder::new()
        .out_dir(out.path())
        .cargo_output(false)
        .compile(&[&description])
        .expect("gate.cool compiles");
    // The header names the description as the crate's directory sees it.
    let generated = std::fs::read_to_string(generated)
        .expect("generated code")
        .replacen(
            &format!(" from {}; ", description.display()),
            " from gate.cool; ",
            1,
        );
    let checked_in_path = crate_dir.join("src/cool.rs");
    let checked_in = std::fs::read_to_string(&checked_in_path).unwrap_or_default();
    if generated == checked_in {
        return;
    }
    if std::env::var_os("COOLC_BLESS").is_some_and(|v| v == "1") {
        std::fs::write(&checked_in_path, generated).expect("write src/cool.rs");
        return;
    }
    panic!(
        "{} is not what coolc generates from gate.cool today: run \
         `COOLC_BLESS=1 cargo test -p coolc --test all generated_code_of_the_compile_fail_cases_is_current`, \
         then `COOLC_BLESS=1 cargo test -p coolbot-compile-fail` and review both diffs",
        checked_in_path.display()
    );
}
