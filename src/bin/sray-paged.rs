//! `sray-paged`: `sray` with the file-backed global allocator
//! (`sray_engine::paging`), for the paper's Table 2 experiment, where the
//! depth-first tracer renders scenes larger than its memory and pages as
//! the paper's RayShade paged through swap (`sray bench table2` runs its
//! depth-first renders with it).
//!
//! The allocator passes every allocation to the system allocator until a
//! depth-first render (`render --mode df`) of a scene larger than its
//! `--memory` budget turns paging on; from then on, large allocations are
//! mappings of an unnamed temporary file in `--tmp-dir`. `sray` itself
//! never installs it: there, such a render stays in ordinary memory and
//! says so.

#[global_allocator]
static ALLOC: sray_engine::paging::PagingAlloc = sray_engine::paging::PagingAlloc;

fn main() -> std::process::ExitCode {
    sray_cli::run()
}
