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

/// Where no desktop session is (a container, a service, CI: no absolute
/// `XDG_RUNTIME_DIR`, no `DISPLAY` or `WAYLAND_DISPLAY`), Mesa's Vulkan
/// device-select layer still tries to reach a Wayland display at every
/// Vulkan instance a command opens (wgpu enables the Wayland surface
/// extension wherever it exists), and libwayland prints "error:
/// XDG_RUNTIME_DIR is invalid or not set in the environment" twice per
/// command, which reads as a failure. Without a session that layer has no
/// display to choose a device by, so a command that opens the GPU runs
/// itself again in place (exec: the same pid, arguments and streams) with
/// the layer off (`NODEVICE_SELECT=1`), unless a device was chosen
/// through it (`MESA_VK_DEVICE_SELECT`, `DRI_PRIME`). Setting the
/// variable in-process would need `unsafe`, which this workspace forbids.
#[cfg(target_os = "linux")]
fn no_display_layer_without_a_session() {
    use std::os::unix::process::CommandExt as _;
    let set = |name: &str| std::env::var_os(name).is_some_and(|v| !v.is_empty());
    let runtime_dir =
        std::env::var_os("XDG_RUNTIME_DIR").is_some_and(|d| std::path::Path::new(&d).is_absolute());
    let session = runtime_dir || set("DISPLAY") || set("WAYLAND_DISPLAY");
    let chosen = set("NODEVICE_SELECT") || set("MESA_VK_DEVICE_SELECT") || set("DRI_PRIME");
    if session || chosen {
        return;
    }
    let mut args = std::env::args_os();
    let Some(arg0) = args.next() else {
        return;
    };
    // Only when this binary is the program (not, say, the dynamic
    // loader that started it, or a wrapper).
    let Ok(exe) = std::env::current_exe() else {
        return;
    };
    if exe.file_name() != std::path::Path::new(&arg0).file_name() {
        return;
    }
    let failed = std::process::Command::new(exe)
        .arg0(&arg0)
        .args(args)
        .env("NODEVICE_SELECT", "1")
        .exec();
    // The exec failed and we go on as we are; it had already put SIGPIPE
    // back to its default (death), which Rust's runtime ignores: a write
    // to a closed pipe or socket must stay an error, not end the process.
    let _ = signal_hook::flag::register(
        signal_hook::consts::SIGPIPE,
        std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false)),
    );
    let _ = failed;
}

fn main() -> std::process::ExitCode {
    let cli = aobake_server::cli::Cli::parse();
    #[cfg(target_os = "linux")]
    if cli.opens_gpu() {
        no_display_layer_without_a_session();
    }
    if !cli.is_service() {
        quiet_on_closed_pipe();
    }
    match aobake_server::cli::run(cli) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(err) => {
            match err.downcast_ref::<aobake_server::cli::client::Exit>() {
                Some(exit) => eprintln!("{}", exit.message),
                None => eprintln!("error: {err:#}"),
            }
            std::process::ExitCode::from(aobake_server::cli::exit_code(&err))
        }
    }
}
