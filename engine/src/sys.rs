//! Facts about this process.

/// Peak resident set size of this process in bytes (Linux `VmHWM`), or 0
/// where unknown.
pub fn peak_rss_bytes() -> u64 {
    status_kib("VmHWM:") * 1024
}

/// Current resident set size in bytes (Linux `VmRSS`), or 0 where unknown.
pub fn rss_bytes() -> u64 {
    status_kib("VmRSS:") * 1024
}

fn status_kib(key: &str) -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with(key))
                .and_then(|l| l.split_whitespace().nth(1))
                .and_then(|v| v.parse().ok())
        })
        .unwrap_or(0)
}

/// Number of CPUs available to this process.
pub fn cpus() -> usize {
    std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1)
}

/// Memory available for new work (Linux `MemAvailable`), or `None`.
pub fn mem_available_bytes() -> Option<u64> {
    meminfo_bytes("MemAvailable:")
}

/// The machine's physical memory (Linux `MemTotal`), or `None`.
pub fn mem_total_bytes() -> Option<u64> {
    meminfo_bytes("MemTotal:")
}

fn meminfo_bytes(key: &str) -> Option<u64> {
    std::fs::read_to_string("/proc/meminfo").ok().and_then(|s| {
        s.lines()
            .find(|l| l.starts_with(key))
            .and_then(|l| l.split_whitespace().nth(1))
            .and_then(|v| v.parse::<u64>().ok())
            .map(|k| k * 1024)
    })
}

/// The default memory budget: half of the memory available now (1 GiB if
/// that is unknown).
pub fn default_memory_budget() -> u64 {
    mem_available_bytes().map_or(1 << 30, |m| (m / 2).max(64 << 20))
}

/// Makes a write past the file-size limit (`ulimit -f`, RLIMIT_FSIZE) fail
/// with EFBIG, which the renderer reports and cleans up after, instead of
/// killing the process with SIGXFSZ and leaving partial files behind.
#[cfg(unix)]
pub fn report_file_size_limit_as_error() {
    // SAFETY: signal(2) takes two integers and touches no memory of ours.
    // SIG_IGN installs no handler, so no code of ours ever runs in signal
    // context (the hazard of signal handlers); SIGXFSZ is a valid signal
    // number; a disposition is process-wide, and setting it is sound from
    // any thread at any time.
    unsafe {
        libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
    }
}

#[cfg(not(unix))]
pub fn report_file_size_limit_as_error() {}

/// Makes freed memory go back to the system, so that the process's
/// resident size follows what the memory budget accounts for. glibc serves
/// allocations above a threshold with their own mappings, unmapped when
/// freed, but by default raises that threshold to the size of any such
/// block freed (up to 32 MiB): after the first phase gives its buffers
/// back, the next phase's buffers come from the heap, which keeps freed
/// memory, and the resident size outgrows the budget by the heap's
/// fragments. A fixed threshold (which turns the raising off) and a
/// heap trimmed past 1 MiB keep it honest.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
pub fn return_freed_memory_to_the_system() {
    // SAFETY: mallopt(3) takes two integers and changes glibc's allocator
    // parameters under the allocator's own lock; it is called before any
    // thread of ours starts, and both values are within glibc's ranges
    // (M_MMAP_THRESHOLD at most HEAP_MAX / 2, M_TRIM_THRESHOLD any).
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 256 << 10);
        libc::mallopt(libc::M_TRIM_THRESHOLD, 1 << 20);
    }
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
pub fn return_freed_memory_to_the_system() {}
