//! Compiles the robot's `.cool` descriptions into `$OUT_DIR/cool.rs` with
//! `coolc::Builder`; a description error fails the build and shows the diagnostics.

fn main() {
    let descriptions = ["../components/mobile_base.cool"];
    if let Err(error) = coolc::Builder::new().compile(&descriptions) {
        eprintln!("{error}");
        std::process::exit(1);
    }
}
