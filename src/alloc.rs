//! Process settings for candle-heavy training: the allocator's thresholds and
//! candle's thread count.
//!
//! glibc serves buffers above its mmap threshold (128 KiB at first) with
//! fresh mappings and returns freed heap tops to the OS; candle's baselines
//! allocate and free tensors of that size on every op, so each one is faulted
//! in again. Measured on LGN (5-spring, 2 epochs): 13.4 s wall, of which 9.7 s
//! system time, against 3.6 s with the thresholds raised. Threads other than
//! the main one allocate from their own arenas, which glibc shrinks unless a
//! top pad keeps them: GNS on the 125-particle cube, 2 epochs on a worker
//! thread (as `reproduce` trains), 12.0 s wall and 4.5 million page faults,
//! against 8.6 s and 1.1 million with the pad (8.5 s on the main thread).
//!
//! candle asks for its thread count on every matrix product and, unless
//! `RAYON_NUM_THREADS` is set, counts the physical cores by parsing
//! `/proc/cpuinfo` each time: LGN, 10 epochs on the 5-spring, 13.8 s wall of
//! which 7.3 s system time, against 3.3 s with the variable set.

/// Prepares the process for candle training: keeps freed memory (raises
/// glibc's mmap threshold to its maximum, 32 MiB on 64-bit, its trim
/// threshold to 1 GiB, and pads every arena's top by 1 GiB of address space,
/// which costs no resident memory) and, unless `RAYON_NUM_THREADS` is set,
/// sets it to 1 (deterministic, and the models are too small to gain from
/// more). Idempotent; the allocator part is a no-op on other C libraries.
///
/// Setting the variable races with `getenv` on other threads, so the binary
/// calls this first thing; library entry points call it again (a no-op then).
pub fn prepare_for_candle() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        if std::env::var_os("RAYON_NUM_THREADS").is_none() {
            std::env::set_var("RAYON_NUM_THREADS", "1");
        }
        #[cfg(all(target_os = "linux", target_env = "gnu"))]
        // SAFETY: mallopt only changes allocator parameters; it is called
        // once, and glibc serialises it against concurrent allocations.
        unsafe {
            libc::mallopt(libc::M_MMAP_THRESHOLD, 32 << 20);
            libc::mallopt(libc::M_TRIM_THRESHOLD, 1 << 30);
            libc::mallopt(libc::M_TOP_PAD, 1 << 30);
        }
    });
}
