//! The `aobake` command: the service and its command-line tools.

use clap::Parser as _;

/// jemalloc, not glibc's malloc: glibc kept what a burst of large uploads
/// freed in its per-thread arenas (a server grew from 43 to 138 MB over
/// five passes of the same hostile corpus and stayed there), while
/// jemalloc with background purging (turned on by `serve`) gives freed
/// pages back to the system (a test holds the server under a stated
/// bound: tests/tests/integration/bad_input.rs). mimalloc was tried and
/// kept more resident.
#[global_allocator]
static ALLOCATOR: tikv_jemallocator::Jemalloc = tikv_jemallocator::Jemalloc;

/// A command whose output goes to a pipe that closes (`aobake params |
/// head`) ends quietly with 141 (128 + SIGPIPE, what a shell reports for a
/// Unix tool killed by it) instead of a panic and a backtrace: `println!`
/// panics on a closed stdout, and Rust ignores SIGPIPE (restoring it needs
/// `unsafe`, which this workspace forbids).
fn quiet_on_closed_pipe() {
    let default = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let payload = info.payload();
        let message = payload
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| payload.downcast_ref::<&str>().copied())
            .unwrap_or_default();
        if message.starts_with("failed printing to stdout") && message.contains("Broken pipe") {
            std::process::exit(141);
        }
        default(info);
    }));
}

/// Where no desktop session is (a container, a service, CI:
/// `XDG_RUNTIME_DIR` unset), Mesa's Vulkan device-select layer still
/// tries to reach a Wayland display at every Vulkan instance a command
/// opens (wgpu enables the Wayland surface extension wherever it exists),
/// and libwayland prints "error: XDG_RUNTIME_DIR is invalid or not set in
/// the environment" twice per command, which reads as a failure. Without
/// a session that layer has no display to choose a device by, so the
/// process runs itself again in place (exec: the same pid, arguments and
/// streams) with the layer off (`NODEVICE_SELECT=1`), unless a device was
/// chosen through it (`MESA_VK_DEVICE_SELECT`). Setting the variable
/// in-process would need `unsafe`, which this workspace forbids.
#[cfg(target_os = "linux")]
fn no_display_layer_without_a_session() {
    use std::os::unix::process::CommandExt as _;
    let unset = |name: &str| std::env::var_os(name).is_none();
    if !(unset("XDG_RUNTIME_DIR") && unset("NODEVICE_SELECT") && unset("MESA_VK_DEVICE_SELECT")) {
        return;
    }
    let Ok(exe) = std::env::current_exe() else {
        return;
    };
    let mut args = std::env::args_os();
    let mut again = std::process::Command::new(exe);
    if let Some(arg0) = args.next() {
        again.arg0(arg0);
    }
    // Returns only if the exec failed: then go on as we are.
    let _ = again.args(args).env("NODEVICE_SELECT", "1").exec();
}

fn main() -> std::process::ExitCode {
    #[cfg(target_os = "linux")]
    no_display_layer_without_a_session();
    let cli = aobake_server::cli::Cli::parse();
    if !cli.is_service() {
        quiet_on_closed_pipe();
    }
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
