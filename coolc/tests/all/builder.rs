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
