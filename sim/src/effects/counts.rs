//! Stage bookkeeping: [`StageSet`] (which stages a plan holds, as a bit set the hot loop tests)
//! and [`StageCounts`] (how often each stage ran while rendering one frame).
//!
//! Contract: counts are exact. The renderer counts per row in plain integers and sums the rows
//! in row order, so counts are identical on any thread count; a stage that is not in the plan
//! always counts zero.

use super::Stage;
use serde::{Serialize, Serializer};

/// A set of stages (bit `i` = `Stage::ALL[i]`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct StageSet(u32);

impl StageSet {
    /// No stages.
    pub const EMPTY: StageSet = StageSet(0);

    /// This set plus `stage`.
    pub const fn with(self, stage: Stage) -> StageSet {
        StageSet(self.0 | 1 << stage as u32)
    }

    /// This set without `stage`.
    pub const fn without(self, stage: Stage) -> StageSet {
        StageSet(self.0 & !(1 << stage as u32))
    }

    /// Whether `stage` is in the set.
    #[inline]
    pub const fn has(self, stage: Stage) -> bool {
        self.0 & (1 << stage as u32) != 0
    }
}

/// Executions per stage during one render.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StageCounts([u64; Stage::COUNT]);

impl StageCounts {
    /// Adds `n` executions of `stage`.
    #[inline]
    pub fn add(&mut self, stage: Stage, n: u64) {
        self.0[stage.index()] += n;
    }

    /// Executions of `stage`.
    pub fn get(&self, stage: Stage) -> u64 {
        self.0[stage.index()]
    }

    /// Adds every count of `other`.
    pub fn merge(&mut self, other: &StageCounts) {
        for (a, b) in self.0.iter_mut().zip(other.0) {
            *a += b;
        }
    }

    /// The stages whose counts differ between `self` and `other`.
    pub fn differing(&self, other: &StageCounts) -> Vec<Stage> {
        Stage::ALL
            .into_iter()
            .filter(|s| self.get(*s) != other.get(*s))
            .collect()
    }

    /// `(stage, count)` for every stage with a non-zero count.
    pub fn nonzero(&self) -> Vec<(Stage, u64)> {
        Stage::ALL
            .into_iter()
            .map(|s| (s, self.get(s)))
            .filter(|(_, n)| *n > 0)
            .collect()
    }
}

impl Serialize for StageCounts {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeMap;
        let nonzero = self.nonzero();
        let mut map = serializer.serialize_map(Some(nonzero.len()))?;
        for (s, n) in nonzero {
            map.serialize_entry(s.name(), &n)?;
        }
        map.end()
    }
}
