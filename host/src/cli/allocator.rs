//! The C allocator's thresholds for this program's allocation pattern (glibc only).
//!
//! Every frame a fit or capture reads allocates a few buffers of megabytes (the decoded mosaic,
//! the demosaic's planes, their DN copy) and frees them after sampling. glibc's defaults hand
//! such blocks back to the kernel on every free (`mmap`/`munmap` above the mmap threshold, heap
//! trimming above the trim threshold), so the next frame faults every page in again and zeroes
//! it: measured on a shard of the demo session, 0.5 s of 1.25 s wall in the kernel. Raising
//! both thresholds keeps the freed blocks in the heap for the next frame (0.05 s in the kernel,
//! 1.0 s wall). Memory still freed stays with the process until it exits; the peak is
//! unchanged.
//!
//! Contract: [`tune`] is called once at start-up, before any thread is spawned; elsewhere than
//! glibc it does nothing.

/// Blocks up to this size come from the heap, not from their own `mmap`.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
const MMAP_THRESHOLD_BYTES: libc::c_int = 256 << 20;
/// The heap's free top is returned to the kernel only beyond this.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
const TRIM_THRESHOLD_BYTES: libc::c_int = 1 << 30;

/// Sets the thresholds (module doc).
pub fn tune() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only adjusts glibc's malloc parameters; called before other threads
    // allocate. A refused setting (returns 0) leaves the default in place, which is harmless.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES);
        libc::mallopt(libc::M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES);
    }
}
