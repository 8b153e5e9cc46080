//! Compiles `gate.cool` into `$OUT_DIR/cool.rs` with `coolc::Builder`: the component
//! the compile-fail cases implement.

fn main() {
    if let Err(error) = coolc::Builder::new().compile(&["gate.cool"]) {
        eprintln!("{error}");
        std::process::exit(1);
    }
}
