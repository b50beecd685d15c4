//! `scaledp experiment compare --benchmark metaworld|aloha --tasks …`: the comparison on a
//! simulation benchmark, task by task. Per task: `--demos` successful demonstrations by the
//! simulator's scripted expert (`scaledp collect --rig <benchmark>/<task> --successes N`, seeds
//! from 0), converted at the rig's image size in the benchmark's action space; every arm trained with the one recipe, its last
//! checkpoint scored on the test seeds; the controls beside it (the scripted expert on the same
//! seeds, the first arm's untrained weights and its cameras frozen). Each (task, arm) resumes
//! where it stopped and lands its JSON as it finishes; the table (by difficulty level) and the
//! plot are rebuilt from the files that are there.

mod cells;
mod chart;
mod files;
mod kind;
mod pooled;
mod replicates;
mod report;
mod rescore;
mod scoring;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use anyhow::{bail, Context, Result};
use scaledp_deploy::Split;
use scaledp_policy::{model::ScaleDp, Policy, TrainOptions};
use scaledp_schema::{ActionSpace, Rig};

use files::{landed, result_path, run_dir};
pub use files::{TaskControls, TaskResult};
pub(crate) use report::{is_benchmark, rebuild, summaries};
use scoring::score_controls;

use crate::arms::Arm;
use crate::audit::{self, Audit, Binary, Collection};
use crate::evaluate::{self, EvalPlan, Kind};
use crate::figures::EvalFigures;
use crate::provenance::write_json;
use crate::{train, Benchmark, CompareArgs, Settings};

/// Successful episodes listed in a `collect.jsonl`, and the next unused seed.
fn collected(demos: &Path) -> (u64, u64) {
    let text = std::fs::read_to_string(demos.join("collect.jsonl")).unwrap_or_default();
    let (mut ok, mut next) = (0, 0);
    for v in text
        .lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
    {
        ok += u64::from(v["outcome"] == "success" && v["episode"].is_string());
        next = next.max(v["seed"].as_u64().map_or(0, |s| s + 1));
    }
    (ok, next)
}

/// Runs `scaledp <args>` (this executable), failing with its status.
fn scaledp(args: &[&str]) -> Result<()> {
    let exe = std::env::current_exe().context("finding the scaledp executable")?;
    eprintln!("  $ scaledp {}", args.join(" "));
    let status = Command::new(&exe)
        .args(args)
        .status()
        .with_context(|| format!("running {}", exe.display()))?;
    // 3: finished but lost data (a recording dropped messages) — still a dataset to check.
    if !(status.success() || status.code() == Some(3)) {
        bail!("scaledp {} failed ({status})", args.join(" "));
    }
    Ok(())
}

/// The task's dataset: `demos` successful demonstrations collected and converted in `space`
/// (whatever of that is already there is kept).
fn prepare(rig: &Rig, dir: &Path, demos: u64, space: ActionSpace) -> Result<(PathBuf, u64)> {
    let ds = dir.join("dataset");
    let rec = dir.join("demos");
    let (mut ok, next) = collected(&rec);
    if ds.join("meta/info.json").exists() {
        return Ok((ds, ok));
    }
    if ok < demos {
        let (n, seed) = ((demos - ok).to_string(), next.to_string());
        let out = rec.display().to_string();
        scaledp(&[
            "collect",
            "--rig",
            &rig.name,
            "--successes",
            &n,
            "--seed",
            &seed,
            "--out",
            &out,
        ])?;
        ok = collected(&rec).0;
        if ok < demos {
            bail!("{}: {ok} successful demonstrations of {demos}", rig.name);
        }
    }
    let cam = rig.cameras.first().context("the rig has no camera")?;
    let size = format!("{}x{}", cam.width, cam.height);
    let partial = dir.join("dataset.partial");
    let _ = std::fs::remove_dir_all(&partial);
    let (src, dst) = (rec.display().to_string(), partial.display().to_string());
    scaledp(&[
        "convert",
        &src,
        "--out",
        &dst,
        "--size",
        &size,
        "--action",
        space.name(),
    ])?;
    std::fs::rename(&partial, &ds).with_context(|| format!("finishing {}", ds.display()))?;
    Ok((ds, ok))
}

/// Refuses a dataset recorded with a camera at another field of view than `rig`'s (made with
/// an earlier rig file): its arms would train on other pictures than evaluation shows them.
fn same_pictures(rig: &Rig, ds: &Path, dir: &Path) -> Result<()> {
    let info = ds.join("meta/info.json");
    let text =
        std::fs::read_to_string(&info).with_context(|| format!("reading {}", info.display()))?;
    let v: serde_json::Value =
        serde_json::from_str(&text).with_context(|| format!("parsing {}", info.display()))?;
    let Some(stored) = v["scaledp"]["rig"].as_str().filter(|t| t.contains('=')) else {
        return Ok(());
    };
    let then = Rig::parse(stored, &info)?;
    if let Some(c) = then.fov_change(rig) {
        bail!(
            "{}: recorded with camera {} at a vertical field of view of {}, and rig {} has {}: \
             move {} aside to collect and train at the rig's",
            ds.display(),
            c.camera,
            scaledp_schema::fov_label(c.from),
            rig.name,
            scaledp_schema::fov_label(c.to),
            dir.display()
        );
    }
    Ok(())
}

/// The demonstrations of a task's run directory, with the command that collected them.
fn collection(task_dir: &Path, rig: &Rig) -> Result<Collection> {
    let demos = task_dir.join("demos");
    let n = collected(&demos).0;
    Collection::read(
        &demos,
        format!(
            "scaledp collect --rig {} --successes {n} --seed 0 --out {}",
            rig.name,
            demos.display()
        ),
    )
}

/// Runs the benchmark comparison of `a`.
pub(crate) fn run(
    a: &CompareArgs,
    st: &Settings,
    base: TrainOptions,
    stop: &Arc<AtomicBool>,
) -> Result<()> {
    let Some(bench) = a.benchmark else {
        bail!("no --benchmark");
    };
    if a.tasks.is_empty() {
        bail!(
            "--benchmark {} needs --tasks (comma-separated)",
            bench.name()
        );
    }
    let demos = a.demos.unwrap_or(bench.demos());
    let results_dir = a.results.join(&st.name);
    std::fs::create_dir_all(&results_dir)
        .with_context(|| format!("creating {}", results_dir.display()))?;
    let plan = EvalPlan {
        max_seconds: a.max_seconds,
        action_steps: st.action_steps,
        fresh: false,
    };
    if a.rescore {
        return rescore::run(a, st, bench, &results_dir, &plan);
    }
    for task in &a.tasks {
        let level = bench.level(task)?;
        let rig = Rig::load_or_builtin(&bench.rig(task))?;
        let task_dir = a.runs.join(&st.name).join(task);
        let names: Vec<&str> = st.arms.iter().map(|arm| arm.name).collect();
        let with_controls = !a.no_controls && a.train_seed == 0;
        if landed(&results_dir, task, &names, a.train_seed, with_controls) {
            eprintln!("== task {task} ({level}): every arm named has landed, nothing to do");
            continue;
        }
        eprintln!("== task {task} ({level})");
        let (dataset, demos) = prepare(&rig, &task_dir, demos, bench.action_space())?;
        same_pictures(&rig, &dataset, &task_dir)?;
        let dataset = dataset.display().to_string();
        for &arm in &st.arms {
            let path = result_path(&results_dir, task, arm.name, a.train_seed);
            if path.exists() {
                continue;
            }
            eprintln!(
                "== {task}: arm {}{}: {}",
                arm.name,
                match a.train_seed {
                    0 => String::new(),
                    s => format!(" (training seed {s})"),
                },
                arm.what
            );
            let opts = arm.options(base.clone());
            let run = run_dir(&task_dir, arm.name, a.train_seed);
            let trainer = audit::record_trainer(&run)?;
            let trained = train::train(&dataset, &run, opts.clone(), stop)?;
            if trained.interrupted {
                eprintln!(
                    "stopped at step {}: the same command resumes it",
                    trained.steps
                );
                return Ok(());
            }
            let (_, last) = evaluate::checkpoints(&run)?
                .pop()
                .context("the run has no checkpoint")?;
            let test = evaluate::checkpoint(
                &last,
                Some(&rig),
                Kind::Policy,
                Split::Test,
                a.test_episodes,
                &plan,
            )?;
            let policy = Policy::load(&last, &candle_core::Device::Cpu)?;
            let counts = ScaleDp::count(&policy.config().model)?;
            let times = train::step_times(&run)?;
            let figures = EvalFigures::of(&test);
            let result = TaskResult {
                benchmark: bench.name().into(),
                task: task.clone(),
                level: level.into(),
                arm: arm.name.into(),
                train_seed: a.train_seed,
                what: arm.what.into(),
                test_success_rate: figures.success_rate,
                test_seeds: (0..a.test_episodes).map(|i| test.seed + i).collect(),
                wilson_low: figures.wilson_low,
                wilson_high: figures.wilson_high,
                test: figures,
                train_hours: trained.hours,
                steps: trained.steps,
                step_s: times.iter().sum::<f64>() / times.len().max(1) as f64,
                checkpoint: last.display().to_string(),
                denoiser_params: counts.denoiser,
                encoder_params: counts.encoders,
                demonstrations: demos,
                command: command(a, st, bench, task, arm),
                train_command: crate::train_command(&dataset, &st.preset, arm, &opts, &run),
                train_options: serde_json::to_value(&opts)?,
                audit: Audit {
                    schema: audit::SCHEMA,
                    trained_by: Some(trainer),
                    scored_by: Binary::this(),
                    simulator: audit::simulator(&test),
                    collection: Some(collection(&task_dir, &rig)?),
                    train_seed: Some(a.train_seed),
                },
                earlier_scores: Vec::new(),
                rescore_command: None,
            };
            write_json(&path, &result)?;
            println!(
                "{task} {}: test {} after {} steps ({:.2} h of training); {}",
                arm.name,
                result.test.cell(),
                result.steps,
                result.train_hours,
                path.display()
            );
            rebuild(&results_dir)?;
        }
        if with_controls {
            if let Some(&first) = st.arms.first() {
                controls(a, &rig, task, level, first, &task_dir, &results_dir, &plan)?;
            }
        }
    }
    Ok(())
}

/// The controls of a task, once its first arm has trained.
#[allow(clippy::too_many_arguments)]
fn controls(
    a: &CompareArgs,
    rig: &Rig,
    task: &str,
    level: &str,
    arm: Arm,
    task_dir: &Path,
    results_dir: &Path,
    plan: &EvalPlan,
) -> Result<()> {
    let path = results_dir.join(format!("{task}--controls.json"));
    if path.exists() {
        return Ok(());
    }
    eprintln!("== {task}: controls");
    let Some((scored, simulator)) = score_controls(
        rig,
        task_dir,
        arm.name,
        a.test_episodes,
        a.controls_episodes,
        plan,
    )?
    else {
        eprintln!(
            "== {task}: controls not scored: {} has no step-0 and final checkpoints under {} \
             (name first an arm this machine trained)",
            arm.name,
            task_dir.join(arm.name).display()
        );
        return Ok(());
    };
    let c = TaskControls {
        task: task.into(),
        level: level.into(),
        arm: arm.name.into(),
        controls: scored,
        audit: Audit {
            schema: audit::SCHEMA,
            trained_by: Some(audit::record_trainer(&task_dir.join(arm.name))?),
            scored_by: Binary::this(),
            simulator,
            collection: Some(collection(task_dir, rig)?),
            train_seed: Some(0),
        },
        earlier_scores: Vec::new(),
        rescore_command: None,
    };
    write_json(&path, &c)?;
    rebuild(results_dir)
}

/// The command line that reproduces one (task, arm).
fn command(a: &CompareArgs, st: &Settings, bench: Benchmark, task: &str, arm: Arm) -> String {
    let seed = match a.train_seed {
        0 => String::new(),
        s => format!(" --train-seed {s}"),
    };
    format!(
        "scaledp experiment compare --benchmark {} --tasks {task} --arms {} --name {} --preset {} --demos {} --test-episodes {} --controls-episodes {} --max-seconds {} --action-steps {}{seed}",
        bench.name(), arm.name, st.name, st.preset, a.demos.unwrap_or(bench.demos()), a.test_episodes, a.controls_episodes, a.max_seconds, st.action_steps
    )
}
