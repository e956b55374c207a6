//! The `sray` binary: the command line (`sray_cli`) with the system
//! allocator. The file-backed allocator that the paper's paging experiment
//! needs is in `sray-paged` only (`src/bin/sray-paged.rs`).

fn main() -> std::process::ExitCode {
    sray_cli::run()
}
