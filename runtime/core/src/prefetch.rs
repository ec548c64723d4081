//! A software prefetch hint: ask the cache for a line that a loop will
//! read soon, so that a search hopping through memory in an order no
//! hardware prefetcher can guess does not wait for it.
//!
//! A hint only: it never faults (any address may be given, inside an
//! allocation or not), never changes memory, and does nothing on targets
//! without one (everything but x86-64 here).

/// Asks for the cache line holding the byte `offset` bytes from `base` to
/// be brought into every cache level (`PREFETCHT0`). `offset` may lead
/// outside `base`'s allocation: the address is only a hint.
#[inline(always)]
pub fn prefetch_read<T>(base: *const T, offset: isize) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        let at = base.cast::<i8>().wrapping_offset(offset);
        // SAFETY: a prefetch reads nothing the program sees and never
        // faults, whatever the address.
        unsafe { _mm_prefetch::<_MM_HINT_T0>(at) };
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (base, offset);
}

#[cfg(test)]
mod tests {
    use super::prefetch_read;

    /// Addresses inside, at the edges of and far outside an allocation
    /// (and null) are all taken without a fault, and memory is unchanged.
    #[test]
    fn any_address_is_only_a_hint() {
        let v = vec![7u64; 64];
        for off in [0, 8, 511, 512, -64, -4096, 1 << 40, isize::MIN / 2] {
            prefetch_read(v.as_ptr(), off);
        }
        prefetch_read(std::ptr::null::<u8>(), 0);
        assert!(v.iter().all(|&x| x == 7));
    }
}
