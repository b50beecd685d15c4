//! Where a training step's time goes, on a synthetic batch (no loader):
//!
//! ```sh
//! cargo run --release -p scaledp-policy --example profile_step -- [WxH] [cams] [batch] [steps] [micro]
//! ```
use scaledp_policy::bench::synthetic_step_profile;
use scaledp_policy::{ModelConfig, ModelSize};

fn main() -> scaledp_policy::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let (w, h) = args
        .get(1)
        .and_then(|s| {
            let (w, h) = s.split_once('x')?;
            Some((w.parse().ok()?, h.parse().ok()?))
        })
        .unwrap_or((84, 84));
    let cams: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(2);
    let batch: usize = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(64);
    let steps: usize = args.get(4).and_then(|s| s.parse().ok()).unwrap_or(3);
    let micro: Option<usize> = args.get(5).and_then(|s| s.parse().ok());
    let names = (0..cams)
        .map(|i| format!("observation.images.cam{i}"))
        .collect();
    let cfg = ModelConfig::new(ModelSize::Ti, names, (w, h), 7, 7);
    let p = synthetic_step_profile(&cfg, batch, micro, 1, steps, 0)?;
    println!("{}", serde_json::to_string(&p).unwrap_or_default());
    println!(
        "{w}x{h} cams {cams} batch {batch}: {:.3} s/step wall, {:.3} s CPU ({:.2} cores); encode {:.3}, denoise {:.3}, backward {:.3}, optimizer {:.3}",
        p.step_s,
        p.cpu_s.unwrap_or(f64::NAN),
        p.cpu_s.unwrap_or(f64::NAN) / p.step_s,
        p.phases.encode_s,
        p.phases.denoise_s,
        p.phases.backward_s,
        p.optimizer_s
    );
    Ok(())
}
