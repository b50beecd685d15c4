//! `scaledp experiment`: the paper's comparisons at one machine's scale. ScaleDP-Ti with
//! non-causal attention (the recipe), the same with causal attention (the DP-T-style ablation)
//! and ScaleDP-S, each trained with one recipe on the same demonstrations, each checkpoint
//! scored in closed loop on the validation seeds, the best one scored on the test seeds — with
//! the recipe's arm also in real time and beside its controls (untrained weights, frozen
//! cameras, the scripted expert).
//!
//! Arms run one after the other and each resumes where it stopped (training from its last
//! checkpoint, evaluations from their cache files), so an arm can finish in one sitting on a
//! machine that may be gone the next day: its result file (`RESULTS/NAME/<arm>.json`) is
//! written as it lands, and the table (`table.md`) and plot (`success_vs_step.svg`) are rebuilt
//! from the arms that are there. Checkpoints stay under `RUNS/NAME` (never committed).
//!
//! Errors are `anyhow`: an application in library form, reported once by the CLI.

mod args;
mod arms;
pub mod audit;
mod benchmark;
mod evaluate;
mod figures;
mod grad_scale;
mod plot;
mod provenance;
mod results;
mod significance;
mod train;

use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use anyhow::{bail, Context, Result};
use scaledp_deploy::Split;
use scaledp_policy::{model::ScaleDp, Policy, TrainOptions};

pub use args::{Benchmark, CompareArgs, ExperimentCommand, ReportArgs};
pub use arms::{Arm, ARMS};
pub use figures::EvalFigures;
pub use grad_scale::GradScaleArgs;
pub use results::ArmResult;

use evaluate::{EvalPlan, Kind};
use figures::{Controls, ValPoint};

/// Runs one `scaledp experiment` command; `stop` (set by Ctrl-C) checkpoints a training run and
/// returns.
pub fn run(command: ExperimentCommand, stop: &Arc<AtomicBool>) -> Result<()> {
    match command {
        ExperimentCommand::Compare(a) => compare(&a, stop),
        ExperimentCommand::GradScale(a) => grad_scale::run(&a, stop),
        ExperimentCommand::Report(a) => {
            let dir = a.results.join(&a.name);
            if benchmark::is_benchmark(&dir) {
                benchmark::rebuild(&dir)?;
                match &a.readme {
                    Some(readme) => write_summary(readme, &a.results),
                    None => Ok(()),
                }
            } else {
                rebuild(&dir).map(|_| ())
            }
        }
    }
}

/// Where the README's results summary starts and ends.
pub const SUMMARY_MARKERS: (&str, &str) = ("<!-- results-summary -->", "<!-- /results-summary -->");

/// The README's results summary as `scaledp experiment report --readme` writes it from every
/// benchmark's results under `results` (ALOHA, MetaWorld): the markers and, per benchmark, its
/// pooled table between them.
pub fn readme_summary(results: &std::path::Path) -> Result<String> {
    let (start, end) = SUMMARY_MARKERS;
    let tables = benchmark::summaries(results)?;
    Ok(format!(
        "{start}\n<!-- written by `scaledp experiment report --name <benchmark> --readme README.md` \
         from every benchmark under docs/results; do not edit -->\n\n{tables}\n{end}"
    ))
}

/// Replaces the summary block of `readme` (or the bare start marker) with [`readme_summary`]
/// of the benchmarks under `results`.
fn write_summary(readme: &std::path::Path, results: &std::path::Path) -> Result<()> {
    let text =
        std::fs::read_to_string(readme).with_context(|| format!("reading {}", readme.display()))?;
    let (start, end) = SUMMARY_MARKERS;
    let Some(a) = text.find(start) else {
        bail!(
            "{}: no `{start}` line to write the summary at",
            readme.display()
        );
    };
    let b = text[a..]
        .find(end)
        .map_or(a + start.len(), |k| a + k + end.len());
    let new = format!("{}{}{}", &text[..a], readme_summary(results)?, &text[b..]);
    std::fs::write(readme, new).with_context(|| format!("writing {}", readme.display()))?;
    eprintln!("wrote the results summary of {}", readme.display());
    Ok(())
}

/// The command's settings with the defaults of its kind (one dataset, or a benchmark) filled in.
#[derive(Debug, Clone)]
pub(crate) struct Settings {
    name: String,
    arms: Vec<Arm>,
    preset: String,
    val_episodes: u64,
    live_episodes: u64,
    /// Actions executed per chunk in every evaluation.
    action_steps: usize,
}

impl Settings {
    fn of(a: &CompareArgs) -> Result<Self> {
        let bench = a.benchmark.is_some();
        let arms = if a.arms.is_empty() {
            if bench {
                vec!["ti".to_string(), "dp-t".to_string()]
            } else {
                vec!["ti".into(), "ti-causal".into(), "s".into()]
            }
        } else {
            a.arms.clone()
        };
        let preset = a
            .preset
            .clone()
            .unwrap_or_else(|| a.benchmark.map_or("cpu-sim", |b| b.preset()).into());
        // diffusion_policy's receding horizon: half the predicted chunk (8 of 16).
        let chunk = TrainOptions::preset(&preset).map_or(16, |o| o.get_action_chunk());
        Ok(Settings {
            name: a
                .name
                .clone()
                .unwrap_or_else(|| a.benchmark.map_or("cpu-sim", |b| b.name()).into()),
            arms: arms
                .iter()
                .map(|n| {
                    arms::arm(n).with_context(|| format!("--arms {n}: one of {}", arms::names()))
                })
                .collect::<Result<_>>()?,
            preset,
            val_episodes: a.val_episodes.unwrap_or(if bench { 0 } else { 20 }),
            live_episodes: a.live_episodes.unwrap_or(if bench { 0 } else { 20 }),
            action_steps: a.action_steps.unwrap_or((chunk / 2).max(1)),
        })
    }
}

/// The recipe with the command's overrides.
fn recipe(a: &CompareArgs, s: &Settings) -> Result<TrainOptions> {
    let mut o = TrainOptions::preset(&s.preset).with_context(|| {
        format!(
            "--preset {}: one of {}",
            s.preset,
            scaledp_policy::PRESETS.join(", ")
        )
    })?;
    if let Some(s) = a.steps {
        o = o.steps(s);
    }
    if let Some(c) = a.checkpoint_every {
        o = o.checkpoint_every(c);
    }
    if let Some(b) = a.batch_size {
        o = o.batch_size(b);
    }
    if a.train_seed != 0 {
        if a.benchmark.is_none() {
            bail!("--train-seed: replicates are kept for --benchmark comparisons only");
        }
        o = o.seed(a.train_seed);
    }
    if o.get_checkpoint_every() == 0 {
        bail!("the experiment evaluates every checkpoint: --checkpoint-every must be at least 1");
    }
    Ok(o)
}

/// The command line that reproduces this run of `compare` for one arm.
fn command(a: &CompareArgs, st: &Settings, dataset: &str, arm: &str) -> String {
    let mut s = format!(
        "scaledp experiment compare --dataset {dataset} --name {} --arms {arm} --preset {} --val-episodes {} --test-episodes {} --live-episodes {} --max-seconds {} --action-steps {}",
        st.name, st.preset, st.val_episodes, a.test_episodes, st.live_episodes, a.max_seconds, st.action_steps
    );
    for (flag, v) in [
        ("--steps", a.steps),
        ("--checkpoint-every", a.checkpoint_every),
    ] {
        if let Some(v) = v {
            s.push_str(&format!(" {flag} {v}"));
        }
    }
    if let Some(b) = a.batch_size {
        s.push_str(&format!(" --batch-size {b}"));
    }
    if a.no_controls {
        s.push_str(" --no-controls");
    }
    s
}

fn compare(a: &CompareArgs, stop: &Arc<AtomicBool>) -> Result<()> {
    let st = Settings::of(a)?;
    // What lands under docs/results is committed: it must come from a committed tree.
    let results_dir = a.results.join(&st.name);
    if results_dir.components().any(|c| c.as_os_str() == "docs") {
        audit::refuse_dirty(&results_dir)?;
    }
    if a.benchmark.is_some() {
        return benchmark::run(a, &st, recipe(a, &st)?, stop);
    }
    let dataset = a.dataset.clone().context("--dataset (or --benchmark)")?;
    let runs_dir = a.runs.join(&st.name);
    std::fs::create_dir_all(&results_dir)
        .with_context(|| format!("creating {}", results_dir.display()))?;
    let base = recipe(a, &st)?;
    let plan = EvalPlan {
        max_seconds: a.max_seconds,
        action_steps: st.action_steps,
        fresh: false,
    };
    for &arm in &st.arms {
        eprintln!("== arm {}: {}", arm.name, arm.what);
        let opts = arm.options(base.clone());
        let run = runs_dir.join(arm.name);
        let trainer = audit::record_trainer(&run)?;
        let trained = train::train(&dataset, &run, opts.clone(), stop)?;
        if trained.interrupted {
            eprintln!(
                "stopped at step {}: the same command resumes it",
                trained.steps
            );
            return Ok(());
        }
        let mut result = evaluate_arm(a, &st, &dataset, arm, &run, &opts, &plan, trained)?;
        result.audit.trained_by = Some(trainer);
        let path = results_dir.join(format!("{}.json", arm.name));
        std::fs::write(&path, serde_json::to_vec_pretty(&result)?)
            .with_context(|| format!("writing {}", path.display()))?;
        println!(
            "{}: test {} after {} steps ({:.2} h of training); {}",
            arm.name,
            result.test.cell(),
            result.steps,
            result.train_hours,
            path.display()
        );
        rebuild(&results_dir)?;
    }
    Ok(())
}

#[allow(clippy::too_many_arguments)]
fn evaluate_arm(
    a: &CompareArgs,
    st: &Settings,
    dataset: &str,
    arm: Arm,
    run: &std::path::Path,
    opts: &TrainOptions,
    plan: &EvalPlan,
    trained: train::Trained,
) -> Result<ArmResult> {
    let ckpts = evaluate::checkpoints(run)?;
    let mut validation = Vec::new();
    for (step, dir) in &ckpts {
        let r = evaluate::checkpoint(dir, None, Kind::Policy, Split::Val, st.val_episodes, plan)?;
        eprintln!(
            "  step {step}: {}/{} on the validation seeds",
            r.successes,
            r.episodes.len()
        );
        validation.push(ValPoint {
            step: *step,
            successes: r.successes,
            episodes: r.episodes.len() as u64,
            success_rate: r.success_rate,
        });
    }
    let pairs: Vec<(u64, u64)> = validation.iter().map(|v| (v.step, v.successes)).collect();
    let selected = evaluate::select(&pairs).context("the run has no checkpoint to evaluate")?;
    let best = ckpts
        .iter()
        .find(|c| c.0 == selected)
        .map(|c| c.1.clone())
        .context("the chosen checkpoint vanished")?;
    let test = evaluate::checkpoint(
        &best,
        None,
        Kind::Policy,
        Split::Test,
        a.test_episodes,
        plan,
    )?;
    let recipe_arm = arm.name == ARMS[0].name;
    let mut controls = Controls::default();
    let policy = Policy::load(&best, &candle_core::Device::Cpu)?;
    let rig = evaluate::trained_rig(&policy)?;
    if recipe_arm && !a.no_controls {
        if let Some((_, untrained)) = ckpts.iter().find(|c| c.0 == 0) {
            let r = evaluate::checkpoint(
                untrained,
                None,
                Kind::Policy,
                Split::Test,
                a.test_episodes,
                plan,
            )?;
            controls.untrained = Some(EvalFigures::of(&r));
        }
        let r = evaluate::checkpoint(
            &best,
            None,
            Kind::Frozen,
            Split::Test,
            a.test_episodes,
            plan,
        )?;
        controls.frozen_cameras = Some(EvalFigures::of(&r));
        let r = evaluate::expert(
            run.parent().unwrap_or(run),
            &rig,
            Split::Test,
            a.test_episodes,
            plan,
        )?;
        controls.scripted_expert = Some(EvalFigures::of(&r));
    }
    let live = if recipe_arm && st.live_episodes > 0 {
        let r = evaluate::checkpoint(
            &best,
            Some(&rig),
            Kind::Live,
            Split::Test,
            st.live_episodes,
            plan,
        )?;
        Some(EvalFigures::of(&r))
    } else {
        None
    };
    let counts = ScaleDp::count(&policy.config().model)?;
    let times = train::step_times(run)?;
    let figures = EvalFigures::of(&test);
    Ok(ArmResult {
        arm: arm.name.into(),
        what: arm.what.into(),
        command: command(a, st, dataset, arm.name),
        train_command: train_command(dataset, &st.preset, arm, opts, run),
        train_options: serde_json::to_value(opts)?,
        dataset: dataset.to_string(),
        steps: trained.steps,
        train_hours: trained.hours,
        step_s: times.iter().sum::<f64>() / times.len().max(1) as f64,
        denoiser_params: counts.denoiser,
        encoder_params: counts.encoders,
        validation,
        selected_step: selected,
        test_success_rate: figures.success_rate,
        test_seeds: (0..a.test_episodes).map(|i| test.seed + i).collect(),
        wilson_low: figures.wilson_low,
        wilson_high: figures.wilson_high,
        test: figures,
        live,
        controls,
        audit: audit::Audit {
            schema: audit::SCHEMA,
            trained_by: None,
            scored_by: audit::Binary::this(),
            simulator: audit::simulator(&test),
            collection: None,
            train_seed: Some(opts.get_seed()),
        },
    })
}

/// The `scaledp train` command equivalent to an arm's run.
fn train_command(
    dataset: &str,
    preset: &str,
    arm: Arm,
    opts: &TrainOptions,
    run: &std::path::Path,
) -> String {
    let model = match arm.arch {
        scaledp_policy::Architecture::DpT => "dp-t".to_string(),
        scaledp_policy::Architecture::ScaleDp => arm.size.to_string(),
    };
    let layers = arm
        .layers
        .map_or(String::new(), |l| format!(" --layers {l}"));
    let seed = match opts.get_seed() {
        0 => String::new(),
        s => format!(" --seed {s}"),
    };
    let pos = match arm.pos_embed {
        scaledp_policy::PosEmbed::Learned => String::new(),
        p => format!(" --pos-embed {p}"),
    };
    format!(
        "scaledp train {dataset} --preset {preset} --model {model}{layers} --attention {}{pos} --steps {} --checkpoint-every {} --batch-size {}{seed} --out {}",
        arm.attention,
        opts.get_steps(),
        opts.get_checkpoint_every(),
        opts.get_batch_size(),
        run.display()
    )
}

/// Rebuilds `table.md` and `success_vs_step.svg` in `dir` from the arm results there.
fn rebuild(dir: &std::path::Path) -> Result<Vec<ArmResult>> {
    let arms = results::read_all(dir)?;
    if arms.is_empty() {
        bail!(
            "{}: no arm results (run `scaledp experiment compare` first)",
            dir.display()
        );
    }
    let mut md = String::from(
        "# Results\n\nRebuilt by `scaledp experiment report` from the arm files beside it.\n\n",
    );
    md.push_str(&results::table(&arms));
    md.push_str("\n| arm | scored by | machine | finished | command |\n|---|---|---|---|---|\n");
    for a in &arms {
        let b = &a.audit.scored_by;
        md.push_str(&format!(
            "| {} | `{}` | {} | {} | `{}` |\n",
            a.arm, b.revision, b.machine, b.utc, a.command
        ));
    }
    std::fs::write(dir.join("table.md"), md)
        .with_context(|| format!("writing {}/table.md", dir.display()))?;
    plot::success_vs_step(&arms, &dir.join("success_vs_step.svg"))?;
    eprintln!(
        "rebuilt {}/table.md and success_vs_step.svg from {} arms",
        dir.display(),
        arms.len()
    );
    Ok(arms)
}
