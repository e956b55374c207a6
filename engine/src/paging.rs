//! File-backed memory for large allocations, so that a depth-first render
//! of a scene larger than memory pages to disk, as the paper's RayShade
//! did through swap, instead of being killed.
//!
//! [`PagingAlloc`] is a global allocator that passes every allocation to
//! the system allocator until [`enable`] is called; from then on, each
//! allocation of [`THRESHOLD`] bytes or more is a shared mapping of a fresh
//! region of one unnamed temporary file. Those pages are ordinary page
//! cache: under memory pressure (a cgroup limit, say) the kernel writes
//! them back to the file and drops them, and faults them in again on use.
//! Regions are reserved on disk when they are mapped (`fallocate`), so a
//! full disk is a failed mapping, which falls back to the system allocator,
//! and never a `SIGBUS` later; freed regions are unmapped and their disk
//! space released (`FALLOC_FL_PUNCH_HOLE`). File offsets are never reused,
//! so a new region is all zeroes.
//!
//! Only the paging experiment's binary, `sray-paged`, installs the
//! allocator (`src/bin/sray-paged.rs`); `sray`, libraries and tests do
//! not, and see [`enable`] return `false`.

use std::alloc::{GlobalAlloc, Layout, System};
use std::path::Path;
use std::sync::atomic::{AtomicBool, AtomicI32, AtomicU64, AtomicUsize, Ordering};

/// Allocations at least this large are file-backed once paging is on.
pub const THRESHOLD: usize = 1 << 20;
const PAGE: usize = 4096;
/// Most file-backed regions alive at once; beyond, the system allocator.
const MAX_REGIONS: usize = 4096;

/// The allocator. Install with `#[global_allocator]`.
pub struct PagingAlloc;

static INSTALLED: AtomicBool = AtomicBool::new(false);
static FD: AtomicI32 = AtomicI32::new(-1);
static NEXT: AtomicU64 = AtomicU64::new(0);
static MAPPED: AtomicU64 = AtomicU64::new(0);
static PEAK_MAPPED: AtomicU64 = AtomicU64::new(0);

/// Live regions: start address (0 = free slot), length, file offset.
struct Region {
    ptr: AtomicUsize,
    len: AtomicUsize,
    off: AtomicU64,
}

#[allow(clippy::declare_interior_mutable_const)]
const FREE: Region = Region {
    ptr: AtomicUsize::new(0),
    len: AtomicUsize::new(0),
    off: AtomicU64::new(0),
};
static REGIONS: [Region; MAX_REGIONS] = [FREE; MAX_REGIONS];

/// Turns paging on: large allocations from now on live in an unnamed file
/// in `dir`. Returns false if [`PagingAlloc`] is not the global allocator
/// (nothing changes then).
pub fn enable(dir: &Path) -> std::io::Result<bool> {
    // Any allocation made through the allocator marks it installed; make
    // one to be sure the flag reflects this process.
    drop(std::hint::black_box(Vec::<u8>::with_capacity(1)));
    if !INSTALLED.load(Ordering::Relaxed) {
        return Ok(false);
    }
    if FD.load(Ordering::Acquire) >= 0 {
        return Ok(true);
    }
    let f = tempfile::tempfile_in(dir)?;
    let fd = std::os::fd::AsRawFd::as_raw_fd(&f);
    if FD
        .compare_exchange(-1, fd, Ordering::AcqRel, Ordering::Acquire)
        .is_ok()
    {
        // The file stays open (and mapped) for the rest of the process.
        std::mem::forget(f);
    }
    Ok(true)
}

/// Whether large allocations are file-backed now.
pub fn enabled() -> bool {
    FD.load(Ordering::Relaxed) >= 0
}

/// Bytes in file-backed regions now, and at most so far.
pub fn mapped_bytes() -> (u64, u64) {
    (
        MAPPED.load(Ordering::Relaxed),
        PEAK_MAPPED.load(Ordering::Relaxed),
    )
}

/// A slot being filled: never a valid address.
const CLAIMED: usize = 1;

fn register(ptr: usize, len: usize, off: u64) -> bool {
    for r in REGIONS.iter() {
        // Claim the slot, fill it, then publish the address: a reader that
        // sees the address sees the length and offset too.
        if r.ptr
            .compare_exchange(0, CLAIMED, Ordering::Acquire, Ordering::Relaxed)
            .is_ok()
        {
            r.len.store(len, Ordering::Relaxed);
            r.off.store(off, Ordering::Relaxed);
            r.ptr.store(ptr, Ordering::Release);
            return true;
        }
    }
    false
}

fn unregister(ptr: usize) -> Option<(usize, u64)> {
    for r in REGIONS.iter() {
        if r.ptr.load(Ordering::Acquire) == ptr {
            let found = (r.len.load(Ordering::Relaxed), r.off.load(Ordering::Relaxed));
            r.ptr.store(0, Ordering::Release);
            return Some(found);
        }
    }
    None
}

/// Gives the disk space of `off..off + len` of our file back; the range is
/// never used again.
fn release(fd: i32, off: u64, len: usize) {
    // SAFETY: fallocate(2) takes integers only and touches no memory of
    // ours; `fd` is our own file's descriptor, and punching a hole (size
    // kept) in a range no live mapping uses changes nothing anyone reads.
    unsafe {
        libc::fallocate(
            fd,
            libc::FALLOC_FL_PUNCH_HOLE | libc::FALLOC_FL_KEEP_SIZE,
            off as libc::off_t,
            len as libc::off_t,
        );
    }
}

impl PagingAlloc {
    /// A file-backed region for `layout`, or None (then the system
    /// allocator serves it).
    fn map(&self, layout: Layout) -> Option<*mut u8> {
        let fd = FD.load(Ordering::Acquire);
        if fd < 0 || layout.size() < THRESHOLD || layout.align() > PAGE {
            return None;
        }
        let len = layout.size().checked_add(PAGE - 1)? & !(PAGE - 1);
        // A range of the file no region has used: it reads as zeroes.
        let off = NEXT.fetch_add(len as u64, Ordering::Relaxed);
        // SAFETY: fallocate(2) takes integers only and touches no memory of
        // ours; `fd` is our own descriptor, open for the rest of the
        // process (see `enable`), so it names our file and nothing else.
        if unsafe { libc::fallocate(fd, 0, off as libc::off_t, len as libc::off_t) } != 0 {
            return None;
        }
        // SAFETY: with a null address hint and no MAP_FIXED the kernel
        // picks addresses that no live mapping or allocation uses, so the
        // new mapping aliases no memory of this process (Rust's or
        // anyone's). Its pages are backed by `off..off + len` of our file,
        // which was just reserved on disk, so touching them cannot raise
        // SIGBUS for want of space; the file is unnamed and no other
        // process has it, so no one can truncate or rewrite it under us.
        let p = unsafe {
            libc::mmap(
                std::ptr::null_mut(),
                len,
                libc::PROT_READ | libc::PROT_WRITE,
                libc::MAP_SHARED,
                fd,
                off as libc::off_t,
            )
        };
        if p == libc::MAP_FAILED {
            release(fd, off, len);
            return None;
        }
        if !register(p as usize, len, off) {
            // SAFETY: `p..p + len` is the mapping just made, which no one
            // else has seen: unmapping it invalidates no reference.
            unsafe { libc::munmap(p, len) };
            release(fd, off, len);
            return None;
        }
        let now = MAPPED.fetch_add(len as u64, Ordering::Relaxed) + len as u64;
        PEAK_MAPPED.fetch_max(now, Ordering::Relaxed);
        Some(p.cast())
    }
}

// SAFETY: every block returned is either the system allocator's (for the
// same layout) or a fresh page-aligned mapping at least `layout.size()`
// long, used only for layouts aligned to a page or less, and zeroed (a
// never-used range of the file) as `alloc_zeroed` promises. A mapping is
// in the live-region table, under its start address, from before it is
// returned until it is deallocated; a system block cannot start at the
// address of a live mapping (they would overlap). So `dealloc`, given a
// block and its layout, tells the two apart by that table (only blocks of
// at least THRESHOLD bytes can be mappings) and returns each to where it
// came from. `realloc` passes to the system allocator only while paging
// is off, when no mapping exists (see there); otherwise it is the default
// alloc, copy, dealloc, which keeps all of the above.
// Nothing here allocates, panics or unwinds, so the allocator never
// re-enters itself.
unsafe impl GlobalAlloc for PagingAlloc {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        INSTALLED.store(true, Ordering::Relaxed);
        match self.map(layout) {
            Some(p) => p,
            // SAFETY: the caller's contract for `alloc` is passed on.
            None => unsafe { System.alloc(layout) },
        }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        INSTALLED.store(true, Ordering::Relaxed);
        match self.map(layout) {
            // A fresh region of the file reads as zeroes.
            Some(p) => p,
            // SAFETY: the caller's contract is passed on.
            None => unsafe { System.alloc_zeroed(layout) },
        }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if FD.load(Ordering::Acquire) < 0 {
            // Paging is off, and it has always been: `FD` is set once and
            // never cleared, and mappings are made only once it is set. So
            // `ptr` is the system allocator's block for `layout`, and its
            // own realloc may grow it in place or move its pages (mremap)
            // instead of copying them into freshly faulted memory. Paging
            // turned on meanwhile changes nothing for this block: its
            // successor is a system block too, which `dealloc` tells from a
            // mapping by the region table.
            // SAFETY: the caller's contract for `realloc` is passed on, and
            // the block is the system allocator's (above).
            return unsafe { System.realloc(ptr, layout, new_size) };
        }
        // SAFETY: `new_size` and the layout's alignment make a valid layout
        // (the caller's contract for `realloc`).
        let new_layout = unsafe { Layout::from_size_align_unchecked(new_size, layout.align()) };
        // SAFETY: `new_layout` has a non-zero size (the caller's contract).
        let new = unsafe { self.alloc(new_layout) };
        if !new.is_null() {
            // SAFETY: both blocks are live and distinct, each at least
            // min(old, new size) long; then the old block, which the caller
            // gives up, returns to where it came from.
            unsafe {
                std::ptr::copy_nonoverlapping(ptr, new, layout.size().min(new_size));
                self.dealloc(ptr, layout);
            }
        }
        new
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        if layout.size() >= THRESHOLD
            && let Some((len, off)) = unregister(ptr as usize)
        {
            // SAFETY: `ptr..ptr + len` is a mapping of ours (it was in the
            // table under this address, and `unregister` took it out, so no
            // other call can unmap it again), and the caller of `dealloc`
            // gives the block up: nothing uses these pages any more.
            unsafe { libc::munmap(ptr.cast(), len) };
            // The region was mapped, so the descriptor was set; it never
            // changes after.
            release(FD.load(Ordering::Acquire), off, len);
            MAPPED.fetch_sub(len as u64, Ordering::Relaxed);
            return;
        }
        // SAFETY: not a live mapping of ours (too small to be one, or not
        // in the table), so the system allocator's block for this layout,
        // which the caller gives up.
        unsafe { System.dealloc(ptr, layout) }
    }
}
