//! Shards: the K-th of N disjoint slices of a batch, from `--shard K/N` or from the
//! array-job variables of Slurm and of Kubernetes Indexed Jobs.

use serde::{Deserialize, Serialize};

/// Shard `k` of `n` (1-based: `1 <= k <= n`) holds the scenarios with
/// `index % n == k - 1` (strided, so slow and fast regions of a product spread evenly).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Shard {
    /// Which slice, 1-based.
    pub k: usize,
    /// Number of slices.
    pub n: usize,
}

impl Shard {
    /// Parses `K/N` with `1 <= K <= N`.
    pub fn parse(s: &str) -> Result<Self, String> {
        let bad = || {
            format!("`--shard {s}`: expected K/N with 1 <= K <= N\n  fix: give e.g. --shard 2/8 (the second of eight shards)")
        };
        let (k, n) = s.split_once('/').ok_or_else(bad)?;
        let k: usize = k.trim().parse().map_err(|_| bad())?;
        let n: usize = n.trim().parse().map_err(|_| bad())?;
        if n == 0 || k == 0 || k > n {
            return Err(bad());
        }
        Ok(Self { k, n })
    }

    /// True when scenario `index` belongs to this shard.
    pub fn contains(self, index: usize) -> bool {
        index % self.n == self.k - 1
    }

    /// The shard from the environment, when running as an array job:
    ///
    /// - Slurm (`sbatch --array=A-B[:S]`): K = (`SLURM_ARRAY_TASK_ID` -
    ///   `SLURM_ARRAY_TASK_MIN`) / `SLURM_ARRAY_TASK_STEP` + 1, N = `SLURM_ARRAY_TASK_COUNT`.
    /// - Kubernetes Indexed Job: K = `JOB_COMPLETION_INDEX` + 1, N = `count` (the
    ///   `--shard-count` flag) or `LONGREACH_SHARD_COUNT` (set it to `.spec.completions`).
    ///
    /// `Ok(None)` when neither is present.
    pub fn from_env(
        get: impl Fn(&str) -> Option<String>,
        count: Option<usize>,
    ) -> Result<Option<Self>, String> {
        let num = |name: &str| -> Result<Option<usize>, String> {
            match get(name) {
                None => Ok(None),
                Some(v) => v.trim().parse().map(Some).map_err(|_| {
                    format!("environment variable {name}={v:?} is not a non-negative integer")
                }),
            }
        };
        if let Some(id) = num("SLURM_ARRAY_TASK_ID")? {
            let min = num("SLURM_ARRAY_TASK_MIN")?.unwrap_or(0);
            let step = num("SLURM_ARRAY_TASK_STEP")?.unwrap_or(1).max(1);
            let n = match count {
                Some(n) => n,
                None => num("SLURM_ARRAY_TASK_COUNT")?.ok_or(
                    "SLURM_ARRAY_TASK_ID is set but SLURM_ARRAY_TASK_COUNT is not: pass --shard-count N or --shard K/N",
                )?,
            };
            let k = id
                .checked_sub(min)
                .map(|d| d / step + 1)
                .ok_or("SLURM_ARRAY_TASK_ID is below SLURM_ARRAY_TASK_MIN")?;
            return Self::checked(k, n, "the Slurm array variables").map(Some);
        }
        if let Some(index) = num("JOB_COMPLETION_INDEX")? {
            let n = match count {
                Some(n) => n,
                None => num("LONGREACH_SHARD_COUNT")?.ok_or(
                    "JOB_COMPLETION_INDEX is set (a Kubernetes Indexed Job) but the number of shards is not: set LONGREACH_SHARD_COUNT to the Job's completions, or pass --shard-count N",
                )?,
            };
            return Self::checked(index + 1, n, "JOB_COMPLETION_INDEX").map(Some);
        }
        Ok(None)
    }

    fn checked(k: usize, n: usize, source: &str) -> Result<Self, String> {
        if n == 0 || k == 0 || k > n {
            return Err(format!(
                "{source} give shard {k} of {n}: need 1 <= K <= N; check the array range and the shard count"
            ));
        }
        Ok(Self { k, n })
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.k, self.n)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn env<'a>(pairs: &'a [(&'a str, &'a str)]) -> impl Fn(&str) -> Option<String> + 'a {
        move |k| {
            pairs
                .iter()
                .find(|(n, _)| *n == k)
                .map(|(_, v)| v.to_string())
        }
    }

    #[test]
    fn shards_partition_the_indices() {
        let n = 3;
        let shards: Vec<Shard> = (1..=n).map(|k| Shard { k, n }).collect();
        for i in 0..20 {
            assert_eq!(shards.iter().filter(|s| s.contains(i)).count(), 1);
        }
        assert_eq!(Shard::parse("2/3"), Ok(Shard { k: 2, n: 3 }));
        assert!(Shard::parse("0/3").is_err());
        assert!(Shard::parse("4/3").is_err());
        assert!(Shard::parse("3").is_err());
    }

    #[test]
    fn reads_slurm_and_kubernetes_variables() {
        let slurm = [
            ("SLURM_ARRAY_TASK_ID", "5"),
            ("SLURM_ARRAY_TASK_MIN", "1"),
            ("SLURM_ARRAY_TASK_COUNT", "8"),
        ];
        assert_eq!(
            Shard::from_env(env(&slurm), None),
            Ok(Some(Shard { k: 5, n: 8 }))
        );
        let stepped = [
            ("SLURM_ARRAY_TASK_ID", "4"),
            ("SLURM_ARRAY_TASK_MIN", "0"),
            ("SLURM_ARRAY_TASK_STEP", "2"),
            ("SLURM_ARRAY_TASK_COUNT", "3"),
        ];
        assert_eq!(
            Shard::from_env(env(&stepped), None),
            Ok(Some(Shard { k: 3, n: 3 }))
        );
        let k8s = [
            ("JOB_COMPLETION_INDEX", "0"),
            ("LONGREACH_SHARD_COUNT", "4"),
        ];
        assert_eq!(
            Shard::from_env(env(&k8s), None),
            Ok(Some(Shard { k: 1, n: 4 }))
        );
        assert!(Shard::from_env(env(&[("JOB_COMPLETION_INDEX", "0")]), None).is_err());
        assert!(Shard::from_env(env(&[("JOB_COMPLETION_INDEX", "4")]), Some(4)).is_err());
        assert_eq!(Shard::from_env(env(&[]), None), Ok(None));
    }
}
