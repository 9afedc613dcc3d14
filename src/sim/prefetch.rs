//! A hint to the memory system: load a value into the caches ahead of its use.

/// Asks the caches for the value at `item` (a hint: a prefetch never faults, whatever
/// the address, and changes no result). Nothing on targets without the instruction.
///
/// The line is asked into the second-level cache, not the first: a contact's
/// resolution reads eight lines (two disks' positions and velocities), and with eight
/// contacts fetched ahead the first level's few outstanding misses were likely the
/// limit (inferred from timings). At 10⁶ disks and packing 0.3 the second-level hint
/// ran 1.055× as fast as the first-level one (`docs/performance.md`, Resolution order).
#[inline(always)]
pub fn prefetch<T>(item: *const T) {
    #[cfg(target_arch = "x86_64")]
    {
        use core::arch::x86_64::{_MM_HINT_T1, _mm_prefetch};
        // SAFETY: a prefetch does not access memory architecturally and never faults.
        unsafe { _mm_prefetch::<_MM_HINT_T1>(item.cast::<i8>()) };
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = item;
}
