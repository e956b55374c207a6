//! The `sray` program's command line ([`cli`]) over the engine, the
//! cluster's coordinator and worker, and the benchmarks, shared by its two
//! binaries: `sray` (`src/main.rs`) and `sray-paged`
//! (`src/bin/sray-paged.rs`), the same program with the file-backed
//! allocator of the paper's paging experiment installed.

pub mod cli;

/// What both binaries' `main` does: the process-wide settings, then the
/// command line.
pub fn run() -> std::process::ExitCode {
    sray_engine::sys::report_file_size_limit_as_error();
    sray_engine::sys::return_freed_memory_to_the_system();
    cli::main()
}
