//! Sharded fits for job arrays: which vertices a shard owns, where its index comes from, the
//! part file a shard writes and the merge of the parts (docs/scale.md).
//!
//! Contract:
//! - Shard `I/N` owns the vertices `v` with `v % N == I` (interleaved, so every shard gets a
//!   like share of the object's front and back); `0/1` owns every vertex.
//! - A shard computes the observations and step A (the per-vertex joint solve) of its vertices;
//!   everything that needs every vertex — the clusters, virtual samples, pooled η, the final
//!   passes, the held-out score and the export — runs once, in the merge
//!   ([`merge::merge_parts`]). Observations and step A are per vertex and every stage is
//!   deterministic, so a merged fit is bit-identical to an unsharded one.
//! - The index comes from `--shard I/N` or from the job array's environment
//!   ([`Shard::from_env`]): Slurm (`SLURM_ARRAY_TASK_ID` − `SLURM_ARRAY_TASK_MIN`, count
//!   `SLURM_ARRAY_TASK_COUNT`), Kubernetes Indexed Jobs (`JOB_COMPLETION_INDEX`) and AWS Batch
//!   (`AWS_BATCH_JOB_ARRAY_INDEX`), the last two with the count given. Absent, malformed or
//!   disagreeing values are errors naming the variable.

pub mod merge;
pub mod part;

use std::fmt;

/// One shard of a sharded fit: `index` of `count`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub struct Shard {
    /// This shard, 0-based, `< count`.
    pub index: u32,
    /// Number of shards, ≥ 1.
    pub count: u32,
}

impl fmt::Display for Shard {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

/// Why a shard index cannot be had.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ShardError {
    /// `--shard` is not `I/N` with integers 0 ≤ I < N.
    #[error("--shard {given:?}: {what} (expected I/N with 0 ≤ I < N, e.g. 0/4, or `env`)")]
    Malformed {
        /// The value given.
        given: String,
        /// What is wrong with it.
        what: String,
    },
    /// An environment variable holds something other than a non-negative integer.
    #[error("{var}={value:?} is not a non-negative integer")]
    BadVariable {
        /// The variable.
        var: &'static str,
        /// Its value.
        value: String,
    },
    /// No job-array index in the environment.
    #[error(
        "--shard env: no job-array index in the environment (none of SLURM_ARRAY_TASK_ID, \
         JOB_COMPLETION_INDEX, AWS_BATCH_JOB_ARRAY_INDEX is set); give --shard I/N"
    )]
    NoIndex,
    /// The index is known but the count is not.
    #[error(
        "--shard env: {var} gives the index but not the number of shards; give --shard-count N \
         ({hint})"
    )]
    NoCount {
        /// The variable that gave the index.
        var: &'static str,
        /// Where the count is in that system.
        hint: &'static str,
    },
    /// Two sources disagree.
    #[error("inconsistent shard settings: {0}")]
    Inconsistent(String),
}

impl Shard {
    /// Every vertex in one shard (an unsharded fit).
    pub const ALL: Shard = Shard { index: 0, count: 1 };

    /// A checked shard.
    pub fn new(index: u32, count: u32) -> Result<Self, ShardError> {
        let given = format!("{index}/{count}");
        if count == 0 {
            return Err(ShardError::Malformed {
                given,
                what: "the number of shards must be at least 1".into(),
            });
        }
        if index >= count {
            return Err(ShardError::Malformed {
                given,
                what: format!("shard index {index} is not below the count {count}"),
            });
        }
        Ok(Self { index, count })
    }

    /// Parses `I/N`.
    pub fn parse(text: &str) -> Result<Self, ShardError> {
        let malformed = |what: &str| ShardError::Malformed {
            given: text.to_string(),
            what: what.to_string(),
        };
        let (i, n) = text
            .split_once('/')
            .ok_or_else(|| malformed("no `/` between index and count"))?;
        let i: u32 = i
            .trim()
            .parse()
            .map_err(|_| malformed("the index is not a non-negative integer"))?;
        let n: u32 = n
            .trim()
            .parse()
            .map_err(|_| malformed("the count is not a positive integer"))?;
        Self::new(i, n).map_err(|e| match e {
            ShardError::Malformed { what, .. } => malformed(&what),
            other => other,
        })
    }

    /// The shard of a job-array task from its environment (`get` looks a variable up; the
    /// binary passes `std::env::var`), with `count` from `--shard-count` where given.
    ///
    /// Slurm: index = `SLURM_ARRAY_TASK_ID` − `SLURM_ARRAY_TASK_MIN` (so `--array=1-8` works),
    /// count = `SLURM_ARRAY_TASK_COUNT`; arrays with a step or gaps are refused (their task ids
    /// are not 0…N−1 after the shift). Kubernetes Indexed Jobs: `JOB_COMPLETION_INDEX`, count
    /// from `--shard-count` (the Job's `spec.completions`). AWS Batch: `AWS_BATCH_JOB_ARRAY_INDEX`,
    /// count from `--shard-count` (the array size). Two systems' indices that disagree, or a
    /// `--shard-count` that disagrees with Slurm's count, are errors.
    pub fn from_env(
        get: &dyn Fn(&str) -> Option<String>,
        count: Option<u32>,
    ) -> Result<Self, ShardError> {
        let number = |var: &'static str| -> Result<Option<u32>, ShardError> {
            match get(var) {
                None => Ok(None),
                Some(value) => value
                    .trim()
                    .parse::<u32>()
                    .map(Some)
                    .map_err(|_| ShardError::BadVariable { var, value }),
            }
        };
        // (variable, index, count it brings, where the count lives)
        let mut found: Vec<(&'static str, u32, Option<u32>, &'static str)> = Vec::new();
        if let Some(id) = number("SLURM_ARRAY_TASK_ID")? {
            let min = number("SLURM_ARRAY_TASK_MIN")?.unwrap_or(0);
            let n = number("SLURM_ARRAY_TASK_COUNT")?;
            if let Some(step) = number("SLURM_ARRAY_TASK_STEP")?
                && step > 1
            {
                return Err(ShardError::Inconsistent(format!(
                    "SLURM_ARRAY_TASK_STEP={step}: the array's task ids must be consecutive \
                     (--array=0-{} without a step)",
                    n.unwrap_or(1).saturating_sub(1)
                )));
            }
            if let (Some(max), Some(n)) = (number("SLURM_ARRAY_TASK_MAX")?, n)
                && max.checked_sub(min).map(|d| d + 1) != Some(n)
            {
                return Err(ShardError::Inconsistent(format!(
                    "the Slurm array runs ids {min}–{max} but has {n} tasks: it must be one \
                     consecutive range (--array=0-{})",
                    n.saturating_sub(1)
                )));
            }
            let index = id.checked_sub(min).ok_or_else(|| {
                ShardError::Inconsistent(format!(
                    "SLURM_ARRAY_TASK_ID={id} is below SLURM_ARRAY_TASK_MIN={min}"
                ))
            })?;
            found.push((
                "SLURM_ARRAY_TASK_ID",
                index,
                n,
                "Slurm exports SLURM_ARRAY_TASK_COUNT",
            ));
        }
        if let Some(i) = number("JOB_COMPLETION_INDEX")? {
            found.push((
                "JOB_COMPLETION_INDEX",
                i,
                None,
                "the Job's spec.completions",
            ));
        }
        if let Some(i) = number("AWS_BATCH_JOB_ARRAY_INDEX")? {
            found.push((
                "AWS_BATCH_JOB_ARRAY_INDEX",
                i,
                None,
                "the array job's arrayProperties.size",
            ));
        }
        let Some(&(var, index, env_count, hint)) = found.first() else {
            return Err(ShardError::NoIndex);
        };
        for &(other, i, _, _) in &found[1..] {
            if i != index {
                return Err(ShardError::Inconsistent(format!(
                    "{var} gives shard {index} but {other} gives {i}"
                )));
            }
        }
        let count = match (env_count, count) {
            (Some(e), Some(c)) if e != c => {
                return Err(ShardError::Inconsistent(format!(
                    "--shard-count {c} but SLURM_ARRAY_TASK_COUNT={e}"
                )));
            }
            (Some(n), _) | (None, Some(n)) => n,
            (None, None) => return Err(ShardError::NoCount { var, hint }),
        };
        Self::new(index, count).map_err(|e| match e {
            ShardError::Malformed { what, .. } => {
                ShardError::Inconsistent(format!("{var}: {what}"))
            }
            other => other,
        })
    }

    /// Whether this shard owns vertex `v`.
    pub fn owns(&self, v: usize) -> bool {
        v % self.count as usize == self.index as usize
    }

    /// The vertices of a mesh with `vertices` vertices this shard owns, ascending.
    pub fn vertices(&self, vertices: usize) -> impl Iterator<Item = usize> + use<> {
        (self.index as usize..vertices).step_by(self.count as usize)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn env(vars: &[(&str, &str)]) -> impl Fn(&str) -> Option<String> + use<> {
        let vars: Vec<(String, String)> = vars
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect();
        move |k: &str| vars.iter().find(|(n, _)| n == k).map(|(_, v)| v.clone())
    }

    #[test]
    fn parse_accepts_i_of_n_and_refuses_the_rest_with_the_reason() {
        assert_eq!(Shard::parse("2/4"), Ok(Shard { index: 2, count: 4 }));
        assert_eq!(Shard::parse("0/1"), Ok(Shard::ALL));
        for (bad, why) in [
            ("4/4", "not below the count"),
            ("1/0", "at least 1"),
            ("3", "no `/`"),
            ("-1/4", "index is not"),
            ("a/4", "index is not"),
            ("1/x", "count is not"),
            ("", "no `/`"),
        ] {
            let e = Shard::parse(bad).unwrap_err().to_string();
            assert!(e.contains(why), "{bad}: {e}");
            assert!(e.contains(&format!("{bad:?}")), "{bad}: {e}");
        }
    }

    #[test]
    fn shards_partition_the_vertices_interleaved() {
        let n = 10;
        let mut seen = vec![0; n];
        for i in 0..3 {
            let s = Shard::new(i, 3).unwrap();
            for v in s.vertices(n) {
                assert!(s.owns(v));
                seen[v] += 1;
            }
        }
        assert!(seen.iter().all(|&c| c == 1), "{seen:?}");
        assert_eq!(
            Shard::new(1, 3).unwrap().vertices(n).collect::<Vec<_>>(),
            [1, 4, 7]
        );
        assert_eq!(Shard::ALL.vertices(3).collect::<Vec<_>>(), [0, 1, 2]);
    }

    #[test]
    fn slurm_index_is_shifted_by_the_array_minimum_and_brings_its_count() {
        let get = env(&[
            ("SLURM_ARRAY_TASK_ID", "3"),
            ("SLURM_ARRAY_TASK_MIN", "1"),
            ("SLURM_ARRAY_TASK_MAX", "4"),
            ("SLURM_ARRAY_TASK_COUNT", "4"),
        ]);
        assert_eq!(Shard::from_env(&get, None), Ok(Shard::new(2, 4).unwrap()));
        assert_eq!(
            Shard::from_env(&get, Some(4)),
            Ok(Shard::new(2, 4).unwrap())
        );
        let e = Shard::from_env(&get, Some(5)).unwrap_err().to_string();
        assert!(
            e.contains("--shard-count 5") && e.contains("COUNT=4"),
            "{e}"
        );
    }

    #[test]
    fn slurm_arrays_with_steps_or_gaps_are_refused() {
        let stepped = env(&[
            ("SLURM_ARRAY_TASK_ID", "2"),
            ("SLURM_ARRAY_TASK_STEP", "2"),
            ("SLURM_ARRAY_TASK_COUNT", "3"),
        ]);
        let e = Shard::from_env(&stepped, None).unwrap_err().to_string();
        assert!(e.contains("SLURM_ARRAY_TASK_STEP=2"), "{e}");
        let gaps = env(&[
            ("SLURM_ARRAY_TASK_ID", "5"),
            ("SLURM_ARRAY_TASK_MIN", "1"),
            ("SLURM_ARRAY_TASK_MAX", "7"),
            ("SLURM_ARRAY_TASK_COUNT", "3"),
        ]);
        let e = Shard::from_env(&gaps, None).unwrap_err().to_string();
        assert!(e.contains("1–7") && e.contains("3 tasks"), "{e}");
    }

    #[test]
    fn kubernetes_and_aws_need_the_count_given() {
        for var in ["JOB_COMPLETION_INDEX", "AWS_BATCH_JOB_ARRAY_INDEX"] {
            let get = env(&[(var, "1")]);
            let e = Shard::from_env(&get, None).unwrap_err();
            assert!(matches!(e, ShardError::NoCount { .. }), "{e}");
            assert!(e.to_string().contains(var) && e.to_string().contains("--shard-count"));
            assert_eq!(
                Shard::from_env(&get, Some(3)),
                Ok(Shard::new(1, 3).unwrap())
            );
            let e = Shard::from_env(&get, Some(1)).unwrap_err().to_string();
            assert!(
                e.contains(var) && e.contains("not below the count 1"),
                "{e}"
            );
        }
    }

    #[test]
    fn absent_malformed_and_disagreeing_environments_are_named() {
        assert_eq!(
            Shard::from_env(&env(&[]), Some(4)),
            Err(ShardError::NoIndex)
        );
        let e = Shard::from_env(&env(&[("JOB_COMPLETION_INDEX", "one")]), Some(4))
            .unwrap_err()
            .to_string();
        assert!(e.contains("JOB_COMPLETION_INDEX=\"one\""), "{e}");
        let e = Shard::from_env(
            &env(&[
                ("JOB_COMPLETION_INDEX", "1"),
                ("AWS_BATCH_JOB_ARRAY_INDEX", "2"),
            ]),
            Some(4),
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("JOB_COMPLETION_INDEX gives shard 1")
                && e.contains("AWS_BATCH_JOB_ARRAY_INDEX gives 2"),
            "{e}"
        );
        let agree = env(&[
            ("JOB_COMPLETION_INDEX", "2"),
            ("AWS_BATCH_JOB_ARRAY_INDEX", "2"),
        ]);
        assert_eq!(
            Shard::from_env(&agree, Some(4)),
            Ok(Shard::new(2, 4).unwrap())
        );
    }
}
