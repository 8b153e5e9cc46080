//! Compiles every description under `cool/` into `$OUT_DIR/cool.rs` with
//! `coolc::Builder`: the components the network tests run.

use std::path::PathBuf;

fn main() {
    let mut files: Vec<PathBuf> = match std::fs::read_dir("cool") {
        Ok(entries) => entries
            .filter_map(|entry| entry.ok().map(|entry| entry.path()))
            .filter(|path| path.extension().is_some_and(|ext| ext == "cool"))
            .collect(),
        Err(error) => {
            eprintln!("cannot read cool/: {error}");
            std::process::exit(1);
        }
    };
    // One order whatever the directory's: the generated file is the same every time.
    files.sort();
    println!("cargo::rerun-if-changed=cool");
    if let Err(error) = coolc::Builder::new().compile(&files) {
        eprintln!("{error}");
        std::process::exit(1);
    }
}
