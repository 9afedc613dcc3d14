//! Large allocations on transparent huge pages: the global allocator of every collide
//! binary. The disks' arrays, the neighbour lists and the grid of a large scene span
//! tens of megabytes that the step reads out of order; on 4 KiB pages most of those
//! reads also miss the TLB. Linux backs an anonymous range with 2 MiB pages when asked
//! (`madvise(MADV_HUGEPAGE)`, honoured under the kernel's default `madvise` setting of
//! `/sys/kernel/mm/transparent_hugepage/enabled`).
//!
//! Allocations of at least [`MIN_ADVISED_BYTES`] are advised, and only their whole
//! 2 MiB pages; everything else, and every other platform, is the system allocator's.
//! The advice changes speed only: bits, results and errors are the same without it
//! (the kernel may ignore it, as it does when the setting is `never`).

use std::alloc::{GlobalAlloc, Layout, System};

/// The system allocator, advising the kernel to back large allocations with huge pages.
pub struct HugePageAllocator;

/// The size of a transparent huge page on x86-64 and on most aarch64 kernels.
const HUGE_PAGE_BYTES: usize = 2 << 20;

/// Smaller allocations are left alone: they hold few whole huge pages, and the system
/// call would cost more than it saves.
pub const MIN_ADVISED_BYTES: usize = 4 * HUGE_PAGE_BYTES;

// SAFETY: every allocation is the system allocator's, returned unchanged; the advice
// only tells the kernel how to back pages the allocation owns.
unsafe impl GlobalAlloc for HugePageAllocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        // SAFETY: the caller's contract, passed on.
        advised(unsafe { System.alloc(layout) }, layout.size())
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        // SAFETY: the caller's contract, passed on.
        advised(unsafe { System.alloc_zeroed(layout) }, layout.size())
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        // SAFETY: the caller's contract, passed on.
        advised(unsafe { System.realloc(ptr, layout, new_size) }, new_size)
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: the caller's contract, passed on.
        unsafe { System.dealloc(ptr, layout) }
    }
}

/// `ptr` (an allocation of `size` bytes, or null), after advising the kernel to back
/// its whole huge pages with huge pages when it is large.
fn advised(ptr: *mut u8, size: usize) -> *mut u8 {
    if size >= MIN_ADVISED_BYTES && !ptr.is_null() {
        advise_huge_pages(ptr, size);
    }
    ptr
}

/// The whole huge pages inside `size` bytes from `address`, if any.
fn whole_huge_pages(address: usize, size: usize) -> Option<std::ops::Range<usize>> {
    let start = address.next_multiple_of(HUGE_PAGE_BYTES);
    let end = (address + size) / HUGE_PAGE_BYTES * HUGE_PAGE_BYTES;
    (end > start).then_some(start..end)
}

#[cfg(target_os = "linux")]
fn advise_huge_pages(ptr: *mut u8, size: usize) {
    if let Some(pages) = whole_huge_pages(ptr as usize, size) {
        // SAFETY: the range lies inside an allocation this process owns; the advice
        // neither moves nor frees memory. A failure (an old kernel, THP compiled out)
        // leaves the pages as they were, which is correct, only slower.
        unsafe {
            libc::madvise(
                pages.start as *mut libc::c_void,
                pages.len(),
                libc::MADV_HUGEPAGE,
            );
        }
    }
}

#[cfg(not(target_os = "linux"))]
fn advise_huge_pages(_ptr: *mut u8, _size: usize) {}

#[cfg(test)]
mod tests {
    use super::{HUGE_PAGE_BYTES, MIN_ADVISED_BYTES, whole_huge_pages};

    /// The advised range is whole huge pages inside the allocation, and nothing when the
    /// allocation holds no whole page.
    #[test]
    fn only_whole_huge_pages_inside_the_allocation_are_advised() {
        const PAGE: usize = HUGE_PAGE_BYTES;
        for (address, size, expected) in [
            (PAGE, 3 * PAGE, Some(PAGE..4 * PAGE)),
            (PAGE + 16, 3 * PAGE, Some(2 * PAGE..4 * PAGE)),
            (PAGE - 16, 3 * PAGE, Some(PAGE..3 * PAGE)),
            (PAGE + 16, PAGE, None),
            (PAGE + 16, 2 * PAGE - 16, Some(2 * PAGE..3 * PAGE)),
        ] {
            let pages = whole_huge_pages(address, size);
            assert_eq!(pages, expected, "{address:#x} + {size:#x}");
            if let Some(pages) = pages {
                assert!(address <= pages.start && pages.end <= address + size);
                assert_eq!(pages.start % PAGE + pages.end % PAGE, 0);
            }
        }
    }

    /// A large buffer of the global allocator is marked for huge pages by the kernel
    /// (`hg` in its mapping's flags), where the kernel has them, and holds what was
    /// written through growth by reallocation.
    #[test]
    #[cfg(target_os = "linux")]
    fn a_large_buffer_is_advised_and_keeps_its_contents() {
        let n = MIN_ADVISED_BYTES / 8 + 12_345;
        let mut values: Vec<u64> = (0..n as u64).collect();
        values.extend(0..n as u64);
        assert!(values.iter().enumerate().all(|(i, &v)| v == (i % n) as u64));
        if !std::path::Path::new("/sys/kernel/mm/transparent_hugepage").exists() {
            return;
        }
        let address = values.as_ptr() as usize + HUGE_PAGE_BYTES;
        let smaps = std::fs::read_to_string("/proc/self/smaps").expect("smaps is readable");
        let mut in_mapping = false;
        let mut flags = None;
        for line in smaps.lines() {
            let range = line.split_whitespace().next().and_then(|first| {
                let (start, end) = first.split_once('-')?;
                Some(usize::from_str_radix(start, 16).ok()?..usize::from_str_radix(end, 16).ok()?)
            });
            match range {
                Some(range) => in_mapping = range.contains(&address),
                None if in_mapping && line.starts_with("VmFlags:") => flags = Some(line.to_owned()),
                None => {}
            }
        }
        let flags = flags.expect("the buffer's mapping is listed");
        assert!(flags.split_whitespace().any(|flag| flag == "hg"), "{flags}");
    }
}
