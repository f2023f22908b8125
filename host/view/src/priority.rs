//! Keeping the live view's work below the capture's: thread priority and a CPU-share pacer.
//!
//! Contract:
//! - [`lower_this_thread`] gives the calling thread the lowest scheduling priority, nice
//!   [`VIEW_NICE`] (Linux: the nice value is per thread, `setpriority(2)` with the thread id). The
//!   view's threads (the follower, the web server's) call it when they start, so on a busy machine
//!   the scheduler runs the capture's threads first (a nice-0 thread weighs 1024 against 15 for
//!   nice 19, and preempts it on wake-up). Elsewhere it reports that it is not supported; the view
//!   then relies on the pacer alone.
//! - [`Pacer`] bounds the share of wall time the follower spends on heavy work (decoding,
//!   rendering and tracking frames, counting coverage) while a capture runs: after work that took
//!   `d`, it waits `d·(1/share − 1)` before allowing more, so the follower falls behind (and says
//!   so) rather than competing. Wall time, not CPU time, is what it measures: on a loaded machine
//!   the same work takes longer, and the view backs off further.

use std::time::{Duration, Instant};

/// The view's threads' nice value: the lowest priority.
pub const VIEW_NICE: i32 = 19;

/// Lowers the calling thread to nice [`VIEW_NICE`].
pub fn lower_this_thread() -> std::io::Result<()> {
    #[cfg(target_os = "linux")]
    {
        // SAFETY: neither call takes a pointer or touches memory; on Linux the nice value is a
        // per-thread attribute and PRIO_PROCESS with a thread id changes that thread only.
        let rc = unsafe {
            let tid = libc::gettid();
            libc::setpriority(libc::PRIO_PROCESS, tid as libc::id_t, VIEW_NICE)
        };
        if rc == 0 {
            Ok(())
        } else {
            Err(std::io::Error::last_os_error())
        }
    }
    #[cfg(not(target_os = "linux"))]
    {
        Err(std::io::Error::new(
            std::io::ErrorKind::Unsupported,
            "per-thread priority is only set on Linux",
        ))
    }
}

/// [`lower_this_thread`], logging (once per thread) when it fails.
pub fn lower_this_thread_or_log(thread: &str) {
    if let Err(e) = lower_this_thread() {
        tracing::warn!("view: cannot lower the priority of its {thread} thread: {e}");
    }
}

/// Bounds the share of wall time spent on heavy work.
#[derive(Debug, Clone)]
pub struct Pacer {
    share: f64,
    resume_at: Option<Instant>,
}

impl Pacer {
    /// A pacer allowing `share` (clamped to [0.01, 1]) of wall time.
    pub fn new(share: f64) -> Self {
        Self {
            share: share.clamp(0.01, 1.0),
            resume_at: None,
        }
    }

    /// Whether heavy work may run at `now`.
    pub fn ready(&self, now: Instant) -> bool {
        self.resume_at.is_none_or(|t| now >= t)
    }

    /// Records work that ended at `now` after taking `spent`: the next is allowed once the
    /// share is met again.
    pub fn spent(&mut self, spent: Duration, now: Instant) {
        let idle = spent.mul_f64(1.0 / self.share - 1.0);
        self.resume_at = Some(now + idle);
    }

    /// The share of wall time allowed.
    #[cfg(test)]
    pub fn share(&self) -> f64 {
        self.share
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The calling thread's nice value, from `/proc/thread-self/stat` (field 19).
    #[cfg(target_os = "linux")]
    fn this_thread_nice() -> i32 {
        let stat = std::fs::read_to_string("/proc/thread-self/stat").unwrap();
        // fields after the command name (which may hold spaces) start at field 3
        let rest = &stat[stat.rfind(')').unwrap() + 1..];
        rest.split_whitespace().nth(16).unwrap().parse().unwrap()
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn lowering_changes_this_thread_only() {
        let before = this_thread_nice();
        let lowered = std::thread::spawn(|| {
            lower_this_thread().unwrap();
            this_thread_nice()
        })
        .join()
        .unwrap();
        assert_eq!(lowered, VIEW_NICE);
        assert_eq!(
            this_thread_nice(),
            before,
            "the spawning thread keeps its priority"
        );
    }

    #[test]
    fn pacer_keeps_the_share() {
        let t0 = Instant::now();
        let mut p = Pacer::new(0.25);
        assert!(p.ready(t0));
        // 30 ms of work at 25 %: 90 ms of rest
        let end = t0 + Duration::from_millis(30);
        p.spent(Duration::from_millis(30), end);
        assert!(!p.ready(end + Duration::from_millis(89)));
        assert!(p.ready(end + Duration::from_millis(90)));
        // over many rounds the work is a quarter of the time
        let (mut now, mut busy) = (t0, Duration::ZERO);
        let mut p = Pacer::new(0.25);
        for _ in 0..1000 {
            if p.ready(now) {
                now += Duration::from_millis(7);
                busy += Duration::from_millis(7);
                p.spent(Duration::from_millis(7), now);
            } else {
                now += Duration::from_millis(1);
            }
        }
        let share = busy.as_secs_f64() / (now - t0).as_secs_f64();
        assert!((0.2..0.26).contains(&share), "{share}");
        assert_eq!(Pacer::new(7.0).share(), 1.0);
        assert_eq!(Pacer::new(-1.0).share(), 0.01);
    }
}
