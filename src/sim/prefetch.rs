//! A hint to the memory system: load a value into the caches ahead of its use.

/// Asks the caches for the value at `item` (a hint: a prefetch never faults, whatever
/// the address, and changes no result). Nothing on targets without the instruction.
#[inline(always)]
pub fn prefetch<T>(item: *const T) {
    #[cfg(target_arch = "x86_64")]
    {
        use core::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        // SAFETY: a prefetch does not access memory architecturally and never faults.
        unsafe { _mm_prefetch::<_MM_HINT_T0>(item.cast::<i8>()) };
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = item;
}
