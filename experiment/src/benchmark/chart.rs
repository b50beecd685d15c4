//! A benchmark's plot: per level (or per task, when every task has one level, as ALOHA's),
//! each arm's mean test success with the 95 % Wilson interval of its pooled episodes, and the
//! level means the table quotes.

use std::path::Path;

use anyhow::{anyhow, Result};
use plotters::prelude::*;

use super::cells::{level_of, Level};
use super::files::TaskResult;
use super::replicates::replicates;

pub(super) type Means = Vec<(Level, (usize, Vec<f64>))>;

/// Per level: the tasks where every arm has a result, and each arm's mean over them (a task's
/// training seeds averaged first).
pub(super) fn level_means(
    tasks: &[(Level, String)],
    arms: &[&str],
    results: &[TaskResult],
) -> Means {
    level_figures(tasks, arms, results, true)
        .into_iter()
        .map(|(l, n, v)| (l, (n, v.into_iter().flatten().map(|f| f.mean).collect())))
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

/// [`level_means`] with each arm's pooled episodes. With `every_arm`, a level holds only the
/// tasks where every arm has a result (so its means compare like with like); without it, every
/// task where any arm has one, and an arm without a result on it has no figure (`None`).
fn level_figures(
    tasks: &[(Level, String)],
    arms: &[&str],
    results: &[TaskResult],
    every_arm: bool,
) -> Vec<(Level, usize, Vec<Option<LevelFigure>>)> {
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
                let has = |a: &&str| !replicates(results, t, a).is_empty();
                l == level
                    && if every_arm {
                        arms.iter().all(has)
                    } else {
                        arms.iter().any(has)
                    }
            })
            .map(|(_, t)| t)
            .collect();
        if full.is_empty() {
            continue;
        }
        let figures = arms
            .iter()
            .map(|a| {
                let mine: Vec<&&String> = full
                    .iter()
                    .filter(|t| !replicates(results, t, a).is_empty())
                    .collect();
                if mine.is_empty() {
                    return None;
                }
                let pooled = mine.iter().flat_map(|t| replicates(results, t, a));
                let (successes, episodes) = pooled.fold((0, 0), |(k, n), r| {
                    (k + r.test.successes, n + r.test.episodes)
                });
                Some(LevelFigure {
                    mean: mine.iter().map(|t| replicate_mean(t, a)).sum::<f64>()
                        / mine.len() as f64,
                    successes,
                    episodes,
                })
            })
            .collect();
        out.push((level.clone(), full.len(), figures));
    }
    out
}

/// `MetaWorld`, `ALOHA` (else the name as it is).
pub(super) fn display_name(benchmark: &str) -> &str {
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
/// group's name under it. Per level only the tasks every arm has count (as in the table's
/// means); per task every task is drawn, with a bar for each arm that has a result on it.
pub(super) fn plot(
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
        level_figures(&per_task, arms, results, false)
    } else {
        level_figures(tasks, arms, results, true)
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
            .filter_map(|(g, (_, _, v))| {
                let x0 = g as f64 + 0.1 + k as f64 * width;
                let f = v[k]?;
                Some(Rectangle::new(
                    [(x0, 0.0), (x0 + width * 0.9, f.mean)],
                    c.filled(),
                ))
            })
            .collect();
        chart
            .draw_series(bars)
            .map_err(|e| err(e.to_string()))?
            .label(arm.to_string())
            .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 12, y + 5)], c.filled()));
        let whiskers = groups.iter().enumerate().filter_map(|(g, (_, _, v))| {
            let x = g as f64 + 0.1 + k as f64 * width + width * 0.45;
            let f = v[k]?;
            let (lo, hi) = scaledp_deploy::wilson_interval(f.successes, f.episodes);
            Some(PathElement::new(
                vec![(x, lo), (x, hi)],
                BLACK.stroke_width(2),
            ))
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
