//! The starter files a crate gets when `coolc compile` creates it: the calls of
//! `src/main.rs` (the components no compound instantiates, run as a process, and the
//! registry of every component type for the network layer) and one test per atomic
//! component in `tests/components.rs`.

use std::collections::BTreeSet;

use crate::ident;
use crate::ir::{self, Code};

/// The starter code of `krate`.
pub(super) fn starter(krate: &ir::Crate) -> ir::Starter {
    let instantiated: BTreeSet<&str> = krate
        .compounds
        .iter()
        .flat_map(|c| c.instances.iter().map(|i| i.component.as_str()))
        .collect();
    let lib = &krate.lib_name;
    // `::lib::generated::module::function`, the user's `::lib::module::Struct`.
    let generated =
        |module: &str, function: &str| format!("::{lib}::generated::{module}::{function}");
    let default = |module: &str, user: &str| {
        Code::call(format!("::{lib}::{module}::{user}::default"), Vec::new())
    };
    let converters = |uses: bool| {
        if uses {
            format!("::<::{lib}::converters::Convert>")
        } else {
            String::new()
        }
    };
    // Each component type: its module, its user struct, whether it is a compound and
    // its generic arguments.
    let components = krate
        .atomics
        .iter()
        .map(|c| {
            (
                &c.module,
                &c.user_struct,
                &c.type_name,
                false,
                String::new(),
            )
        })
        .chain(krate.compounds.iter().map(|c| {
            (
                &c.module,
                &c.user_struct,
                &c.type_name,
                true,
                converters(c.uses_converters),
            )
        }));
    let mut registrations = Vec::new();
    let mut roots = Vec::new();
    for (module, user, type_name, compound, generics) in components {
        let component = generated(module, &format!("component{generics}"));
        registrations.push(Code::call(
            generated(module, "register"),
            vec![
                Code::atom("&mut registry"),
                Code::closure(
                    "name",
                    Code::Block(
                        Vec::new(),
                        Box::new(Code::call(
                            component.as_str(),
                            vec![Code::atom("name"), default(module, user)],
                        )),
                    ),
                ),
            ],
        ));
        if !instantiated.contains(type_name.as_str()) {
            let name = Code::atom(ident::string_literal(module.trim_start_matches("r#")));
            let root = Code::call(component, vec![name, default(module, user)]);
            roots.push(if compound { root.try_op() } else { root });
        }
    }
    let tests = krate
        .atomics
        .iter()
        .map(|c| {
            let module = &c.module;
            let harness = Code::atom("harness");
            ir::StarterTest {
                name: format!(
                    "{}_runs_for_a_second_without_error",
                    module.trim_start_matches("r#")
                ),
                behavior: default(module, &c.user_struct),
                harness: Code::call(
                    generated(module, "Harness::running"),
                    vec![Code::atom("behavior")],
                )
                .method("unwrap", Vec::new()),
                check: Code::call(
                    "assert_eq!",
                    vec![
                        harness.clone().method("error", Vec::new()),
                        Code::atom("None"),
                        Code::string(&format!("{} is in {{}}", c.type_name)),
                        harness.method("state", Vec::new()),
                    ],
                ),
            }
        })
        .collect();
    ir::Starter {
        roots,
        registrations,
        tests,
    }
}
