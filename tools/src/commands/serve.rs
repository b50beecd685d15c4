//! `scaledp serve`: a checkpoint driving a rig over Zenoh (see `scaledp_deploy::serve`).

use std::path::PathBuf;
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Result;
use clap::Args;
use scaledp_deploy::{Command, ServeOptions, Server};
use scaledp_policy::Policy;
use scaledp_schema::Rig;

use crate::cli::{ExitStatus, KeysArg, NetArgs};
use crate::shared::{self, rig_for, ControlArgs};

/// `scaledp serve`.
#[derive(Debug, Args)]
pub struct ServeArgs {
    /// A checkpoint directory, or a run directory (its latest checkpoint).
    pub checkpoint: PathBuf,
    /// Rig file or shipped rig name (default: the rig the checkpoint was trained on).
    #[arg(long)]
    pub rig: Option<String>,
    /// Key layout of the rig's topics.
    #[arg(long, value_enum, default_value = "bridge")]
    pub keys: KeysArg,
    /// Bridge namespace prefix for the keys.
    #[arg(long, default_value = "")]
    pub namespace: String,
    /// Publish nothing; print each tick's commands instead.
    #[arg(long)]
    pub dry_run: bool,
    /// Key of the JSON status (inference latency, command rate, why it holds).
    #[arg(long, default_value = "scaledp/serve/status")]
    pub status_key: String,
    /// Stop after this many seconds (default: until Ctrl-C).
    #[arg(long, value_name = "SECONDS")]
    pub duration: Option<f64>,
    /// Seed of the sampling noise.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Follow a simulation's rosgraph_msgs/Clock topic instead of the wall clock (ROS's
    /// use_sim_time): ticks, receive times and command stamps on its time. `scaledp sim --rig
    /// metaworld/<task>` publishes /clock.
    #[arg(long, value_name = "TOPIC")]
    pub clock: Option<String>,
    #[command(flatten)]
    pub control: ControlArgs,
    /// Network settings; by default it connects to tcp/127.0.0.1:7447 (the bridge, or `scaledp sim`).
    #[command(flatten)]
    pub net: NetArgs,
}

fn describe(tick: u64, cmds: &[Command], rig: &Rig) -> String {
    let mut s = format!("tick {tick}:");
    for c in cmds {
        let p = scaledp_schema::kinematics::pose6_from_transform(c.base_from_tcp);
        s.push_str(&format!(
            " {} xyz ({:.3}, {:.3}, {:.3}) rpy ({:.3}, {:.3}, {:.3})",
            rig.arms[c.arm].name, p[0], p[1], p[2], p[3], p[4], p[5]
        ));
        if let Some(w) = c.gripper_width_m {
            s.push_str(&format!(" gripper {w:.3} m"));
        }
        if c.clamped.any() {
            s.push_str(&format!(" [clamped {:?}]", c.clamped));
        }
    }
    s
}

/// Runs `scaledp serve`.
pub fn run(a: ServeArgs) -> Result<ExitStatus> {
    let dev = shared::device(&a.control.device)?;
    let policy = Policy::load(&a.checkpoint, &dev)?;
    let rig = rig_for(&policy, a.rig.as_deref())?;
    let mut opts = ServeOptions::new(rig.clone());
    opts.keys = match a.keys {
        KeysArg::Bridge => scaledp_sim::KeyStyle::Bridge,
        KeysArg::Rmw => scaledp_sim::KeyStyle::Rmw,
    };
    opts.namespace = a.namespace.clone();
    opts.control = a
        .control
        .options(&rig, policy.config().model.action_chunk)?;
    opts.dry_run = a.dry_run;
    opts.status_key = a.status_key.clone();
    opts.seed = a.seed;
    opts.clock = a.clock.clone();
    if a.dry_run {
        let r = rig.clone();
        opts.on_commands = Some(Arc::new(move |tick, cmds| {
            println!("{}", describe(tick, cmds, &r))
        }));
    }
    // The checkpoint is checked against the rig before the session opens.
    let ckpt = policy.dir().display().to_string();
    scaledp_deploy::check::check(policy.config(), &ckpt, &rig)?;
    let session = scaledp_recorder::net::open(shared::zenoh_config(&a.net, &[])?)?;
    let server = Server::start(policy, opts, &session)?;
    eprintln!(
        "serving {ckpt} on rig {} at {} Hz{}",
        rig.name,
        rig.control_rate_hz,
        if a.dry_run {
            " (dry run: nothing is published)"
        } else {
            ""
        }
    );
    let stop = shared::interrupt_flag();
    let started = Instant::now();
    let mut last = Instant::now();
    while !stop.load(Ordering::Relaxed)
        && a.duration
            .is_none_or(|d| started.elapsed().as_secs_f64() < d)
    {
        std::thread::sleep(Duration::from_millis(50));
        if last.elapsed() >= Duration::from_secs(1) {
            last = Instant::now();
            eprintln!("{}", server.status().line());
        }
    }
    let st = server.stop();
    eprintln!("stopped: {}", st.line());
    Ok(ExitStatus::Success)
}
