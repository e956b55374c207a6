//! The `sray` binary: a thin shell over the coordinator crate, which owns the
//! command line.

fn main() -> std::process::ExitCode {
    sray_coordinator::cli::main()
}
