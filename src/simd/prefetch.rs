//! Cache hints for the frame update's scattered accesses: its passes walk one order (source
//! triangles, or the dirty list) while reading or writing per-slot arrays and packs in
//! another (the BVH's), so each access would be a cache miss; the index a few steps ahead
//! is known, and a hint issued that far ahead hides most of the miss.

/// Hints the cache to load the line holding `p`. Never faults (a prefetch reads and writes
/// nothing), so any address is fine; a no-op on targets without a hint.
#[inline(always)]
pub fn prefetch_ptr<T>(p: *const T) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: SSE is part of x86-64, and a prefetch touches no memory.
    unsafe {
        std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(p.cast())
    };
    #[cfg(not(target_arch = "x86_64"))]
    let _ = p;
}

/// Hints the cache to load `items[i]` (nothing when `i` is out of range).
#[inline(always)]
pub fn prefetch<T>(items: &[T], i: usize) {
    if let Some(item) = items.get(i) {
        prefetch_ptr(item);
    }
}
