//! This process's resident-memory high-water mark, for the benchmarks' peak-memory figures
//! (Linux `/proc`; `None` elsewhere).
//!
//! Contract: [`peak_rss_bytes`] reads `VmHWM` of `/proc/self/status`; [`reset_peak_rss`] sets
//! it back to the current resident size (writing 5 to `/proc/self/clear_refs`, Linux ≥ 4.0), so
//! one process can measure the peak of several runs in turn. A run's peak includes everything
//! the process holds during it.

/// The resident-memory high-water mark since the process started or the last
/// [`reset_peak_rss`], bytes; `None` where the kernel does not report it.
pub fn peak_rss_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// Resets the high-water mark to the current resident size; false where the kernel does not
/// allow it (the next [`peak_rss_bytes`] is then the process's peak so far).
pub fn reset_peak_rss() -> bool {
    std::fs::write("/proc/self/clear_refs", "5").is_ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// This process's resident size now (`VmRSS`), bytes.
    fn resident_bytes() -> u64 {
        let status = std::fs::read_to_string("/proc/self/status").unwrap();
        let line = status.lines().find(|l| l.starts_with("VmRSS:")).unwrap();
        line.split_whitespace()
            .nth(1)
            .unwrap()
            .parse::<u64>()
            .unwrap()
            * 1024
    }

    // Other tests of this binary run on other threads and allocate and free at any time, so
    // the mark is compared with this process's resident size while the block is held, not
    // with the mark taken before it (which another thread's freeing can lower).
    #[test]
    fn the_high_water_mark_follows_an_allocation_and_resets() {
        if !reset_peak_rss() {
            return; // not Linux
        }
        // 64 MiB touched page by page.
        let block = vec![1u8; 64 << 20];
        std::hint::black_box(&block);
        let resident = resident_bytes();
        assert!(resident >= 60 << 20, "resident {resident} with 64 MiB held");
        let peak = peak_rss_bytes().expect("VmHWM on Linux");
        assert!(
            peak >= resident,
            "mark {peak} below the resident size {resident}"
        );
        drop(block);
        assert!(reset_peak_rss());
        assert!(peak_rss_bytes().unwrap() < peak);
    }
}
