//! Flash-energy bracketing: the relative energies a capture fires in turn.
//!
//! Contract:
//! - A [`Bracket`] is a list of 0 to [`MAX_BRACKET_STEPS`] relative flash energies in Q15 fixed
//!   point (`energy × 32 768`, so [`ENERGY_ONE_Q15`] = 1.0, `0x2000` = 0.25, `0x0800` = 0.0625).
//!   Pulse `k` of a capture (from 0) fires step `k mod len`; an empty bracket means "no bracket":
//!   every pulse at energy 1, reported as step 0.
//! - The energy is realised by the flash's **on-time** inside one fixed exposure (an LED's energy
//!   is proportional to its on-time at constant current): step `i` is lit for
//!   `round(flash_duration_us · q_i / 32 768)` µs ([`Bracket::on_time_us`]). The board checks
//!   every step against its limits (`ellipso_firmware::CapturePlan`).
//! - On the wire a bracket is a postcard sequence: a varint count, then each step as a varint
//!   `u16`. A count above [`MAX_BRACKET_STEPS`] does not decode (`Malformed`). Values are not
//!   range-checked here: the board's plan check rejects steps of 0 or above 1.0 with the step's
//!   index, so a host learns which step was wrong.
//! - The type is `Copy` with a fixed footprint (no alloc), and unused slots are always zero, so
//!   two brackets with the same steps compare equal.

use core::fmt;

use serde::de::{Error as _, SeqAccess, Visitor};
use serde::ser::SerializeSeq;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// Most steps a bracket may have.
pub const MAX_BRACKET_STEPS: usize = 8;

/// Relative energy 1.0 in Q15 (`energy × 32 768`).
pub const ENERGY_ONE_Q15: u16 = 1 << 15;

/// The relative flash energies of a capture, fired in turn; see the [module docs](self).
#[derive(Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct Bracket {
    len: u8,
    steps_q15: [u16; MAX_BRACKET_STEPS],
}

impl Bracket {
    /// No bracket: every pulse at energy 1 (step 0).
    pub const NONE: Self = Self {
        len: 0,
        steps_q15: [0; MAX_BRACKET_STEPS],
    };

    /// A bracket of these Q15 energies, in firing order; `None` for more than
    /// [`MAX_BRACKET_STEPS`] steps. Values are taken as given (the board checks their range).
    pub const fn from_q15(steps: &[u16]) -> Option<Self> {
        if steps.len() > MAX_BRACKET_STEPS {
            return None;
        }
        let mut steps_q15 = [0u16; MAX_BRACKET_STEPS];
        let mut i = 0;
        while i < steps.len() {
            steps_q15[i] = steps[i];
            i += 1;
        }
        Some(Self {
            len: steps.len() as u8,
            steps_q15,
        })
    }

    /// A bracket of relative energies in (0, 1], in firing order, each rounded to Q15
    /// (`round(energy × 32768)`, halves up). Refuses more than [`MAX_BRACKET_STEPS`] steps, a
    /// step outside (0, 1] or not finite, and a step below the Q15 resolution (< 1/65536).
    pub fn from_relative(energies: &[f64]) -> Result<Self, BracketError> {
        if energies.len() > MAX_BRACKET_STEPS {
            return Err(BracketError::TooManySteps {
                len: energies.len(),
            });
        }
        let mut q = [0u16; MAX_BRACKET_STEPS];
        for (step, &e) in energies.iter().enumerate() {
            // NaN fails both comparisons.
            if !(e > 0.0 && e <= 1.0) {
                return Err(BracketError::OutOfRange { step, energy: e });
            }
            // e in (0, 1]: the sum is in (0.5, 32768.5], so the cast truncates a positive value
            // (round half up) and cannot overflow.
            q[step] = (e * f64::from(ENERGY_ONE_Q15) + 0.5) as u16;
            if q[step] == 0 {
                return Err(BracketError::BelowResolution { step, energy: e });
            }
        }
        Ok(Self::from_q15(&q[..energies.len()]).unwrap_or(Self::NONE))
    }

    /// The relative energy of each step (`q / 32768`), in firing order.
    pub fn energies(&self) -> impl Iterator<Item = f64> + '_ {
        self.steps_q15()
            .iter()
            .map(|&q| f64::from(q) / f64::from(ENERGY_ONE_Q15))
    }

    /// The steps, Q15, in firing order.
    pub fn steps_q15(&self) -> &[u16] {
        &self.steps_q15[..usize::from(self.len)]
    }

    /// Number of steps (0 for no bracket).
    pub const fn len(&self) -> usize {
        self.len as usize
    }

    /// Whether this is "no bracket".
    pub const fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Steps per cycle as pulses see them: `len`, or 1 without a bracket.
    pub const fn cycle_len(&self) -> usize {
        if self.len == 0 { 1 } else { self.len as usize }
    }

    /// The Q15 energy of step `step` (`ENERGY_ONE_Q15` for step 0 without a bracket); `None`
    /// past the last step.
    pub fn step_q15(&self, step: usize) -> Option<u16> {
        if self.is_empty() {
            return (step == 0).then_some(ENERGY_ONE_Q15);
        }
        self.steps_q15().get(step).copied()
    }

    /// The step pulse number `pulse_in_capture` (from 0) fires: `pulse_in_capture mod len`.
    pub fn step_of_pulse(&self, pulse_in_capture: u64) -> u8 {
        (pulse_in_capture % self.cycle_len() as u64) as u8
    }

    /// The on-time of relative energy `q15` for a full-energy on-time of `full_on_us`:
    /// `round(full_on_us · q15 / 32 768)`, halves rounded up, in `u64` so nothing overflows.
    pub const fn on_time_us(full_on_us: u32, q15: u16) -> u64 {
        (full_on_us as u64 * q15 as u64 + (ENERGY_ONE_Q15 as u64 / 2)) / ENERGY_ONE_Q15 as u64
    }
}

/// Why a list of relative energies is not a [`Bracket`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum BracketError {
    /// More than [`MAX_BRACKET_STEPS`] steps.
    TooManySteps {
        /// Steps given.
        len: usize,
    },
    /// A step outside (0, 1], or not finite.
    OutOfRange {
        /// Its index, from 0.
        step: usize,
        /// Its value.
        energy: f64,
    },
    /// A step that rounds to 0 in Q15 (below 1/65536).
    BelowResolution {
        /// Its index, from 0.
        step: usize,
        /// Its value.
        energy: f64,
    },
}

impl fmt::Display for BracketError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::TooManySteps { len } => {
                write!(f, "{len} bracket steps; at most {MAX_BRACKET_STEPS}")
            }
            Self::OutOfRange { step, energy } => write!(
                f,
                "bracket step {step} is {energy}; relative energies must be in (0, 1]"
            ),
            Self::BelowResolution { step, energy } => write!(
                f,
                "bracket step {step} is {energy}; the smallest relative energy is 1/65536"
            ),
        }
    }
}

impl core::error::Error for BracketError {}

impl fmt::Debug for Bracket {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_list().entries(self.steps_q15()).finish()
    }
}

impl Serialize for Bracket {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let mut seq = serializer.serialize_seq(Some(self.len()))?;
        for step in self.steps_q15() {
            seq.serialize_element(step)?;
        }
        seq.end()
    }
}

impl<'de> Deserialize<'de> for Bracket {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        deserializer.deserialize_seq(BracketVisitor)
    }
}

struct BracketVisitor;

impl<'de> Visitor<'de> for BracketVisitor {
    type Value = Bracket;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "at most {MAX_BRACKET_STEPS} Q15 flash energies")
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Bracket, A::Error> {
        if seq.size_hint().is_some_and(|n| n > MAX_BRACKET_STEPS) {
            return Err(A::Error::invalid_length(
                seq.size_hint().unwrap_or(0),
                &self,
            ));
        }
        let mut bracket = Bracket::NONE;
        while let Some(step) = seq.next_element::<u16>()? {
            let i = usize::from(bracket.len);
            if i == MAX_BRACKET_STEPS {
                return Err(A::Error::invalid_length(i + 1, &self));
            }
            bracket.steps_q15[i] = step;
            bracket.len += 1;
        }
        Ok(bracket)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn on_times_round_half_up_and_never_overflow() {
        assert_eq!(Bracket::on_time_us(5_000, ENERGY_ONE_Q15), 5_000);
        assert_eq!(Bracket::on_time_us(5_000, 0x2000), 1_250);
        // 5000 / 16 = 312.5 → 313
        assert_eq!(Bracket::on_time_us(5_000, 0x0800), 313);
        assert_eq!(Bracket::on_time_us(1, 0x4000), 1); // 0.5 → 1
        assert_eq!(Bracket::on_time_us(1, 0x3fff), 0);
        assert_eq!(
            Bracket::on_time_us(u32::MAX, u16::MAX),
            (u64::from(u32::MAX) * u64::from(u16::MAX) + 16_384) / 32_768
        );
    }

    #[test]
    fn relative_energies_round_to_q15_and_bad_ones_are_named() {
        let b = Bracket::from_relative(&[1.0, 0.25, 0.0625]).unwrap();
        assert_eq!(b.steps_q15(), [ENERGY_ONE_Q15, 0x2000, 0x0800]);
        let mut e = [0.0; 3];
        b.energies().zip(&mut e).for_each(|(v, slot)| *slot = v);
        assert_eq!(e, [1.0, 0.25, 0.0625]);
        // 1/3 → 10922.67 → 10923
        assert_eq!(
            Bracket::from_relative(&[1.0 / 3.0]).unwrap().steps_q15(),
            [10_923]
        );
        assert_eq!(Bracket::from_relative(&[]).unwrap(), Bracket::NONE);
        assert_eq!(
            Bracket::from_relative(&[0.5; 9]),
            Err(BracketError::TooManySteps { len: 9 })
        );
        for bad in [0.0, -0.25, 1.0001, f64::INFINITY] {
            assert_eq!(
                Bracket::from_relative(&[1.0, bad]),
                Err(BracketError::OutOfRange {
                    step: 1,
                    energy: bad
                })
            );
        }
        assert!(matches!(
            Bracket::from_relative(&[f64::NAN]),
            Err(BracketError::OutOfRange { step: 0, .. })
        ));
        assert_eq!(
            Bracket::from_relative(&[1e-6]),
            Err(BracketError::BelowResolution {
                step: 0,
                energy: 1e-6
            })
        );
    }

    #[test]
    fn steps_cycle_and_no_bracket_is_one_full_step() {
        let b = Bracket::from_q15(&[ENERGY_ONE_Q15, 0x2000, 0x0800]).unwrap();
        assert_eq!(b.len(), 3);
        let steps: [u8; 7] = core::array::from_fn(|k| b.step_of_pulse(k as u64));
        assert_eq!(steps, [0, 1, 2, 0, 1, 2, 0]);
        assert_eq!(b.step_q15(1), Some(0x2000));
        assert_eq!(b.step_q15(3), None);
        assert!(Bracket::NONE.is_empty());
        assert_eq!(Bracket::NONE.step_of_pulse(41), 0);
        assert_eq!(Bracket::NONE.step_q15(0), Some(ENERGY_ONE_Q15));
        assert_eq!(Bracket::from_q15(&[1; 9]), None);
        assert_eq!(Bracket::from_q15(&[]), Some(Bracket::NONE));
    }
}
