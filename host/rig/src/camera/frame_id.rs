//! Unwraps a camera's 16-bit GigE Vision block ids into a monotonic 64-bit frame id.
//!
//! GVSP 1.x block ids run 1..=65535 and then wrap to 1 (0 is reserved and skipped), and a camera
//! need not start at 1 (aravis' fake camera starts at 65401 on purpose). Each new id advances the
//! 64-bit counter by the forward distance from the previous id on that 65535-cycle; a distance of
//! 0 is a duplicate. A gap of `n > 1` means `n − 1` frames were lost before this one.

/// Stateful unwrapper of 16-bit block ids.
#[derive(Debug, Clone, Default)]
pub struct FrameIdUnwrapper {
    last: Option<(u16, u64)>,
}

/// What one new block id means.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Unwrapped {
    /// The next frame: its 64-bit id, and how many frames were skipped before it.
    Next {
        /// Monotonic 64-bit id.
        frame_id: u64,
        /// Frames lost since the previous one.
        skipped: u64,
    },
    /// The same block id again.
    Duplicate {
        /// The 64-bit id it duplicates.
        frame_id: u64,
    },
    /// Block id 0, which GVSP 1.x never sends.
    Invalid,
}

/// Ids in one wrap cycle.
const CYCLE: u64 = 65_535;

impl FrameIdUnwrapper {
    /// A fresh unwrapper; the first id maps to 64-bit id 0.
    pub fn new() -> Self {
        Self::default()
    }

    /// Feeds the next block id.
    pub fn push(&mut self, block_id: u16) -> Unwrapped {
        if block_id == 0 {
            return Unwrapped::Invalid;
        }
        let Some((last_block, last_id)) = self.last else {
            self.last = Some((block_id, 0));
            return Unwrapped::Next {
                frame_id: 0,
                skipped: 0,
            };
        };
        // both in 1..=65535: forward distance modulo the cycle
        let advance = (u64::from(block_id) + CYCLE - u64::from(last_block)) % CYCLE;
        if advance == 0 {
            return Unwrapped::Duplicate { frame_id: last_id };
        }
        let frame_id = last_id + advance;
        self.last = Some((block_id, frame_id));
        Unwrapped::Next {
            frame_id,
            skipped: advance - 1,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wraps_from_65535_to_1_without_a_gap() {
        let mut u = FrameIdUnwrapper::new();
        assert_eq!(
            u.push(65_534),
            Unwrapped::Next {
                frame_id: 0,
                skipped: 0
            }
        );
        assert_eq!(
            u.push(65_535),
            Unwrapped::Next {
                frame_id: 1,
                skipped: 0
            }
        );
        assert_eq!(
            u.push(1),
            Unwrapped::Next {
                frame_id: 2,
                skipped: 0
            }
        );
        assert_eq!(
            u.push(2),
            Unwrapped::Next {
                frame_id: 3,
                skipped: 0
            }
        );
    }

    #[test]
    fn gaps_duplicates_and_zero() {
        let mut u = FrameIdUnwrapper::new();
        u.push(65_401);
        assert_eq!(
            u.push(65_404),
            Unwrapped::Next {
                frame_id: 3,
                skipped: 2
            }
        );
        assert_eq!(u.push(65_404), Unwrapped::Duplicate { frame_id: 3 });
        assert_eq!(u.push(0), Unwrapped::Invalid);
        assert_eq!(
            u.push(3),
            Unwrapped::Next {
                frame_id: 137,
                skipped: 133
            }
        );
    }

    #[test]
    fn many_cycles_stay_monotonic() {
        let mut u = FrameIdUnwrapper::new();
        let mut block: u16 = 65_400;
        let mut prev = None;
        for i in 0..300_000u64 {
            let r = u.push(block);
            let Unwrapped::Next {
                frame_id,
                skipped: 0,
            } = r
            else {
                panic!("{r:?} at {i}")
            };
            assert_eq!(frame_id, i);
            assert!(prev.is_none_or(|p| p < frame_id));
            prev = Some(frame_id);
            block = if block == u16::MAX { 1 } else { block + 1 };
        }
    }
}
