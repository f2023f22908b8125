//! Link faults: independent bit errors at a bit error rate (BER), and the link going down at a
//! pulse.
//!
//! Contract:
//! - [`BitErrorInjector::corrupt`] flips each bit that passes through it independently with
//!   probability `ber`, drawing the gap to the next error from the geometric distribution (so a
//!   BER of 10⁻⁶ costs one draw per error, not one per bit). The draws depend only on the seed
//!   and the number of bits passed, not on how they were chunked.
//! - A BER of 0 never flips anything and draws nothing.
//! - [`LinkFaults`] is what a virtual board needs: a BER per direction and an optional
//!   [`Disconnect`].

use std::time::Duration;

use rand::Rng;
use rand_chacha::ChaCha8Rng;

use super::RigError;
use super::seeds::{FaultStream, fault_rng};

/// The link goes down when the board is about to send the pulse event numbered `at_pulse`
/// (sequence numbers from 0): pulses `0 .. at_pulse` are delivered intact, that one and
/// everything after is lost.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Disconnect {
    /// First pulse sequence number that is not delivered.
    pub at_pulse: u64,
    /// `None`: the board closes its end for good and its thread ends (a pulled cable on a USB
    /// device). `Some(d)`: a blackout: for `d` every byte in either direction is lost, then the
    /// link works again (a flaky connector); the board keeps running throughout.
    pub blackout: Option<Duration>,
}

/// The link faults of one virtual board.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LinkFaults {
    /// Bit error rate on the board → host direction, in [0, 0.5].
    pub ber_to_host: f64,
    /// Bit error rate on the host → board direction, in [0, 0.5].
    pub ber_to_board: f64,
    /// Where the link goes down, if it does.
    pub disconnect: Option<Disconnect>,
}

impl LinkFaults {
    /// Refuses a BER outside [0, 0.5] or not finite.
    pub fn check(&self) -> Result<(), RigError> {
        for (name, ber) in [
            ("ber_to_host", self.ber_to_host),
            ("ber_to_board", self.ber_to_board),
        ] {
            check_ber(name, ber)?;
        }
        Ok(())
    }
}

fn check_ber(name: &'static str, ber: f64) -> Result<(), RigError> {
    if !(0.0..=0.5).contains(&ber) {
        return Err(RigError::Parameter {
            name,
            value: ber,
            expected: "a bit error rate in [0, 0.5]",
        });
    }
    Ok(())
}

/// Flips bits of a byte stream at a BER; see the [module docs](self).
#[derive(Debug, Clone)]
pub struct BitErrorInjector {
    ber: f64,
    rng: ChaCha8Rng,
    /// Clean bits to pass before the next flipped one (`u64::MAX`: never).
    gap_bits: u64,
    bits_flipped: u64,
    bits_seen: u64,
}

impl BitErrorInjector {
    /// An injector for `ber` on the given stream of `seed`.
    pub fn new(ber: f64, seed: u64, stream: FaultStream) -> Result<Self, RigError> {
        check_ber("bit_error_rate", ber)?;
        let mut me = Self {
            ber,
            rng: fault_rng(seed, stream),
            gap_bits: u64::MAX,
            bits_flipped: 0,
            bits_seen: 0,
        };
        me.gap_bits = me.draw_gap();
        Ok(me)
    }

    /// Geometric number of failures before the next success, `floor(ln U / ln(1 − p))`.
    fn draw_gap(&mut self) -> u64 {
        if self.ber <= 0.0 {
            return u64::MAX;
        }
        // U in (0, 1]: ln U ≤ 0 is finite. ln(1 − p) < 0 for p in (0, 0.5]: the ratio is ≥ 0.
        let u: f64 = 1.0 - self.rng.random::<f64>();
        let gap = (u.ln() / (1.0 - self.ber).ln()).floor();
        if gap >= u64::MAX as f64 {
            u64::MAX
        } else {
            gap as u64
        }
    }

    /// Flips bits of `bytes` in place; returns how many were flipped.
    pub fn corrupt(&mut self, bytes: &mut [u8]) -> u32 {
        let mut flipped = 0u32;
        let total_bits = bytes.len() as u64 * 8;
        let mut pos = 0u64;
        while self.gap_bits != u64::MAX && total_bits - pos > self.gap_bits {
            pos += self.gap_bits;
            bytes[(pos / 8) as usize] ^= 1 << (pos % 8);
            flipped += 1;
            pos += 1;
            self.gap_bits = self.draw_gap();
        }
        if self.gap_bits != u64::MAX {
            self.gap_bits -= total_bits - pos;
        }
        self.bits_flipped += u64::from(flipped);
        self.bits_seen += total_bits;
        flipped
    }

    /// Bits flipped so far.
    pub fn bits_flipped(&self) -> u64 {
        self.bits_flipped
    }

    /// Bits passed so far.
    pub fn bits_seen(&self) -> u64 {
        self.bits_seen
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flip_rate_matches_the_ber_and_chunking_does_not_matter() {
        let ber = 1e-3;
        let mut whole = BitErrorInjector::new(ber, 3, FaultStream::LinkBitErrorsToHost).unwrap();
        let mut chunked = whole.clone();
        let mut a = vec![0u8; 250_000];
        let mut b = a.clone();
        whole.corrupt(&mut a);
        for chunk in b.chunks_mut(37) {
            chunked.corrupt(chunk);
        }
        assert_eq!(a, b);
        let ones: u64 = a.iter().map(|x| u64::from(x.count_ones())).sum();
        assert_eq!(ones, whole.bits_flipped());
        let expected = ber * 2_000_000.0;
        // 2000 expected flips: ±5 σ ≈ ±224
        assert!(
            (ones as f64 - expected).abs() < 5.0 * expected.sqrt(),
            "{ones}"
        );
    }

    #[test]
    fn zero_ber_never_flips_and_bad_ber_is_refused() {
        let mut inj = BitErrorInjector::new(0.0, 1, FaultStream::LinkBitErrorsToHost).unwrap();
        let mut bytes = vec![0x5Au8; 10_000];
        assert_eq!(inj.corrupt(&mut bytes), 0);
        assert!(bytes.iter().all(|&b| b == 0x5A));
        assert!(BitErrorInjector::new(0.6, 1, FaultStream::LinkBitErrorsToHost).is_err());
        assert!(BitErrorInjector::new(f64::NAN, 1, FaultStream::LinkBitErrorsToHost).is_err());
    }
}
