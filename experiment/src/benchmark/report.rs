//! A benchmark's table (`table.md`: per task and arm the test success with its interval, the
//! controls, and per level the mean over its tasks) and plot (`success_by_level.svg`: per
//! level, or per task when the benchmark has one level, as ALOHA), rebuilt from the (task, arm)
//! files in the results directory.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};

use super::cells::{behaviour, level_of, marked, Level};
use super::chart::{display_name, level_means, plot};
use super::files::{TaskControls, TaskResult};
use super::pooled;
use super::replicates::{cell, pairings, replicates};
use crate::arms::ARMS;
use crate::figures::EvalFigures;
use crate::significance::{self, seed_suffix};

/// Whether `dir` holds a benchmark's results (files named `<task>--<arm>.json`).
pub(crate) fn is_benchmark(dir: &Path) -> bool {
    std::fs::read_dir(dir).is_ok_and(|d| {
        d.filter_map(|e| e.ok())
            .any(|e| e.file_name().to_string_lossy().contains("--"))
    })
}

struct Loaded {
    results: Vec<TaskResult>,
    controls: BTreeMap<String, TaskControls>,
}

fn load(dir: &Path) -> Result<Loaded> {
    let mut results = Vec::new();
    let mut controls = BTreeMap::new();
    let mut names: Vec<_> = std::fs::read_dir(dir)
        .with_context(|| format!("reading {}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.extension().is_some_and(|x| x == "json")
                && p.file_name()
                    .is_some_and(|n| n.to_string_lossy().contains("--"))
        })
        .collect();
    names.sort();
    for path in names {
        let bytes = std::fs::read(&path).with_context(|| format!("reading {}", path.display()))?;
        if path.to_string_lossy().ends_with("--controls.json") {
            let c: TaskControls = serde_json::from_slice(&bytes)
                .with_context(|| format!("{}: not a task's controls", path.display()))?;
            controls.insert(c.task.clone(), c);
        } else {
            results.push(
                serde_json::from_slice(&bytes)
                    .with_context(|| format!("{}: not a task result", path.display()))?,
            );
        }
    }
    Ok(Loaded { results, controls })
}

/// The arms present, in the arms' order.
fn arms_of(results: &[TaskResult]) -> Vec<&'static str> {
    ARMS.iter()
        .map(|a| a.name)
        .filter(|n| results.iter().any(|r| r.arm == *n))
        .collect()
}

/// Which arm's checkpoints each task's untrained and frozen-camera controls were scored on
/// (its step 0 and its last): not always the same arm on every benchmark.
fn controls_arms(controls: &BTreeMap<String, TaskControls>) -> String {
    if controls.is_empty() {
        return String::new();
    }
    let each: Vec<String> = controls
        .iter()
        .map(|(task, c)| format!("{task} `{}`", c.arm))
        .collect();
    format!(
        "\nThe untrained and frozen-camera controls use the step-0 and last checkpoints of one \
         arm trained from seed 0: {}.\n",
        each.join(", ")
    )
}

/// Rebuilds `table.md` and `success_by_level.svg` in `dir`.
pub(crate) fn rebuild(dir: &Path) -> Result<()> {
    let l = load(dir)?;
    if l.results.is_empty() {
        bail!("{}: no task results yet", dir.display());
    }
    let arms = arms_of(&l.results);
    let (newest, older) = newest_behaviour(&l);
    let mut tasks: Vec<(Level, String)> = l
        .results
        .iter()
        .map(|r| (level_of(&r.level), r.task.clone()))
        .collect();
    tasks.sort();
    tasks.dedup();
    let mut md = String::from(
        "# Results\n\nRebuilt by `scaledp experiment report` from the files beside it: test-seed \
         success of each arm's last checkpoint (seeds 3 000 000 …, 95 % Wilson interval), and the \
         controls.\n\n",
    );
    md.push_str("| level | task |");
    for a in &arms {
        md.push_str(&format!(" {a} |"));
    }
    md.push_str(" scripted expert | untrained | cameras frozen |\n|---|---|");
    md.push_str(&"---|".repeat(arms.len() + 3));
    md.push('\n');
    for (level, task) in &tasks {
        md.push_str(&format!("| {} | {task} |", level.label));
        for a in &arms {
            md.push_str(&format!(
                " {} |",
                cell(&replicates(&l.results, task, a), newest)
            ));
        }
        let c = l.controls.get(task).map(|c| &c.controls);
        for f in [
            c.and_then(|c| c.scripted_expert.as_ref()),
            c.and_then(|c| c.untrained.as_ref()),
            c.and_then(|c| c.frozen_cameras.as_ref()),
        ] {
            md.push_str(&format!(
                " {} |",
                f.map_or("–".into(), |f| marked(f, newest))
            ));
        }
        md.push('\n');
    }
    md.push_str(&controls_arms(&l.controls));
    if older {
        md.push_str(&format!(
            "\n† Scored by an earlier behaviour of the simulator's bridge than the newest here \
             ({newest}; what changed is listed at `BEHAVIOUR` in `sim/bridges/scaledp_bridge/`): \
             `scaledp experiment compare --benchmark {} --tasks <task> --rescore` scores it again \
             with this build.\n",
            l.results[0].benchmark
        ));
    }
    let pairings = pairings(&tasks, &arms, &l.results);
    md.push_str(&significance::table(&pairings, true));
    let task_names: Vec<String> = tasks.iter().map(|(_, t)| t.clone()).collect();
    let pooled = pooled::table(&task_names, &arms, &l.results);
    if !pooled.is_empty() {
        md.push_str(&format!(
            "\nEach arm's training seeds pooled, read by the rule written in `docs/experiments.md` \
             before the runs finished (a finding needs p < 0.05 pooled and every seed agreeing):\n\n{pooled}"
        ));
    }
    md.push_str(&pooled::against_others(&task_names, &arms, &l.results));
    md.push_str(&stages_table(&tasks, &arms, &l));
    if let Some(cited) = super::kind::published(&l.results[0].benchmark) {
        md.push_str(cited);
    }
    md.push_str(
        "\nMean over each level's tasks (tasks where every arm has a result):\n\n| level | tasks |",
    );
    for a in &arms {
        md.push_str(&format!(" {a} |"));
    }
    md.push_str("\n|---|---|");
    md.push_str(&"---|".repeat(arms.len()));
    md.push('\n');
    for (level, means) in level_means(&tasks, &arms, &l.results) {
        let (n, values) = means;
        md.push_str(&format!("| {} | {n} |", level.label));
        for v in values {
            md.push_str(&format!(" {:.1} % |", 100.0 * v));
        }
        md.push('\n');
    }
    md.push_str("\n| task | arm | steps | training | s/step | inference p50 / p99 | trained at | scored at | machine |\n|---|---|---|---|---|---|---|---|---|\n");
    for (_, task) in &tasks {
        for a in &arms {
            for r in replicates(&l.results, task, a) {
                let ms = |v: Option<f64>| v.map_or("–".into(), |v| format!("{v:.0}"));
                md.push_str(&format!(
                    "| {task} | {a}{} | {} | {:.2} h | {:.2} | {} / {} ms | `{}` | `{}` | {} |\n",
                    seed_suffix(r.train_seed),
                    r.steps,
                    r.train_hours,
                    r.step_s,
                    ms(r.test.inference_ms_p50),
                    ms(r.test.inference_ms_p99),
                    r.audit
                        .trained_by
                        .as_ref()
                        .map_or("–".into(), |b| short(&b.revision)),
                    short(&r.audit.scored_by.revision),
                    r.audit.scored_by.machine
                ));
            }
        }
    }
    if let Some(r) = l.results.first() {
        md.push_str(&format!(
            "\nSimulator: {}. Every (task, arm) reproduces with the `command` of its JSON file.\n",
            r.audit
                .simulator
                .iter()
                .map(|(k, v)| format!("{k} {v}"))
                .collect::<Vec<_>>()
                .join(", ")
        ));
    }
    std::fs::write(dir.join("table.md"), md)
        .with_context(|| format!("writing {}/table.md", dir.display()))?;
    let title = l.results[0].benchmark.as_str();
    plot(
        title,
        &tasks,
        &arms,
        &l.results,
        &dir.join("success_by_level.svg"),
    )?;
    eprintln!(
        "rebuilt {}/table.md and success_by_level.svg",
        dir.display()
    );
    Ok(())
}

/// For staged tasks (ALOHA's rewards, MetaWorld's flags), the episodes of each arm and control
/// that reached each stage (furthest stage ≥ 1, 2, …), as ACT's evaluation reports them; empty
/// for other tasks and for results scored before their simulator named stages.
fn stages_table(tasks: &[(Level, String)], arms: &[&str], l: &Loaded) -> String {
    let mut md = String::new();
    for (_, task) in tasks {
        let c = l.controls.get(task).map(|c| &c.controls);
        let mut rows: Vec<(String, &EvalFigures)> = arms
            .iter()
            .flat_map(|a| {
                replicates(&l.results, task, a)
                    .into_iter()
                    .map(move |r| (format!("{a}{}", seed_suffix(r.train_seed)), &r.test))
            })
            .collect();
        for (who, f) in [
            (
                "scripted expert",
                c.and_then(|c| c.scripted_expert.as_ref()),
            ),
            ("untrained", c.and_then(|c| c.untrained.as_ref())),
            ("cameras frozen", c.and_then(|c| c.frozen_cameras.as_ref())),
        ] {
            rows.extend(f.map(|f| (who.to_string(), f)));
        }
        rows.retain(|(_, f)| !f.stages.is_empty());
        let Some((_, first)) = rows.first() else {
            continue;
        };
        md.push_str(&format!(
            "\n{task}: test episodes that reached each stage (furthest stage ≥ 1, 2, …):\n\n| |"
        ));
        for s in &first.stages {
            md.push_str(&format!(" {} |", s.stage));
        }
        md.push_str("\n|---|");
        md.push_str(&"---|".repeat(first.stages.len()));
        md.push('\n');
        for (who, f) in &rows {
            md.push_str(&format!("| {who} |"));
            for s in &f.stages {
                md.push_str(&format!(" {}/{} |", s.episodes, f.episodes));
            }
            md.push('\n');
        }
    }
    md
}

fn short(rev: &str) -> String {
    rev.get(..10).map_or(rev.to_string(), |s| {
        if rev.ends_with("-dirty") {
            format!("{s}-dirty")
        } else {
            s.to_string()
        }
    })
}

/// The newest bridge behaviour among the results and controls, and whether any of them was
/// scored by an older one.
fn newest_behaviour(l: &Loaded) -> (u32, bool) {
    let controls = l.controls.values().flat_map(|c| {
        let c = &c.controls;
        [&c.scripted_expert, &c.untrained, &c.frozen_cameras]
            .into_iter()
            .flatten()
    });
    let all: Vec<u32> = l
        .results
        .iter()
        .map(|r| &r.test)
        .chain(controls)
        .map(behaviour)
        .collect();
    let newest = all.iter().copied().max().unwrap_or(1);
    (newest, all.iter().any(|&b| b < newest))
}

/// The README's results summary: for each benchmark under `root` (each directory holding
/// results, in name order), its name and the pooled table of its files.
pub(crate) fn summaries(root: &Path) -> Result<String> {
    let mut dirs: Vec<PathBuf> = std::fs::read_dir(root)
        .with_context(|| format!("reading {}", root.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| is_benchmark(p))
        .collect();
    dirs.sort();
    let mut parts = Vec::new();
    for dir in &dirs {
        let name = dir
            .file_name()
            .map_or(String::new(), |n| n.to_string_lossy().into_owned());
        parts.push(format!("**{}**\n\n{}", display_name(&name), summary(dir)?));
    }
    if parts.is_empty() {
        bail!("{}: no benchmark results to summarise", root.display());
    }
    Ok(parts.join("\n"))
}

/// The pooled table of the benchmark results in `dir`.
fn summary(dir: &Path) -> Result<String> {
    let l = load(dir)?;
    let arms = arms_of(&l.results);
    let mut tasks: Vec<(Level, String)> = l
        .results
        .iter()
        .map(|r| (level_of(&r.level), r.task.clone()))
        .collect();
    tasks.sort();
    tasks.dedup();
    let names: Vec<String> = tasks.into_iter().map(|(_, t)| t).collect();
    Ok(pooled::table(&names, &arms, &l.results)
        + &pooled::against_others(&names, &arms, &l.results))
}
