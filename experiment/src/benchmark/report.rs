//! A benchmark's table (`table.md`: per task and arm the test success with its interval, the
//! controls, and per level the mean over its tasks) and plot (`success_by_level.svg`: per
//! level, or per task when the benchmark has one level, as ALOHA), rebuilt from the (task, arm)
//! files in the results directory.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{anyhow, bail, Context, Result};
use plotters::prelude::*;
use scaledp_schema::benchmarks::Difficulty;

use super::replicates::{cell, pairings, replicates};
use super::{TaskControls, TaskResult};
use crate::arms::ARMS;
use crate::results::EvalFigures;
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

/// A task's level: MetaWorld's difficulty levels in their order, any other label (ALOHA's
/// `bimanual`) after them.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
pub(super) struct Level {
    rank: usize,
    label: String,
}

fn level_of(label: &str) -> Level {
    let rank = Difficulty::ALL
        .iter()
        .position(|d| d.label() == label)
        .unwrap_or(Difficulty::ALL.len());
    Level {
        rank,
        label: label.to_string(),
    }
}

/// The arms present, in the arms' order.
fn arms_of(results: &[TaskResult]) -> Vec<&'static str> {
    ARMS.iter()
        .map(|a| a.name)
        .filter(|n| results.iter().any(|r| r.arm == *n))
        .collect()
}

pub(super) fn pct(f: &EvalFigures) -> String {
    format!(
        "{:.0} % ({}/{}, {:.0}–{:.0})",
        100.0 * f.success_rate,
        f.successes,
        f.episodes,
        100.0 * f.wilson_low,
        100.0 * f.wilson_high
    )
}

/// The bridge behaviour that scored `f` (1 when it was scored before bridges reported one).
fn behaviour(f: &EvalFigures) -> u32 {
    f.bridge
        .as_deref()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1)
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

/// `pct`, marked ` †` when an older bridge than `newest` scored it.
pub(super) fn marked(f: &EvalFigures, newest: u32) -> String {
    let mark = if behaviour(f) < newest { " †" } else { "" };
    format!("{}{mark}", pct(f))
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

type Means = Vec<(Level, (usize, Vec<f64>))>;

/// Per level: the tasks where every arm has a result, and each arm's mean over them (a task's
/// training seeds averaged first).
fn level_means(tasks: &[(Level, String)], arms: &[&str], results: &[TaskResult]) -> Means {
    level_figures(tasks, arms, results)
        .into_iter()
        .map(|(l, n, v)| (l, (n, v.into_iter().map(|f| f.mean).collect())))
        .collect()
}

/// One arm's figure on a level: the mean of its tasks' rates, and the episodes pooled over
/// its tasks and training seeds (for the interval).
#[derive(Debug, Clone, Copy)]
struct LevelFigure {
    mean: f64,
    successes: u64,
    episodes: u64,
}

/// [`level_means`] with each arm's pooled episodes.
fn level_figures(
    tasks: &[(Level, String)],
    arms: &[&str],
    results: &[TaskResult],
) -> Vec<(Level, usize, Vec<LevelFigure>)> {
    let replicate_mean = |t: &str, a: &str| {
        let rs = replicates(results, t, a);
        rs.iter().map(|r| r.test_success_rate).sum::<f64>() / rs.len().max(1) as f64
    };
    let mut levels: Vec<&Level> = tasks.iter().map(|(l, _)| l).collect();
    levels.dedup();
    let mut out = Vec::new();
    for level in levels {
        let full: Vec<&String> = tasks
            .iter()
            .filter(|(l, t)| {
                l == level && arms.iter().all(|a| !replicates(results, t, a).is_empty())
            })
            .map(|(_, t)| t)
            .collect();
        if full.is_empty() {
            continue;
        }
        let figures = arms
            .iter()
            .map(|a| {
                let pooled = full.iter().flat_map(|t| replicates(results, t, a));
                let (successes, episodes) = pooled.fold((0, 0), |(k, n), r| {
                    (k + r.test.successes, n + r.test.episodes)
                });
                LevelFigure {
                    mean: full.iter().map(|t| replicate_mean(t, a)).sum::<f64>()
                        / full.len() as f64,
                    successes,
                    episodes,
                }
            })
            .collect();
        out.push((level.clone(), full.len(), figures));
    }
    out
}

/// `MetaWorld`, `ALOHA` (else the name as it is).
fn display_name(benchmark: &str) -> &str {
    match benchmark {
        "metaworld" => "MetaWorld",
        "aloha" => "ALOHA",
        other => other,
    }
}

const COLOURS: [RGBColor; 7] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(148, 103, 189),
    RGBColor(255, 127, 14),
    RGBColor(140, 86, 75),
    RGBColor(23, 190, 207),
];

/// Grouped bars: per level (or per task, when every task has the same level), each arm's mean
/// test success, with the 95 % Wilson interval of its pooled episodes as a whisker, and each
/// group's name under it.
fn plot(
    benchmark: &str,
    tasks: &[(Level, String)],
    arms: &[&str],
    results: &[TaskResult],
    path: &Path,
) -> Result<()> {
    let by_task = tasks.iter().all(|(l, _)| *l == tasks[0].0);
    let groups = if by_task {
        let per_task: Vec<(Level, String)> = tasks
            .iter()
            .map(|(_, t)| (level_of(t), t.clone()))
            .collect();
        level_figures(&per_task, arms, results)
    } else {
        level_figures(tasks, arms, results)
    };
    let err = |e: String| anyhow!("plot: {e}");
    let root = SVGBackend::new(path, (800, 480)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(e.to_string()))?;
    let n = groups.len().max(1) as f64;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            format!(
                "{}: test success by {}",
                display_name(benchmark),
                if by_task { "task" } else { "difficulty level" }
            ),
            ("sans-serif", 20),
        )
        .margin(16)
        .x_label_area_size(48)
        .y_label_area_size(56)
        .build_cartesian_2d(0f64..n, 0f64..1.0)
        .map_err(|e| err(e.to_string()))?;
    chart
        .configure_mesh()
        .disable_x_mesh()
        .x_labels(0)
        .y_desc("mean test success (whisker: 95 % Wilson, pooled)")
        .draw()
        .map_err(|e| err(e.to_string()))?;
    let width = 0.8 / arms.len().max(1) as f64;
    for (k, arm) in arms.iter().enumerate() {
        let c = COLOURS[k % COLOURS.len()];
        let bars: Vec<Rectangle<(f64, f64)>> = groups
            .iter()
            .enumerate()
            .map(|(g, (_, _, v))| {
                let x0 = g as f64 + 0.1 + k as f64 * width;
                Rectangle::new([(x0, 0.0), (x0 + width * 0.9, v[k].mean)], c.filled())
            })
            .collect();
        chart
            .draw_series(bars)
            .map_err(|e| err(e.to_string()))?
            .label(arm.to_string())
            .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 12, y + 5)], c.filled()));
        let whiskers = groups.iter().enumerate().map(|(g, (_, _, v))| {
            let x = g as f64 + 0.1 + k as f64 * width + width * 0.45;
            let (lo, hi) = scaledp_deploy::wilson_interval(v[k].successes, v[k].episodes);
            PathElement::new(vec![(x, lo), (x, hi)], BLACK.stroke_width(2))
        });
        chart
            .draw_series(whiskers)
            .map_err(|e| err(e.to_string()))?;
    }
    // Each group's name under its bars, in pixels below the axis (plotters' tick labels sit
    // on its own tick positions, which need not be the groups' centres).
    let font =
        ("sans-serif", 15)
            .into_font()
            .color(&BLACK)
            .pos(plotters::style::text_anchor::Pos::new(
                plotters::style::text_anchor::HPos::Center,
                plotters::style::text_anchor::VPos::Top,
            ));
    for (g, (l, n, _)) in groups.iter().enumerate() {
        let text = if by_task {
            l.label.clone()
        } else {
            format!("{} ({n} task{})", l.label, if *n == 1 { "" } else { "s" })
        };
        let (x, y) = chart.backend_coord(&(g as f64 + 0.5, 0.0));
        root.draw(&Text::new(text, (x, y + 8), font.clone()))
            .map_err(|e| err(e.to_string()))?;
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .position(SeriesLabelPosition::UpperRight)
        .draw()
        .map_err(|e| err(e.to_string()))?;
    root.present().map_err(|e| err(e.to_string()))?;
    Ok(())
}
