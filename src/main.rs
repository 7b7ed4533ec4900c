//! `mipray`: render animated scenes with ray-length MIP-map level selection.
//! The command line lives in `mipray::cli`; this file only reports errors.

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    match mipray::cli::run(mipray::cli::Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("error: {error:#}");
            ExitCode::FAILURE
        }
    }
}
