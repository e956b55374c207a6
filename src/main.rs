//! The `sray` binary: the command line ([`cli`]) over the engine, the
//! cluster's coordinator and worker, and the benchmarks.

mod cli;

/// The system allocator, until a depth-first render of a scene larger than
/// its memory budget turns on file-backed large allocations (see
/// `sray_engine::paging`).
#[global_allocator]
static ALLOC: sray_engine::paging::PagingAlloc = sray_engine::paging::PagingAlloc;

fn main() -> std::process::ExitCode {
    sray_engine::sys::report_file_size_limit_as_error();
    sray_engine::sys::return_freed_memory_to_the_system();
    cli::main()
}
