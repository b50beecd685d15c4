//! Where a training step's time goes, on a synthetic batch (no loader):
//!
//! ```sh
//! cargo run --release -p scaledp-policy --example profile_step -- [WxH] [cams] [batch] [steps] [micro] [noise_samples] [resnet_width] [engine|autograd] [ti|dp-t]
//! ```
use scaledp_policy::bench::synthetic_step_profile;
use scaledp_policy::{LossSpec, ModelConfig, ModelSize};

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
    let micro: Option<usize> = args.get(5).and_then(|s| s.parse().ok()).filter(|&m| m > 0);
    let k: usize = args.get(6).and_then(|s| s.parse().ok()).unwrap_or(1);
    let width: usize = args.get(7).and_then(|s| s.parse().ok()).unwrap_or(64);
    let autograd = args.get(8).is_some_and(|s| s == "autograd");
    let names = (0..cams)
        .map(|i| format!("observation.images.cam{i}"))
        .collect();
    let mut cfg = if args.get(9).is_some_and(|s| s == "dp-t") {
        ModelConfig::dp_t(names, (w, h), 7, 7)
    } else {
        ModelConfig::new(ModelSize::Ti, names, (w, h), 7, 7)
    };
    cfg.resnet_width = width;
    let spec = LossSpec {
        noise_samples: k,
        mask_padding: false,
    };
    let p = synthetic_step_profile(&cfg, batch, micro, spec, 1, steps, 0, autograd)?;
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
