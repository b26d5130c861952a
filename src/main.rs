//! The `clothsr` command: parses arguments and calls the library (see `cli/`).

mod cli;

use std::io::Write;

fn main() {
    let code = cli::run();
    let _ = std::io::stdout().flush();
    let _ = std::io::stderr().flush();
    exit_now(code)
}

/// Ends the process without running C++ static destructors. usd-core's destructors race its
/// own TBB worker threads at exit ("pure virtual method called", then SIGABRT) — seen once in
/// CI after a USD parse error had been reported, turning exit code 2 into a crash. Every Rust
/// value is dropped and every file written (atomically) before this point, and stdio is flushed.
#[allow(unsafe_code)]
fn exit_now(code: i32) -> ! {
    // SAFETY: `_exit` only ends the process; nothing of ours is left to run.
    unsafe { libc::_exit(code) }
}
