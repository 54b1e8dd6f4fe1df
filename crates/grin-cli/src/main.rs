//! `grin`: the one binary. Subcommands only parse arguments, call the libraries and print.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// Gradient-index renderer: trace, bake, render and inspect GRIN media.
#[derive(Debug, Parser)]
#[command(name = "grin", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Ray table in, ray table out.
    Trace(cmd::trace::Args),
    /// Bake a scene's field into a .grinf file.
    Bake(cmd::bake::Args),
    /// Render a scene to EXR (+ PNG preview).
    Render(cmd::render::Args),
    /// Real-time viewer.
    View(cmd::view::Args),
    /// Show what is inside a .vdb or .grinf file.
    Info(cmd::info::Args),
    /// Export a baked field to OpenVDB.
    Export(cmd::export::Args),
    /// Generate a dataset for learning (BOS, schlieren or heat-haze pairs with ground truth).
    Dataset(cmd::dataset::Args),
    /// Speed-vs-accuracy charts, stability matrix, speed ratios.
    Bench(cmd::bench::Args),
}

/// 128 + SIGPIPE, what a shell reports for a process killed by a closed pipe.
const SIGPIPE_EXIT_CODE: i32 = 141;

/// Print a line on stdout. `grin info x.vdb | head` closes stdout early: that is the reader
/// being done (as a SIGPIPE would end a C program, exit 141), not a crash; any other
/// write error ends grin with a one-line error. (`println!` panics on both.)
fn write_stdout(args: std::fmt::Arguments<'_>) {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    if let Err(e) = out.write_fmt(args).and_then(|()| out.write_all(b"\n")) {
        if e.kind() == std::io::ErrorKind::BrokenPipe {
            std::process::exit(SIGPIPE_EXIT_CODE);
        }
        eprintln!(
            "grin: error: cannot write to stdout: {}",
            grin_output::plain(&e)
        );
        std::process::exit(1);
    }
}

/// `println!` for the binary's results: see [`write_stdout`].
macro_rules! outln {
    ($($arg:tt)*) => {
        $crate::write_stdout(format_args!($($arg)*))
    };
}

/// Print a command's result (summary, JSON): on stdout, or on stderr where the command's
/// own output went to a stream (`-o -`, a device), which may be stdout itself.
fn report(output_is_stream: bool, text: impl std::fmt::Display) {
    if output_is_stream {
        eprintln!("{text}");
    } else {
        write_stdout(format_args!("{text}"));
    }
}

/// `text` with its control characters but line ends escaped (`\u{0}`, `\u{1b}`): an error
/// that quotes a user's input must not write a NUL or a terminal escape to the terminal.
fn printable(text: &str) -> String {
    text.chars()
        .map(|c| {
            if c.is_control() && c != '\n' {
                c.escape_default().to_string()
            } else {
                c.to_string()
            }
        })
        .collect()
}

/// Whether `output` is written into a stream (`-`, a device, a FIFO) rather than a file.
fn is_stream(output: &std::path::Path) -> bool {
    grin_output::Destination::resolve(output).is_ok_and(|d| d.is_stream())
}

mod cmd;

fn main() -> ExitCode {
    // Started by ourselves to try a VDB file in a child process (crash isolation).
    if let Some(code) = vdb_sys::checker_entry() {
        std::process::exit(code);
    }
    if let Err(e) = vdb_sys::use_current_exe_as_checker() {
        eprintln!("grin: warning: {e}");
    }
    if let Err(e) = grin_output::install_signal_cleanup() {
        eprintln!("grin: warning: {e}");
    }
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Trace(a) => cmd::trace::run(a),
        Command::Bake(a) => cmd::bake::run(a),
        Command::Render(a) => cmd::render::run(a),
        Command::View(a) => cmd::view::run(a),
        Command::Info(a) => cmd::info::run(a),
        Command::Export(a) => cmd::export::run(a),
        Command::Bench(a) => cmd::bench::run(a),
        Command::Dataset(a) => cmd::dataset::run(a),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("grin: error: {}", printable(&format!("{e:#}")));
            ExitCode::FAILURE
        }
    }
}
