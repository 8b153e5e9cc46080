//! The `coolc` command-line front end (see `coolc::cli`).

use clap::Parser;

fn main() -> std::process::ExitCode {
    coolc::cli::run(coolc::cli::Cli::parse())
}
