//! `scaledp sim`: a simulated rig on Zenoh.

use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use anyhow::Result;
use scaledp_schema::Rig;

use crate::cli::{ExitStatus, KeysArg, SimArgs};
use scaledp_sim::{KeyStyle, SimOptions};

pub fn run(args: SimArgs) -> Result<ExitStatus> {
    let rig = Rig::load_or_builtin(&args.rig)?;
    let config = super::zenoh_config(
        &args.net,
        &[scaledp_recorder::net::DEFAULT_ENDPOINT.to_string()],
    )?;
    let session = scaledp_recorder::net::open(config)?;
    let keys = match args.keys {
        KeysArg::Bridge => KeyStyle::Bridge,
        KeysArg::Rmw => KeyStyle::Rmw,
    };
    tracing::info!(rig = %rig.name, seed = args.seed, "simulating {} topics", rig.topics().len());
    let sim = SimOptions::new(rig)
        .seed(args.seed)
        .keys(keys)
        .namespace(args.namespace)
        .spawn(&session)?;
    let stop = super::interrupt_flag();
    let start = Instant::now();
    while !stop.load(Ordering::Relaxed)
        && args
            .duration
            .is_none_or(|d| start.elapsed().as_secs_f64() < d)
    {
        std::thread::sleep(Duration::from_millis(50));
    }
    for (topic, n) in sim.stop() {
        println!("{topic}\t{n} messages published");
    }
    Ok(ExitStatus::Success)
}
