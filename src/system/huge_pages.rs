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
//!
//! Large allocations also start at staggered offsets within a 4 KiB page
//! ([`STAGGER_FROM_BYTES`]). The system allocator maps each large allocation on its own
//! pages, so arrays of equal length (a disk's x, y, vx and vy) would all start at the
//! same offset in a page, and the step, reading the same index of each, would find them
//! in the same first-level cache sets: measured at 2·10⁵ disks, the resolution of
//! contacts took 2.3× as long as with the arrays apart.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

/// The system allocator, advising the kernel to back large allocations with huge pages.
pub struct HugePageAllocator;

/// The size of a transparent huge page on x86-64 and on most aarch64 kernels.
const HUGE_PAGE_BYTES: usize = 2 << 20;

/// Smaller allocations are left alone: they hold few whole huge pages, and the system
/// call would cost more than it saves.
pub const MIN_ADVISED_BYTES: usize = 4 * HUGE_PAGE_BYTES;

/// Allocations of at least this many bytes (and alignment at most [`STAGGER_ALIGN`])
/// start at one of [`STAGGERS`] offsets in a page, in turn.
pub const STAGGER_FROM_BYTES: usize = 64 << 10;

/// The offsets are multiples of this, from one of it: a cache line's alignment, and room
/// before the allocation for the offset itself.
const STAGGER_ALIGN: usize = 64;

/// Offsets taken in turn: 8 × 512 bytes span a 4 KiB page.
const STAGGERS: usize = 8;
const STAGGER_STEP: usize = 512;

/// The next allocation's turn.
static NEXT_STAGGER: AtomicUsize = AtomicUsize::new(0);

/// Whether an allocation of `layout` is staggered.
fn is_staggered(layout: Layout) -> bool {
    layout.size() >= STAGGER_FROM_BYTES && layout.align() <= STAGGER_ALIGN
}

/// What a staggered allocation of `layout` takes from the system: room for the largest
/// offset in front (`None` past the largest size an allocation may have).
fn padded(layout: Layout) -> Option<Layout> {
    let front = STAGGER_ALIGN + (STAGGERS - 1) * STAGGER_STEP;
    Layout::from_size_align(layout.size().checked_add(front)?, STAGGER_ALIGN).ok()
}

/// A staggered allocation in `base` (null passes through): the address at the turn's
/// offset, with the offset written just before it for [`unstaggered`].
fn staggered(base: *mut u8) -> *mut u8 {
    if base.is_null() {
        return base;
    }
    let turn = NEXT_STAGGER.fetch_add(1, Ordering::Relaxed) % STAGGERS;
    let offset = STAGGER_ALIGN + turn * STAGGER_STEP;
    // SAFETY: `padded` left `offset` bytes (at most its front) before the caller's bytes,
    // and the offset's word lies in them, aligned (the offset is a multiple of 64).
    unsafe {
        let ptr = base.add(offset);
        ptr.cast::<usize>().sub(1).write(offset);
        ptr
    }
}

/// The system allocation behind a staggered `ptr`.
///
/// # Safety
/// `ptr` came from [`staggered`].
unsafe fn unstaggered(ptr: *mut u8) -> *mut u8 {
    // SAFETY: [`staggered`] wrote the offset in the word before `ptr`.
    unsafe { ptr.sub(ptr.cast::<usize>().sub(1).read()) }
}

// SAFETY: every allocation is the system allocator's, returned unchanged or (when
// staggered) at an offset inside a larger one that [`unstaggered`] recovers; the advice
// only tells the kernel how to back pages the allocation owns.
unsafe impl GlobalAlloc for HugePageAllocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        // SAFETY: the caller's contract, passed on.
        match (is_staggered(layout), padded(layout)) {
            (true, Some(padded)) => {
                staggered(advised(unsafe { System.alloc(padded) }, layout.size()))
            }
            (true, None) => std::ptr::null_mut(),
            (false, _) => advised(unsafe { System.alloc(layout) }, layout.size()),
        }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        // SAFETY: the caller's contract, passed on.
        match (is_staggered(layout), padded(layout)) {
            (true, Some(padded)) => staggered(advised(
                unsafe { System.alloc_zeroed(padded) },
                layout.size(),
            )),
            (true, None) => std::ptr::null_mut(),
            (false, _) => advised(unsafe { System.alloc_zeroed(layout) }, layout.size()),
        }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let new_layout = Layout::from_size_align(new_size, layout.align()).expect("valid");
        if !is_staggered(layout) && !is_staggered(new_layout) {
            // SAFETY: the caller's contract, passed on.
            return advised(unsafe { System.realloc(ptr, layout, new_size) }, new_size);
        }
        // SAFETY: the caller's contract: `ptr` holds `layout.size()` bytes, and the new
        // allocation is another; the old one is freed as it was allocated.
        unsafe {
            let new = self.alloc(new_layout);
            if !new.is_null() {
                std::ptr::copy_nonoverlapping(ptr, new, layout.size().min(new_size));
                self.dealloc(ptr, layout);
            }
            new
        }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: the caller's contract, passed on; a staggered allocation is freed from
        // its start, with the layout it was made with.
        match (is_staggered(layout), padded(layout)) {
            (true, Some(padded)) => unsafe { System.dealloc(unstaggered(ptr), padded) },
            _ => unsafe { System.dealloc(ptr, layout) },
        }
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
    use super::{HUGE_PAGE_BYTES, MIN_ADVISED_BYTES, STAGGER_FROM_BYTES, whole_huge_pages};

    /// Large arrays of one length, made one after another, start at different offsets in
    /// a page, and keep their contents through growth and shrinking.
    #[test]
    fn large_arrays_start_apart_in_a_page_and_keep_their_contents() {
        let n = STAGGER_FROM_BYTES / 8 * 4;
        let arrays: Vec<Vec<f64>> = (0..4).map(|k| vec![k as f64; n]).collect();
        let mut offsets: Vec<usize> = arrays.iter().map(|a| a.as_ptr() as usize % 4096).collect();
        offsets.sort_unstable();
        offsets.dedup();
        assert_eq!(offsets.len(), 4, "{offsets:?}");
        let mut grown = arrays[3].clone();
        grown.extend(std::iter::repeat_n(7.0, 3 * n));
        assert!(grown[..n].iter().all(|&v| v == 3.0) && grown[n..].iter().all(|&v| v == 7.0));
        grown.truncate(10);
        grown.shrink_to_fit();
        assert_eq!(grown, vec![3.0; 10]);
        let mut small = vec![1u8; 100];
        small.resize(STAGGER_FROM_BYTES * 2, 2);
        assert!(small[..100].iter().all(|&v| v == 1) && small[100..].iter().all(|&v| v == 2));
    }

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
