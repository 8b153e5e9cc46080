//! The `coolc` command-line front end.

fn main() {
    eprintln!("coolc: not built yet");
    std::process::exit(2);
}
