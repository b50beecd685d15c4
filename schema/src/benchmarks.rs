//! The simulation benchmarks a rig can stand for: which simulator runs behind the bridge
//! protocol (a rig's `[simulator]` table), the built-in `metaworld/<task>` rigs and
//! MetaWorld's 50 task names by difficulty level.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::rig::Rig;
pub use crate::simulator::{Simulator, SimulatorKind};

/// MetaWorld's difficulty levels (Seo et al. 2023, as the 3D Diffusion Policy paper and the
/// ScaleDP paper group their tables).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Difficulty {
    /// 28 tasks.
    Easy,
    /// 11 tasks.
    Medium,
    /// 6 tasks.
    Hard,
    /// 5 tasks.
    VeryHard,
}

impl Difficulty {
    /// Every level, easiest first.
    pub const ALL: [Difficulty; 4] = [Self::Easy, Self::Medium, Self::Hard, Self::VeryHard];

    /// `easy`, `medium`, `hard`, `very hard`.
    pub fn label(self) -> &'static str {
        match self {
            Self::Easy => "easy",
            Self::Medium => "medium",
            Self::Hard => "hard",
            Self::VeryHard => "very hard",
        }
    }
}

const VERY_HARD: &[&str] = &[
    "shelf-place",
    "disassemble",
    "stick-pull",
    "stick-push",
    "pick-place-wall",
];
const HARD: &[&str] = &[
    "assembly",
    "hand-insert",
    "pick-out-of-hole",
    "pick-place",
    "push",
    "push-back",
];
const MEDIUM: &[&str] = &[
    "basketball",
    "bin-picking",
    "box-close",
    "coffee-pull",
    "coffee-push",
    "hammer",
    "peg-insert-side",
    "push-wall",
    "soccer",
    "sweep",
    "sweep-into",
];
const EASY: &[&str] = &[
    "button-press",
    "button-press-topdown",
    "button-press-topdown-wall",
    "button-press-wall",
    "coffee-button",
    "dial-turn",
    "door-close",
    "door-lock",
    "door-open",
    "door-unlock",
    "drawer-close",
    "drawer-open",
    "faucet-close",
    "faucet-open",
    "handle-press",
    "handle-press-side",
    "handle-pull",
    "handle-pull-side",
    "lever-pull",
    "peg-unplug-side",
    "plate-slide",
    "plate-slide-back",
    "plate-slide-back-side",
    "plate-slide-side",
    "reach",
    "reach-wall",
    "window-close",
    "window-open",
];

/// MetaWorld's 50 tasks (names without `-v3`) with their difficulty level, by level.
pub fn metaworld_tasks() -> impl Iterator<Item = (&'static str, Difficulty)> {
    [
        (EASY, Difficulty::Easy),
        (MEDIUM, Difficulty::Medium),
        (HARD, Difficulty::Hard),
        (VERY_HARD, Difficulty::VeryHard),
    ]
    .into_iter()
    .flat_map(|(names, d)| names.iter().map(move |n| (*n, d)))
}

/// The difficulty of MetaWorld task `name` (with or without `-v3`).
pub fn metaworld_difficulty(name: &str) -> Option<Difficulty> {
    let name = name.strip_suffix("-v3").unwrap_or(name);
    metaworld_tasks().find(|(n, _)| *n == name).map(|(_, d)| d)
}

/// gym-aloha's bimanual tasks, as `aloha/<task>` rigs name them.
pub const ALOHA_TASKS: [&str; 2] = ["transfer-cube", "insertion"];

const ALOHA_TEMPLATE: &str = include_str!("../../rigs/aloha.toml");

fn aloha_rig(task: &str) -> Result<Rig> {
    if !ALOHA_TASKS.contains(&task) {
        return Err(Error::Rig {
            path: PathBuf::from(format!("aloha/{task}")),
            reason: format!(
                "gym-aloha has no task {task:?}; its tasks: {}",
                ALOHA_TASKS.join(", ")
            ),
        });
    }
    let text = ALOHA_TEMPLATE.replace("TASK", task);
    Rig::parse(&text, &PathBuf::from("rigs/aloha.toml"))
}

const METAWORLD_TEMPLATE: &str = include_str!("../../rigs/metaworld.toml");

/// The built-in rig of a simulated benchmark: `metaworld/<task>` for any of MetaWorld's 50
/// tasks, `aloha/<task>` for gym-aloha's two ([`ALOHA_TASKS`]). `None` when `name` names no benchmark; an error naming the valid tasks when it names
/// a benchmark but no task of it.
pub fn builtin(name: &str) -> Option<Result<Rig>> {
    if let Some(task) = name.strip_prefix("aloha/") {
        return Some(aloha_rig(task));
    }
    let task = name.strip_prefix("metaworld/")?;
    let task = task.strip_suffix("-v3").unwrap_or(task);
    if metaworld_difficulty(task).is_none() {
        let names: Vec<&str> = metaworld_tasks().map(|(n, _)| n).collect();
        return Some(Err(Error::Rig {
            path: PathBuf::from(name),
            reason: format!(
                "MetaWorld has no task {task:?}; its 50 tasks: {}",
                names.join(", ")
            ),
        }));
    }
    let text = METAWORLD_TEMPLATE.replace("TASK", task);
    Some(Rig::parse(&text, &PathBuf::from("rigs/metaworld.toml")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fifty_tasks_in_four_levels_and_a_rig_for_each() {
        let all: Vec<_> = metaworld_tasks().collect();
        assert_eq!(all.len(), 50);
        let count = |d| all.iter().filter(|(_, x)| *x == d).count();
        assert_eq!(
            Difficulty::ALL.map(count),
            [28, 11, 6, 5],
            "easy, medium, hard, very hard"
        );
        let mut names: Vec<_> = all.iter().map(|(n, _)| *n).collect();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), 50, "no task twice");
        for (task, _) in all {
            let rig = builtin(&format!("metaworld/{task}")).unwrap().unwrap();
            assert_eq!(rig.name, format!("metaworld/{task}"));
            let sim = rig.simulator.as_ref().unwrap();
            assert_eq!(
                (sim.bridge, sim.task.as_str()),
                (SimulatorKind::Metaworld, task)
            );
        }
        let e = builtin("metaworld/fly").unwrap().unwrap_err().to_string();
        assert!(
            e.contains("no task \"fly\"") && e.contains("assembly"),
            "{e}"
        );
        assert!(builtin("franka_sim").is_none());
        assert_eq!(metaworld_difficulty("assembly-v3"), Some(Difficulty::Hard));
        for task in ALOHA_TASKS {
            let rig = builtin(&format!("aloha/{task}")).unwrap().unwrap();
            assert_eq!(rig.arms.len(), 2);
            assert_eq!(rig.simulator.as_ref().unwrap().bridge, SimulatorKind::Aloha);
        }
        let e = builtin("aloha/juggle").unwrap().unwrap_err().to_string();
        assert!(e.contains("transfer-cube, insertion"), "{e}");
    }
}
