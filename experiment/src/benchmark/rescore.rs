//! `compare --benchmark … --rescore`: the tasks' finished results scored again with this build,
//! after a change to the simulator's bridge (its `scaledp-bridge` behaviour). Each (task, arm)
//! has its last checkpoint scored on the same test seeds, and each task its controls; nothing
//! is trained. Every file keeps what it said before in `earlier_scores` and is replaced whole
//! (a `.partial` renamed over it). A (task, arm) whose checkpoint is gone is named at the end
//! and the others are still scored.

use std::path::Path;

use anyhow::{bail, Context, Result};
use scaledp_deploy::Split;
use scaledp_schema::Rig;
use serde::de::DeserializeOwned;

use super::files::{result_path, run_dir, Earlier, TaskControls, TaskResult};
use super::report::rebuild;
use super::scoring::score_controls;
use crate::audit::{self, Binary};
use crate::evaluate::{self, EvalPlan, Kind};
use crate::figures::{Controls, EvalFigures};
use crate::provenance::write_json;
use crate::{Benchmark, CompareArgs, Settings};

/// Scores the finished results of `a`'s tasks and arms again.
pub(super) fn run(
    a: &CompareArgs,
    st: &Settings,
    bench: Benchmark,
    results_dir: &Path,
    plan: &EvalPlan,
) -> Result<()> {
    let plan = EvalPlan {
        fresh: true,
        ..plan.clone()
    };
    let (mut done, mut skipped) = (0, Vec::new());
    for task in &a.tasks {
        bench.level(task)?;
        let rig = Rig::load_or_builtin(&bench.rig(task))?;
        let task_dir = a.runs.join(&st.name).join(task);
        let command = |arms: &str| rescore_command(a, st, bench, task, arms);
        for &arm in &st.arms {
            let path = result_path(results_dir, task, arm.name, a.train_seed);
            if !path.exists() {
                skipped.push(format!(
                    "{}: no result yet (train it without --rescore)",
                    path.display()
                ));
                continue;
            }
            eprintln!("== {task}: arm {}: re-scoring", arm.name);
            let run = run_dir(&task_dir, arm.name, a.train_seed);
            match task_result(&path, &rig, &run, &plan, command(arm.name)) {
                Ok(line) => {
                    println!("{task} {}: {line}", arm.name);
                    done += 1;
                    rebuild(results_dir)?;
                }
                Err(e) => skipped.push(format!("{e:#}")),
            }
        }
        let path = results_dir.join(format!("{task}--controls.json"));
        if a.no_controls || a.train_seed != 0 || !path.exists() {
            continue;
        }
        eprintln!("== {task}: controls: re-scoring");
        let arms = st.arms.iter().map(|a| a.name).collect::<Vec<_>>().join(",");
        match controls(&path, &rig, &task_dir, &plan, command(&arms)) {
            Ok(line) => {
                println!("{task} controls: {line}");
                done += 1;
                rebuild(results_dir)?;
            }
            Err(e) => skipped.push(format!("{e:#}")),
        }
    }
    if !skipped.is_empty() {
        bail!(
            "re-scored {done} file(s); not re-scored:\n  {}",
            skipped.join("\n  ")
        );
    }
    eprintln!("re-scored {done} file(s) in {}", results_dir.display());
    Ok(())
}

fn read<T: DeserializeOwned>(path: &Path, what: &str) -> Result<T> {
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    serde_json::from_slice(&bytes).with_context(|| format!("{}: not {what}", path.display()))
}

/// The last checkpoint of `run`, which must be the one `path` scored (step `steps`).
fn last_checkpoint(run: &Path, steps: u64, path: &Path) -> Result<std::path::PathBuf> {
    let gone = || {
        format!(
            "{}: its checkpoint (step {steps} of {}) is gone: move the file aside and run \
             without --rescore to train it again",
            path.display(),
            run.display()
        )
    };
    let (step, last) = evaluate::checkpoints(run)
        .ok()
        .and_then(|mut c| c.pop())
        .with_context(gone)?;
    if step != steps {
        bail!(
            "{}: scored step {steps}, but the last checkpoint of {} is step {step}",
            path.display(),
            run.display()
        );
    }
    Ok(last)
}

/// Re-scores one (task, arm) file: its test episodes again, the earlier figures kept.
fn task_result(
    path: &Path,
    rig: &Rig,
    run: &Path,
    plan: &EvalPlan,
    command: String,
) -> Result<String> {
    let mut r: TaskResult = read(path, "a task result")?;
    let last = last_checkpoint(run, r.steps, path)?;
    let report = evaluate::checkpoint(
        &last,
        Some(rig),
        Kind::Policy,
        Split::Test,
        r.test.episodes,
        plan,
    )?;
    let test = EvalFigures::of(&report);
    let was = r.test.cell();
    r.earlier_scores.push(Earlier {
        figures: r.test.clone(),
        audit: r.audit.clone(),
    });
    r.test_success_rate = test.success_rate;
    r.wilson_low = test.wilson_low;
    r.wilson_high = test.wilson_high;
    r.test_seeds = (0..test.episodes).map(|i| test.first_seed + i).collect();
    r.audit.simulator = audit::simulator(&report);
    r.audit.scored_by = Binary::this();
    r.test = test;
    r.rescore_command = Some(command);
    write_json(path, &r)?;
    Ok(format!(
        "test {} (was {was}); {}",
        r.test.cell(),
        path.display()
    ))
}

/// Re-scores a task's controls, each on as many episodes as before.
fn controls(
    path: &Path,
    rig: &Rig,
    task_dir: &Path,
    plan: &EvalPlan,
    command: String,
) -> Result<String> {
    let mut c: TaskControls = read(path, "a task's controls")?;
    let episodes = |f: &Option<EvalFigures>| f.as_ref().map_or(0, |f| f.episodes);
    let before = &c.controls;
    let (expert, n) = (
        episodes(&before.scripted_expert),
        episodes(&before.untrained).max(episodes(&before.frozen_cameras)),
    );
    let (scored, simulator) = score_controls(rig, task_dir, &c.arm, expert, n, plan)?
        .with_context(|| {
            format!(
                "{}: the checkpoints of {} are gone",
                path.display(),
                task_dir.join(&c.arm).display()
            )
        })?;
    let line = summary(&c.controls, &scored);
    let was = std::mem::replace(&mut c.controls, scored);
    c.earlier_scores.push(Earlier {
        figures: was,
        audit: c.audit.clone(),
    });
    c.audit.simulator = simulator;
    c.audit.scored_by = Binary::this();
    c.rescore_command = Some(command);
    write_json(path, &c)?;
    Ok(format!("{line}; {}", path.display()))
}

/// `expert 49/50 (was 49/50), untrained 0/20 (was 0/20), cameras frozen 1/20 (was 1/20)`.
fn summary(was: &Controls, now: &Controls) -> String {
    let count = |f: &Option<EvalFigures>| {
        f.as_ref()
            .map_or("–".into(), |f| format!("{}/{}", f.successes, f.episodes))
    };
    [
        ("expert", &was.scripted_expert, &now.scripted_expert),
        ("untrained", &was.untrained, &now.untrained),
        ("cameras frozen", &was.frozen_cameras, &now.frozen_cameras),
    ]
    .iter()
    .map(|(what, w, n)| format!("{what} {} (was {})", count(n), count(w)))
    .collect::<Vec<_>>()
    .join(", ")
}

/// The command line of a re-score of `task`'s `arms`.
fn rescore_command(
    a: &CompareArgs,
    st: &Settings,
    bench: Benchmark,
    task: &str,
    arms: &str,
) -> String {
    let seed = match a.train_seed {
        0 => String::new(),
        s => format!(" --train-seed {s}"),
    };
    format!(
        "scaledp experiment compare --benchmark {} --tasks {task} --arms {arms} --name {} --max-seconds {} --action-steps {}{seed} --rescore",
        bench.name(), st.name, a.max_seconds, st.action_steps
    )
}
