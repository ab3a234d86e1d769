//! The `filterjit` program: process set-up, then the command line (`cli`).

mod cli;

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    // Mesa's Vulkan device-select layer probes for a Wayland/X display and
    // prints errors without one; filterjit chooses its adapter itself
    // (gpu::adapter). Set before any thread exists.
    if std::env::var_os("NODEVICE_SELECT").is_none() {
        std::env::set_var("NODEVICE_SELECT", "1");
    }
    // A reader that stops early (`filterjit simplify E | head -1`) ends the
    // program quietly, as it does other command-line tools, instead of
    // making `println!` panic on the closed pipe.
    #[cfg(unix)]
    // SAFETY: restoring the default action of one signal, before any thread exists.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    let cli = cli::Cli::parse();
    // Compile timings must include the driver's compilation: Mesa would
    // otherwise answer from its on-disk shader cache.
    if matches!(cli.command, cli::Command::Bench(_)) && std::env::var_os("MESA_SHADER_CACHE_DISABLE").is_none() {
        std::env::set_var("MESA_SHADER_CACHE_DISABLE", "true");
    }
    match cli::run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            if let Some(flag) = cli::flag_for(&e) {
                eprintln!("hint: {flag}");
            }
            ExitCode::FAILURE
        }
    }
}
