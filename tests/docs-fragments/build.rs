//! Compiles the description the API fragments of the docs name (`cool/fragments.cool`)
//! into `$OUT_DIR/cool.rs` with `coolc::Builder`, and writes `$OUT_DIR/fragments.rs`:
//! each fragment of `places::FRAGMENTS`, read from its doc, in a function of its own
//! (after a comment naming the doc, line and heading it comes from, so that a compiler
//! error in it says which block of the docs no longer compiles), then `COMPILED`, what
//! was compiled from where.

use std::collections::BTreeSet;
use std::fmt::Write as _;
use std::path::PathBuf;

mod places;

fn main() {
    if let Err(error) = coolc::Builder::new().compile(&["cool/fragments.cool"]) {
        eprintln!("{error}");
        std::process::exit(1);
    }
    println!("cargo::rerun-if-changed=places.rs");
    let mut functions = String::new();
    let mut compiled = String::new();
    let mut docs = BTreeSet::new();
    for (index, (place, before)) in places::FRAGMENTS.iter().enumerate() {
        docs.insert(place.doc);
        let fence = place.fence();
        write!(
            functions,
            "\n/// {}:{}, under {:?}.\n\
             fn fragment_{index}() -> Result<(), Box<dyn std::error::Error>> {{\n\
             {before}{}Ok(())\n}}\n",
            place.doc, fence.line, place.heading, fence.body
        )
        .unwrap();
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
    let out = PathBuf::from(std::env::var_os("OUT_DIR").expect("OUT_DIR is set"));
    let path = out.join("fragments.rs");
    if let Err(error) = std::fs::write(&path, text) {
        eprintln!("cannot write {}: {error}", path.display());
        std::process::exit(1);
    }
}
