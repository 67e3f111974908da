//! The `aobake` command: the service and its command-line tools.

use clap::Parser as _;

fn main() -> std::process::ExitCode {
    let cli = aobake_server::cli::Cli::parse();
    match aobake_server::cli::run(cli) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(err) => {
            if let Some(exit) = err.downcast_ref::<aobake_server::cli::client::Exit>() {
                eprintln!("{}", exit.message);
                return std::process::ExitCode::from(exit.code);
            }
            eprintln!("error: {err:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
