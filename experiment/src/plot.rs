//! The success-vs-step plot of an experiment: every arm's validation success rate at each of
//! its checkpoints, as SVG.

use std::path::Path;

use anyhow::{anyhow, Result};
use plotters::prelude::*;

use crate::results::ArmResult;

const COLOURS: [RGBColor; 3] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
];

/// Writes the plot of `arms` to `path`.
pub fn success_vs_step(arms: &[ArmResult], path: &Path) -> Result<()> {
    let max_step = arms
        .iter()
        .flat_map(|a| a.validation.iter().map(|v| v.step))
        .max()
        .unwrap_or(1)
        .max(1);
    let root = SVGBackend::new(path, (800, 460)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| anyhow!("plot: {e}"))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "closed-loop success on the validation seeds",
            ("sans-serif", 20),
        )
        .margin(16)
        .x_label_area_size(40)
        .y_label_area_size(56)
        .build_cartesian_2d(0u64..max_step, 0f64..1.0)
        .map_err(|e| anyhow!("plot: {e}"))?;
    chart
        .configure_mesh()
        .x_desc("optimizer step")
        .y_desc("success rate")
        .draw()
        .map_err(|e| anyhow!("plot: {e}"))?;
    for (i, a) in arms.iter().enumerate() {
        let c = COLOURS[i % COLOURS.len()];
        let pts: Vec<(u64, f64)> = a
            .validation
            .iter()
            .map(|v| (v.step, v.success_rate))
            .collect();
        chart
            .draw_series(LineSeries::new(pts.clone(), c.stroke_width(2)))
            .map_err(|e| anyhow!("plot: {e}"))?
            .label(format!(
                "{} (test {:.0} %)",
                a.arm,
                100.0 * a.test_success_rate
            ))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], c.stroke_width(2)));
        chart
            .draw_series(pts.iter().map(|&p| Circle::new(p, 3, c.filled())))
            .map_err(|e| anyhow!("plot: {e}"))?;
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .position(SeriesLabelPosition::LowerRight)
        .draw()
        .map_err(|e| anyhow!("plot: {e}"))?;
    root.present().map_err(|e| anyhow!("plot: {e}"))?;
    Ok(())
}
