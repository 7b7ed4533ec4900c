//! Large pages for large buffers: the memory allocator the `mipray` binary installs.
//!
//! A frame's walks and lookups jump across tens of megabytes (tree nodes, triangle packs,
//! per-slot shading data, texture levels) in an order no cache predicts. With 4 KiB pages
//! most of those jumps also miss the TLB and wait for a page walk before the load can even
//! start; a 2 MiB page maps 512 times as much, so the same jumps stay within the pages the
//! TLB holds. [`LargePageAllocator`] gives every allocation of at least [`LARGE`] (2 MiB)
//! its own mapping, rounded up to whole 2 MiB pages and aligned to one:
//!
//! 1. from the kernel's reserved pool of huge pages (`MAP_HUGETLB`), which exists only where
//!    an administrator reserved one (`sysctl vm.nr_hugepages=N`); the kernel reserves the
//!    pages when the mapping is made, so a pool too small fails here, never later;
//! 2. otherwise as ordinary memory marked for transparent huge pages (`MADV_HUGEPAGE`),
//!    which the kernel backs with 2 MiB pages where its setting
//!    (`/sys/kernel/mm/transparent_hugepage/enabled`) is `madvise` or `always` and it has
//!    them to give, and with 4 KiB pages otherwise.
//!
//! Smaller allocations (with glibc's thresholds set as its own rules would set them had
//! it seen the large ones, see [`keep_small_blocks_in_the_heap`]), and every allocation
//! once the allocator is turned off
//! ([`turn_off`], which the binary calls for `MIPRAY_LARGE_PAGES=off`), go to the system
//! allocator. Outside Linux everything does.
//!
//! Invariant: whether a block is one of this allocator's mappings is decided by its layout
//! and the allocator's state alone ([`maps`]), and the state is settled (on or off) before
//! the first large block is made and never changes after, so a block is always released
//! the way it was made.
//!
//! A released mapping is kept for reuse ([`Spares`]: at most [`MAX_SPARES`] of them and
//! [`MAX_SPARE_BYTES`] in all, the oldest given back to the kernel first) and handed to the
//! next allocation of the same rounded length. Why: the frame loop makes and drops some
//! large buffers every frame (on BART Kitchen two mappings a frame), and a fresh mapping
//! is fresh pages, each faulted in and zeroed by the kernel again; the system allocator
//! keeps freed memory for the next block instead. The cost that remains is up to 2 MiB of
//! rounding a block, the spares' memory, and a zeroing pass where a zeroed block reuses a
//! spare (BENCHMARKS.md has the measured effect on whole frames).

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::Mutex;
use std::sync::atomic::{AtomicU8, Ordering};

/// The smallest allocation that gets a mapping of its own, and the page size it is rounded
/// up and aligned to: x86-64's and AArch64's (4 KiB granule) huge page.
pub const LARGE: usize = 2 << 20;

/// Not settled yet: turns on at the first large allocation unless [`turn_off`] came first.
const UNSETTLED: u8 = 0;
const ON: u8 = 1;
const OFF: u8 = 2;

static STATE: AtomicU8 = AtomicU8::new(UNSETTLED);

/// The allocator (a unit type: its state is this module's, one per process).
pub struct LargePageAllocator;

/// Turns the allocator off for the rest of the process, if no large block was made yet:
/// everything then goes to the system allocator. Returns whether it is off.
pub fn turn_off() -> bool {
    let _ = STATE.compare_exchange(UNSETTLED, OFF, Ordering::AcqRel, Ordering::Acquire);
    STATE.load(Ordering::Acquire) == OFF
}

/// Settles the allocator on, if it was not settled yet (the binary that installs it calls
/// this or [`turn_off`] first, so [`is_in_use`] answers from the start). Returns whether it
/// is on.
pub fn turn_on() -> bool {
    is_on()
}

/// Whether large allocations get mappings of their own (settling the state to on if it was
/// not settled yet). Never outside Linux, where everything goes to the system allocator.
fn is_on() -> bool {
    if !cfg!(target_os = "linux") {
        return false;
    }
    if STATE
        .compare_exchange(UNSETTLED, ON, Ordering::AcqRel, Ordering::Acquire)
        .is_ok()
    {
        keep_small_blocks_in_the_heap();
    }
    STATE.load(Ordering::Acquire) == ON
}

/// Tells the C library's allocator (glibc's), which keeps every block below [`LARGE`], to
/// keep its freed memory as it would had it seen the large blocks itself.
///
/// Why: glibc raises its own thresholds as it frees large blocks (a freed mapping of `n`
/// bytes, up to 32 MiB, makes blocks below `n` come from its heap, and lets its heap keep
/// up to `2 n` free at the top before giving memory back). Once the large blocks are
/// mapped here it sees none, keeps its starting thresholds (128 KiB) and gives back, at
/// the end of every frame, the freed memory the next frame takes again: on BART Kitchen
/// about 730 page faults a frame on one thread (none with the system allocator alone), on
/// BART Robots about 870 on two (75); 2 and 24 with the thresholds set here
/// (docs/benchmark-log.md). Here blocks below [`LARGE`] come from its heap and
/// the heap keeps up to [`HEAP_KEEPS`] free, the most glibc's own rule keeps. Set once,
/// when the allocator turns on; a C library without these settings is left as it is.
fn keep_small_blocks_in_the_heap() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: `mallopt` only changes the C allocator's thresholds; it is called before
    // this allocator hands out its first block and takes the C allocator's own lock.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, LARGE as libc::c_int);
        libc::mallopt(libc::M_TRIM_THRESHOLD, HEAP_KEEPS as libc::c_int);
    }
}

/// The most free memory the C library's heap keeps at its top once the allocator is on:
/// twice glibc's largest dynamic mapping threshold (32 MiB on 64-bit systems).
pub const HEAP_KEEPS: usize = 64 << 20;

/// Whether the allocator is installed and on: turned on (or it has made a large block)
/// and not turned off first.
pub fn is_in_use() -> bool {
    STATE.load(Ordering::Acquire) == ON
}

/// How much of this process's memory the kernel backs with huge pages right now, in KiB:
/// transparent ones (`AnonHugePages`) and the reserved pool's (`Private_Hugetlb`), as
/// `/proc/self/smaps_rollup` reports them; `None` where it cannot be read.
pub fn huge_page_kib() -> Option<(u64, u64)> {
    let text = std::fs::read_to_string("/proc/self/smaps_rollup").ok()?;
    let field = |name: &str| {
        text.lines().find_map(|l| {
            l.strip_prefix(name)?
                .trim()
                .strip_suffix("kB")?
                .trim()
                .parse()
                .ok()
        })
    };
    Some((
        field("AnonHugePages:")?,
        field("Private_Hugetlb:").unwrap_or(0),
    ))
}

/// Whether a block of `layout` is (or is to be) one of this allocator's mappings.
#[inline]
fn maps(layout: Layout) -> bool {
    layout.size() >= LARGE && layout.align() <= LARGE && is_on()
}

/// `size` rounded up to whole large pages (`size` is at least [`LARGE`], far below
/// `usize::MAX`: a `Layout`'s size is at most `isize::MAX`).
#[inline]
fn mapped_len(size: usize) -> usize {
    size.div_ceil(LARGE) * LARGE
}

/// Most released mappings kept for reuse.
pub const MAX_SPARES: usize = 16;

/// Most bytes the kept mappings may hold together: a frame's large buffers come to tens of
/// megabytes (BART Kitchen at 800x600), so one frame's set fits; a larger block is given
/// back to the kernel at once.
pub const MAX_SPARE_BYTES: usize = 256 << 20;

/// Released mappings kept for reuse, oldest first: `(address, length)`, lengths multiples
/// of [`LARGE`]. A fixed array, so keeping and taking one never allocates (this is the
/// allocator).
struct Spares {
    blocks: [(usize, usize); MAX_SPARES],
    count: usize,
    bytes: usize,
}

impl Spares {
    const EMPTY: Spares = Spares {
        blocks: [(0, 0); MAX_SPARES],
        count: 0,
        bytes: 0,
    };

    /// Takes the most recently kept mapping of exactly `len` bytes, if any.
    fn take(&mut self, len: usize) -> Option<*mut u8> {
        let i = self.blocks[..self.count]
            .iter()
            .rposition(|&(_, l)| l == len)?;
        let (p, _) = self.remove(i);
        Some(p as *mut u8)
    }

    /// Keeps the mapping `(p, len)`; returns the mappings to give back to the kernel to
    /// stay within the limits (the oldest kept ones, or this one itself when it alone is
    /// over [`MAX_SPARE_BYTES`]), at most [`MAX_SPARES`] + 1 of them.
    fn keep(&mut self, p: *mut u8, len: usize) -> Released {
        let mut released = Released::default();
        if len > MAX_SPARE_BYTES {
            released.push((p as usize, len));
            return released;
        }
        while self.count == MAX_SPARES || self.bytes + len > MAX_SPARE_BYTES {
            released.push(self.remove(0));
        }
        self.blocks[self.count] = (p as usize, len);
        self.count += 1;
        self.bytes += len;
        released
    }

    fn remove(&mut self, i: usize) -> (usize, usize) {
        let block = self.blocks[i];
        self.blocks.copy_within(i + 1..self.count, i);
        self.count -= 1;
        self.bytes -= block.1;
        block
    }
}

/// Mappings to give back to the kernel once the lock on [`SPARES`] is released.
#[derive(Default)]
struct Released {
    blocks: [(usize, usize); MAX_SPARES + 1],
    count: usize,
}

impl Released {
    fn push(&mut self, block: (usize, usize)) {
        self.blocks[self.count] = block;
        self.count += 1;
    }
}

static SPARES: Mutex<Spares> = Mutex::new(Spares::EMPTY);

/// The spares, locked. Nothing panics while the lock is held, but a poisoned lock would
/// still hold a consistent list, so it is used as it is.
fn spares() -> std::sync::MutexGuard<'static, Spares> {
    SPARES
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// A mapping of `len` bytes (a multiple of [`LARGE`]): a kept one of that length, else a
/// fresh one; its first `zeroed` bytes (at most `len`) zero (a fresh mapping already is all
/// zero; a kept one is cleared that far). Null where the kernel makes none.
#[cfg(target_os = "linux")]
fn obtain(len: usize, zeroed: usize) -> *mut u8 {
    debug_assert!(zeroed <= len);
    let kept = spares().take(len);
    match kept {
        Some(p) => {
            // SAFETY: `p` is a kept mapping of `len >= zeroed` writable bytes, now this
            // block's alone.
            unsafe { std::ptr::write_bytes(p, 0, zeroed) };
            p
        }
        None => map::map(len),
    }
}

/// Releases the mapping `(p, len)`: kept for reuse, or given back to the kernel (with any
/// kept ones it displaces).
///
/// # Safety
/// `p` and `len` must be a live mapping [`obtain`] handed out, not used after this.
#[cfg(target_os = "linux")]
unsafe fn release(p: *mut u8, len: usize) {
    let released = spares().keep(p, len);
    for &(q, l) in &released.blocks[..released.count] {
        // SAFETY: every released block was a mapping of this length (kept, or `p` itself),
        // no longer kept, so nothing hands it out again.
        unsafe { map::unmap(q as *mut u8, l) };
    }
}

#[cfg(target_os = "linux")]
mod map {
    use super::LARGE;

    /// A fresh private anonymous mapping of `len` bytes with the extra `flags`, if the
    /// kernel makes it.
    fn anonymous(len: usize, flags: libc::c_int) -> Option<*mut libc::c_void> {
        // SAFETY: an anonymous private mapping at an address of the kernel's choosing
        // touches no existing memory; the result is checked before use.
        let p = unsafe {
            libc::mmap(
                std::ptr::null_mut(),
                len,
                libc::PROT_READ | libc::PROT_WRITE,
                libc::MAP_PRIVATE | libc::MAP_ANONYMOUS | flags,
                -1,
                0,
            )
        };
        (p != libc::MAP_FAILED).then_some(p)
    }

    /// `len` bytes (a multiple of [`LARGE`]) from the reserved pool, if it has them.
    pub(super) fn from_pool(len: usize) -> Option<*mut u8> {
        anonymous(len, libc::MAP_HUGETLB).map(|p| p.cast())
    }

    /// `len` bytes (a multiple of [`LARGE`]) of ordinary memory aligned to [`LARGE`] and
    /// advised for transparent huge pages (a kernel without them ignores the advice).
    pub(super) fn advised(len: usize) -> Option<*mut u8> {
        // One large page more than asked, so an aligned start lies inside; the ends are
        // given back. (The kernel backs a range with huge pages only where it is aligned.)
        let whole = len.checked_add(LARGE)?;
        let p = anonymous(whole, 0)?;
        let start = p as usize;
        let aligned = start.next_multiple_of(LARGE);
        let head = aligned - start;
        let tail = whole - len - head;
        // SAFETY: both ranges lie inside the mapping just made and outside the part kept;
        // `munmap` of part of a mapping leaves the rest mapped. A failure would only leave
        // a range mapped that is never touched, so the results are not needed.
        unsafe {
            if head > 0 {
                libc::munmap(p, head);
            }
            if tail > 0 {
                libc::munmap((aligned + len) as *mut libc::c_void, tail);
            }
            // Advice only: where it is refused the memory works the same in small pages.
            libc::madvise(aligned as *mut libc::c_void, len, libc::MADV_HUGEPAGE);
        }
        Some(aligned as *mut u8)
    }

    /// A mapping for `len` bytes: from the pool, else advised ordinary memory.
    pub(super) fn map(len: usize) -> *mut u8 {
        from_pool(len)
            .or_else(|| advised(len))
            .unwrap_or(std::ptr::null_mut())
    }

    /// Releases a mapping of `len` bytes at `p`, of either kind.
    ///
    /// # Safety
    /// `p` and `len` must be a mapping `map` made (and not released yet).
    pub(super) unsafe fn unmap(p: *mut u8, len: usize) {
        // SAFETY: the caller's promise.
        unsafe { libc::munmap(p.cast(), len) };
    }
}

// SAFETY: every block is either the system allocator's (made and released by `System`
// with the same layout) or a private mapping of exactly `mapped_len(layout.size())` bytes
// (fresh, or kept from an earlier block of the same rounded length and used by nothing
// else while kept), aligned to `LARGE` (at least `layout.align()`, which `maps` checks) and
// released (kept or unmapped) with that same length; `maps` gives the same answer for a
// layout at its release as at its allocation (see the module's invariant).
unsafe impl GlobalAlloc for LargePageAllocator {
    #[inline]
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        #[cfg(target_os = "linux")]
        if maps(layout) {
            return obtain(mapped_len(layout.size()), 0);
        }
        // SAFETY: the caller's promise (a layout of non-zero size), passed on.
        unsafe { System.alloc(layout) }
    }

    #[inline]
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        #[cfg(target_os = "linux")]
        if maps(layout) {
            return obtain(mapped_len(layout.size()), layout.size());
        }
        // SAFETY: as in `alloc`.
        unsafe { System.alloc_zeroed(layout) }
    }

    #[inline]
    unsafe fn dealloc(&self, p: *mut u8, layout: Layout) {
        #[cfg(target_os = "linux")]
        if maps(layout) {
            // SAFETY: a block of this layout was obtained here (the module's invariant),
            // with its length rounded the same way, and the caller is done with it.
            return unsafe { release(p, mapped_len(layout.size())) };
        }
        // SAFETY: the caller's promise; the block is `System`'s (see `alloc`).
        unsafe { System.dealloc(p, layout) }
    }

    unsafe fn realloc(&self, p: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        // SAFETY (the whole body): the caller promises `p` is a live block of `layout` and
        // `new_size` a valid size for its alignment; each path below releases `p` only after
        // its contents are copied into the new block.
        let new_layout = unsafe { Layout::from_size_align_unchecked(new_size, layout.align()) };
        match (maps(layout), maps(new_layout)) {
            (false, false) => unsafe { System.realloc(p, layout, new_size) },
            // Within the same whole pages (a vector growing into its rounding): in place.
            (true, true) if mapped_len(layout.size()) == mapped_len(new_size) => p,
            _ => unsafe {
                let q = self.alloc(new_layout);
                if !q.is_null() {
                    std::ptr::copy_nonoverlapping(p, q, layout.size().min(new_size));
                    self.dealloc(p, layout);
                }
                q
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    // The tests call the allocator directly (the test binary keeps the system allocator);
    // the state they settle (on) is this test process's.
    const A: LargePageAllocator = LargePageAllocator;

    fn layout(size: usize, align: usize) -> Layout {
        Layout::from_size_align(size, align).unwrap()
    }

    /// Fills a block with a pattern of its offsets and checks it back.
    fn fill_and_check(p: *mut u8, len: usize, seed: u8) {
        // SAFETY: `p` is a live block of at least `len` bytes.
        let block = unsafe { std::slice::from_raw_parts_mut(p, len) };
        for (i, b) in block.iter_mut().enumerate() {
            *b = (i as u8).wrapping_mul(31).wrapping_add(seed);
        }
        assert!(
            block
                .iter()
                .enumerate()
                .all(|(i, &b)| b == (i as u8).wrapping_mul(31).wrapping_add(seed))
        );
    }

    #[test]
    fn a_large_block_is_aligned_writable_and_zeroed_when_asked() {
        for size in [LARGE, LARGE + 1, 3 * LARGE + 12_345, 9 * LARGE] {
            let l = layout(size, 64);
            // SAFETY: a layout of non-zero size; released with the same layout below.
            unsafe {
                let z = A.alloc_zeroed(l);
                assert!(!z.is_null());
                let zeroed = std::slice::from_raw_parts(z, size);
                assert!(zeroed.iter().all(|&b| b == 0), "{size}");
                let p = A.alloc(l);
                assert!(!p.is_null());
                if cfg!(target_os = "linux") {
                    assert_eq!(p as usize % LARGE, 0, "{size}");
                    assert_eq!(z as usize % LARGE, 0, "{size}");
                    assert!(is_in_use());
                }
                fill_and_check(p, size, 7);
                // The other block was not written through this one.
                assert!(zeroed.iter().all(|&b| b == 0), "{size}");
                A.dealloc(p, l);
                A.dealloc(z, l);
            }
        }
    }

    #[test]
    fn small_blocks_keep_their_alignment() {
        for (size, align) in [
            (1, 1),
            (24, 8),
            (4096, 4096),
            (LARGE - 1, 64),
            (100, 4 * LARGE),
        ] {
            let l = layout(size, align);
            // SAFETY: as above.
            unsafe {
                let p = A.alloc(l);
                assert!(!p.is_null());
                assert_eq!(p as usize % align, 0, "{size} {align}");
                fill_and_check(p, size, 3);
                A.dealloc(p, l);
            }
        }
    }

    /// Growing and shrinking across the threshold and across whole pages keeps the
    /// contents; growing within a block's rounding keeps its address.
    #[test]
    fn realloc_keeps_contents_across_the_threshold() {
        // SAFETY: every block is live and of the layout passed with it.
        unsafe {
            let mut l = layout(1000, 16);
            let mut p = A.alloc(l);
            fill_and_check(p, 1000, 1);
            for new_size in [
                LARGE - 8,
                LARGE + 8,
                LARGE + 4096,
                5 * LARGE + 1,
                300,
                3 * LARGE,
            ] {
                let before: Vec<u8> = std::slice::from_raw_parts(p, l.size()).to_vec();
                let q = A.realloc(p, l, new_size);
                assert!(!q.is_null());
                let kept = l.size().min(new_size);
                assert_eq!(
                    std::slice::from_raw_parts(q, kept),
                    &before[..kept],
                    "{new_size}"
                );
                if cfg!(target_os = "linux")
                    && maps(l)
                    && new_size >= LARGE
                    && mapped_len(l.size()) == mapped_len(new_size)
                {
                    assert_eq!(q, p, "grown within its pages");
                }
                l = layout(new_size, 16);
                p = q;
                fill_and_check(p, new_size, new_size as u8);
            }
            A.dealloc(p, l);
        }
    }

    /// Both kinds of mapping directly: the pool's only where this machine reserved one.
    #[cfg(target_os = "linux")]
    #[test]
    fn both_kinds_of_mapping_are_aligned_zeroed_and_released() {
        let len = 2 * LARGE;
        let advised = map::advised(len).expect("an ordinary mapping");
        assert_eq!(advised as usize % LARGE, 0);
        // SAFETY: a fresh mapping of `len` bytes, released once below.
        unsafe {
            assert!(
                std::slice::from_raw_parts(advised, len)
                    .iter()
                    .all(|&b| b == 0)
            );
            fill_and_check(advised, len, 9);
            map::unmap(advised, len);
        }
        match map::from_pool(len) {
            Some(p) => {
                assert_eq!(p as usize % LARGE, 0);
                // SAFETY: as above.
                unsafe {
                    fill_and_check(p, len, 5);
                    map::unmap(p, len);
                }
            }
            None => println!("no reserved pool of huge pages here: its mapping was not tried"),
        }
    }

    /// A released block comes back for the next one of its rounded length, and a zeroed
    /// one comes back zero whatever was written into it before.
    #[cfg(target_os = "linux")]
    #[test]
    fn a_released_block_is_reused_and_cleared_when_zeroed() {
        // A length no other test uses, so no test running alongside takes the spare.
        let l = layout(11 * LARGE - 100, 64);
        // SAFETY: live blocks of layout `l`, each released once.
        unsafe {
            let p = A.alloc(l);
            assert!(!p.is_null());
            fill_and_check(p, l.size(), 11);
            A.dealloc(p, l);
            let q = A.alloc_zeroed(l);
            assert_eq!(q, p, "the kept mapping is reused");
            assert!(
                std::slice::from_raw_parts(q, l.size())
                    .iter()
                    .all(|&b| b == 0)
            );
            fill_and_check(q, l.size(), 12);
            A.dealloc(q, l);
            // A length in the same whole pages reuses it too; without zeroing, the block
            // is simply writable (its old contents are the caller's to overwrite).
            let shorter = layout(10 * LARGE + 1, 64);
            let r = A.alloc(shorter);
            assert_eq!(r, p);
            fill_and_check(r, shorter.size(), 13);
            A.dealloc(r, shorter);
        }
    }

    /// The kept list stays within its limits, gives back the oldest first, and hands out
    /// only exact lengths, newest first. On the list alone (no memory is touched).
    #[test]
    fn spares_keep_the_newest_within_their_limits() {
        let mut spares = Spares::EMPTY;
        let released: Vec<(usize, usize)> = (1..=MAX_SPARES + 2)
            .flat_map(|i| {
                let r = spares.keep((i * LARGE * 64) as *mut u8, LARGE);
                r.blocks[..r.count].to_vec()
            })
            .collect();
        assert_eq!(spares.count, MAX_SPARES);
        assert_eq!(spares.bytes, MAX_SPARES * LARGE);
        assert_eq!(released, [(LARGE * 64, LARGE), (2 * LARGE * 64, LARGE)]);
        assert_eq!(spares.take(2 * LARGE), None, "only exact lengths");
        let newest = ((MAX_SPARES + 2) * LARGE * 64) as *mut u8;
        assert_eq!(spares.take(LARGE), Some(newest));
        assert_eq!(spares.count, MAX_SPARES - 1);
        // A block over the byte limit alone is given back at once, nothing displaced.
        let r = spares.keep(std::ptr::null_mut(), MAX_SPARE_BYTES + LARGE);
        assert_eq!(&r.blocks[..r.count], [(0, MAX_SPARE_BYTES + LARGE)]);
        assert_eq!(spares.count, MAX_SPARES - 1);
        // One that fits only once older ones go displaces just enough of them.
        let big = MAX_SPARE_BYTES - 4 * LARGE;
        let r = spares.keep(std::ptr::null_mut(), big);
        assert!(spares.bytes <= MAX_SPARE_BYTES && spares.count <= MAX_SPARES);
        assert_eq!(r.count, MAX_SPARES - 1 - 4, "{:?}", &r.blocks[..r.count]);
        assert_eq!(spares.bytes, big + 4 * LARGE);
    }

    #[test]
    fn lengths_round_up_to_whole_large_pages() {
        assert_eq!(mapped_len(LARGE), LARGE);
        assert_eq!(mapped_len(LARGE + 1), 2 * LARGE);
        assert_eq!(mapped_len(7 * LARGE - 1), 7 * LARGE);
    }
}
