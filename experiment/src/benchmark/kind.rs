//! What differs between the simulation benchmarks `compare` runs: their rigs, task names and
//! levels, how many demonstrations, the recipe and the action space a task trains in.

use anyhow::{bail, Result};
use scaledp_schema::benchmarks::{metaworld_difficulty, ALOHA_TASKS};
use scaledp_schema::ActionSpace;

use crate::args::Benchmark;

impl Benchmark {
    /// `metaworld`, `aloha`: the experiment's default name and the results' `benchmark`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Metaworld => "metaworld",
            Self::Aloha => "aloha",
        }
    }

    /// The recipe every task and arm trains with.
    pub fn preset(self) -> &'static str {
        match self {
            Self::Metaworld => "cpu-metaworld",
            Self::Aloha => "cpu-aloha",
        }
    }

    /// Successful demonstrations per task: the ScaleDP paper's 20 on MetaWorld, the ACT paper's
    /// 50 on ALOHA.
    pub fn demos(self) -> u64 {
        match self {
            Self::Metaworld => 20,
            Self::Aloha => 50,
        }
    }

    /// The space the datasets are converted in: MetaWorld's Sawyer takes TCP targets; ALOHA's
    /// puppets follow the leader arms' joints, and ACT (and LeRobot) train on those.
    pub(crate) fn action_space(self) -> ActionSpace {
        match self {
            Self::Metaworld => ActionSpace::Tcp,
            Self::Aloha => ActionSpace::Joints,
        }
    }

    /// The rig that runs `task`.
    pub(crate) fn rig(self, task: &str) -> String {
        format!("{}/{task}", self.name())
    }

    /// The level `task` is reported under (MetaWorld's difficulty; ALOHA's tasks are all
    /// `bimanual`), or an error naming the tasks there are.
    pub(crate) fn level(self, task: &str) -> Result<&'static str> {
        match self {
            Self::Metaworld => match metaworld_difficulty(task) {
                Some(d) => Ok(d.label()),
                None => bail!("--tasks {task}: not one of MetaWorld's 50 tasks"),
            },
            Self::Aloha if ALOHA_TASKS.contains(&task) => Ok("bimanual"),
            Self::Aloha => bail!("--tasks {task}: ALOHA's are {}", ALOHA_TASKS.join(", ")),
        }
    }
}

/// What others published on a benchmark's tasks, quoted under its table (cited, not run here),
/// by the results' `benchmark` name.
pub(crate) fn published(benchmark: &str) -> Option<&'static str> {
    match benchmark {
        "aloha" => Some(
            "\nPublished for scale (cited, not run here): the ACT paper's Table I (Zhao et al. \
             2023, arXiv 2304.13705; 50 scripted demonstrations per task, 3 training seeds × 50 \
             evaluations, a GPU). Transfer-cube: ACT touched 97 %, lifted 90 %, **transferred \
             86 %**; its best baseline (BeT) 27 %. Insertion: ACT grasped 93 %, contact 90 %, \
             **inserted 32 %**; BeT 3 %. ACT's repository's README says \"around 90 %\" and \
             \"around 50 %\" (its simulation code renders the one top camera at 480×640).\n",
        ),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tasks_are_checked_against_their_benchmark() {
        assert_eq!(Benchmark::Metaworld.level("assembly").unwrap(), "hard");
        assert_eq!(Benchmark::Aloha.level("insertion").unwrap(), "bimanual");
        let e = Benchmark::Aloha.level("assembly").unwrap_err().to_string();
        assert!(e.contains("transfer-cube, insertion"), "{e}");
        assert!(Benchmark::Metaworld.level("transfer-cube").is_err());
        assert_eq!(Benchmark::Aloha.rig("insertion"), "aloha/insertion");
    }
}
