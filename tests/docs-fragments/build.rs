//! Compiles the description the API fragments of the docs name (`cool/fragments.cool`)
//! into `$OUT_DIR/cool.rs` with `coolc::Builder`, and writes `$OUT_DIR/fragments.rs`:
//! each fragment of `places::FRAGMENTS`, read from its doc, in a function of its own,
//! then `COMPILED`, what was compiled from where. Each function is a file of its own
//! named after its place,
//! `$OUT_DIR/fragments/<doc>/<entry>-<heading's anchor>-<index>.rs` (its comment
//! names the doc, line and heading), so that a compiler error in a fragment says
//! which block of the docs no longer compiles.

use std::collections::BTreeSet;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

mod places;

fn main() {
    if let Err(error) = coolc::Builder::new().compile(&["cool/fragments.cool"]) {
        eprintln!("{error}");
        std::process::exit(1);
    }
    println!("cargo::rerun-if-changed=places.rs");
    let out = PathBuf::from(std::env::var_os("OUT_DIR").expect("OUT_DIR is set"));
    let dir = out.join("fragments");
    // What an older table placed elsewhere goes.
    let _ = std::fs::remove_dir_all(&dir);
    let mut functions = String::new();
    let mut compiled = String::new();
    let mut docs = BTreeSet::new();
    for (index, (place, before)) in places::FRAGMENTS.iter().enumerate() {
        docs.insert(place.doc);
        let fence = place.fence();
        let path = dir.join(place.doc).join(format!(
            "{index}-{}-{}.rs",
            anchor(place.heading),
            place.index
        ));
        let function = format!(
            "/// {}:{}, under {:?}.\n\
             fn fragment_{index}() -> Result<(), Box<dyn std::error::Error>> {{\n\
             {before}{}Ok(())\n}}\n",
            place.doc, fence.line, place.heading, fence.body
        );
        write(&path, &function);
        writeln!(functions, "include!({:?});", path.display().to_string()).unwrap();
        writeln!(
            compiled,
            "    Fragment {{ doc: {:?}, heading: {:?}, index: {}, text: {:?} }},",
            place.doc, place.heading, place.index, fence.body
        )
        .unwrap();
    }
    for doc in docs {
        println!(
            "cargo::rerun-if-changed={}",
            places::repository().join(doc).display()
        );
    }
    let text = format!(
        "{functions}\n/// Every fragment compiled above, in `FRAGMENTS`' order.\n\
         pub const COMPILED: &[Fragment] = &[\n{compiled}];\n"
    );
    write(&out.join("fragments.rs"), &text);
}

/// The anchor of a Markdown heading, as GitHub makes it: lowercase, spaces to `-`,
/// without the `#`s and punctuation.
fn anchor(heading: &str) -> String {
    heading
        .trim_start_matches('#')
        .trim()
        .chars()
        .filter_map(|c| match c {
            ' ' | '-' => Some('-'),
            c if c.is_alphanumeric() || c == '_' => Some(c.to_ascii_lowercase()),
            _ => None,
        })
        .collect()
}

/// Writes `text` to `path`, its directory created; ends the build script when it cannot.
fn write(path: &Path, text: &str) {
    let written = path
        .parent()
        .map_or(Ok(()), std::fs::create_dir_all)
        .and_then(|()| std::fs::write(path, text));
    if let Err(error) = written {
        eprintln!("cannot write {}: {error}", path.display());
        std::process::exit(1);
    }
}
