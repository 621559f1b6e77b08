//! The `occmask` binary: parse arguments, run, map the outcome to an exit code.

mod cli;

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    let args = match cli::Args::try_parse() {
        Ok(args) => args,
        Err(err) => {
            // --help and --version are "errors" to clap that go to stdout with success.
            let code = if err.use_stderr() { cli::EXIT_USAGE } else { 0 };
            let _ = err.print();
            return ExitCode::from(code);
        }
    };
    match cli::run(args) {
        Ok(outcome) => ExitCode::from(outcome.exit_code()),
        Err(err) => {
            eprintln!("error: {err:#}");
            ExitCode::from(if cli::interrupted(&err) {
                cli::EXIT_INTERRUPTED
            } else {
                cli::EXIT_ERROR
            })
        }
    }
}
