//! DDIM-10 latency per action chunk at batch 1 (what `scaledp bench train` prints last), alone,
//! for profiling the sampler:
//!
//! ```sh
//! cargo run --release -p scaledp-policy --example ddim_latency -- [ti|s] [WxH] [runs]
//! ```
use candle_core::Device;
use scaledp_policy::bench::ddim_latency;
use scaledp_policy::{ModelConfig, ModelSize};

fn main() -> scaledp_policy::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let size = match args.get(1).map(String::as_str) {
        Some("s") => ModelSize::S,
        _ => ModelSize::Ti,
    };
    let (w, h) = args
        .get(2)
        .and_then(|s| {
            let (w, h) = s.split_once('x')?;
            Some((w.parse().ok()?, h.parse().ok()?))
        })
        .unwrap_or((64, 64));
    let runs: usize = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(50);
    let cams = vec![
        "observation.images.front".into(),
        "observation.images.wrist".into(),
    ];
    let cfg = ModelConfig::new(size, cams, (w, h), 7, 7);
    let l = ddim_latency(&cfg, 10, runs, &Device::Cpu)?;
    println!(
        "ddim-10 {size} {w}x{h}: p50 {:.1} ms (encoders {:.1} ms), p99 {:.1} ms over {runs} runs",
        l.p50_ms, l.encode_p50_ms, l.p99_ms
    );
    Ok(())
}
