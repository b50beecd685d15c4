//! `scaledp bench record`: the reference load — 2 × 1280×720 bgra8 @ 30 Hz, 1 × 640×480 rgb8
//! @ 30 Hz, 2 arms @ 500 Hz — published over loopback into a `scaledp record` child process, so
//! the recorder's CPU time is its own.

use std::collections::BTreeMap;
use std::path::Path;
use std::process::{Command as Process, Stdio};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{mpsc, Arc};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use scaledp_recorder::net;
use scaledp_schema::Rig;
use zenoh::Wait;

use crate::{BenchRecordArgs, Compression as CompressionArg, Outcome};
use scaledp_sim::SimOptions;

const REFERENCE_RIG: &str = r#"
name = "bench_reference"
control_rate_hz = 10.0

[[camera]]
name = "zed_left"
topic = "/zed_left/zed_node/rgb/color/rect/image"
model = "zed"
width = 1280
height = 720
fps = 30.0

[[camera]]
name = "zed_right"
topic = "/zed_right/zed_node/rgb/color/rect/image"
model = "zed"
width = 1280
height = 720
fps = 30.0

[[camera]]
name = "realsense"
topic = "/camera/camera/color/image_raw"
model = "realsense"
width = 640
height = 480
fps = 30.0

[[arm]]
name = "left"
model = "ur5e"
joint_state_topic = "/left/joint_states"
joint_names = ["left_shoulder_pan_joint", "left_shoulder_lift_joint", "left_elbow_joint", "left_wrist_1_joint", "left_wrist_2_joint", "left_wrist_3_joint"]
rate_hz = 500.0

[[arm]]
name = "right"
model = "ur5e"
joint_state_topic = "/right/joint_states"
joint_names = ["right_shoulder_pan_joint", "right_shoulder_lift_joint", "right_elbow_joint", "right_wrist_1_joint", "right_wrist_2_joint", "right_wrist_3_joint"]
rate_hz = 500.0
"#;

/// User + system CPU seconds of a process, from /proc.
fn cpu_seconds(pid: u32) -> Option<f64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    let after = stat.rsplit_once(')')?.1;
    let fields: Vec<&str> = after.split_whitespace().collect();
    let utime: f64 = fields.get(11)?.parse().ok()?;
    let stime: f64 = fields.get(12)?.parse().ok()?;
    // /proc reports in USER_HZ, which Linux fixes at 100 per second for user space.
    Some((utime + stime) / 100.0)
}

fn wait_status(
    rx: &mpsc::Receiver<serde_json::Value>,
    event: &str,
    timeout: Duration,
) -> Result<serde_json::Value> {
    let deadline = Instant::now() + timeout;
    while let Some(left) = deadline.checked_duration_since(Instant::now()) {
        match rx.recv_timeout(left) {
            Ok(v) if v["event"] == event => return Ok(v),
            Ok(v) if v["event"] == "failed" => bail!("the recorder failed: {}", v["error"]),
            Ok(_) => {}
            Err(_) => break,
        }
    }
    bail!("no '{event}' from the recorder within {timeout:?}")
}

pub fn record(args: BenchRecordArgs) -> Result<Outcome> {
    let tmp = tempfile::tempdir()?;
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| tmp.path().join("recording"));
    let rig_path = tmp.path().join("bench_reference.toml");
    std::fs::write(&rig_path, REFERENCE_RIG)?;
    let rig = Rig::load(&rig_path)?;
    let endpoint = format!("tcp/127.0.0.1:{}", scaledp_testkit::free_port()?);
    let prefix = format!("scaledp/bench/{}", std::process::id());
    let session = net::open(net::zenoh_config(
        None,
        &[],
        std::slice::from_ref(&endpoint),
    )?)?;
    let (tx, status) = mpsc::channel();
    let _status_sub = session
        .declare_subscriber(format!("{prefix}/status"))
        .callback(move |s| {
            if let Ok(v) = serde_json::from_slice(&s.payload().to_bytes()) {
                let _ = tx.send(v);
            }
        })
        .wait()
        .map_err(|e| anyhow::anyhow!("{e}"))?;

    let compression = match args.compression {
        CompressionArg::None => "none",
        CompressionArg::Lz4 => "lz4",
        CompressionArg::Zstd => "zstd",
    };
    let exe = std::env::current_exe()?;
    let mut child = Process::new(exe)
        .args([
            "record",
            "--task",
            "bench",
            "--episodes",
            "1",
            "--no-keyboard",
            "-q",
        ])
        .args([
            "--compression",
            compression,
            "--control-prefix",
            &prefix,
            "--connect",
            &endpoint,
        ])
        .arg("--rig")
        .arg(&rig_path)
        .arg("--out")
        .arg(&out)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .spawn()
        .context("starting the recorder")?;
    let pid = child.id();

    // The recorder connects within a second or so; repeat `start` until it answers.
    let control = format!("{prefix}/control");
    let deadline = Instant::now() + Duration::from_secs(20);
    let started = loop {
        session
            .put(&control, "start")
            .wait()
            .map_err(|e| anyhow::anyhow!("{e}"))?;
        if let Ok(v) = wait_status(&status, "started", Duration::from_millis(300)) {
            break v;
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            bail!("the recorder did not start within 20 s");
        }
    };
    tracing::info!(
        "recorder started episode {}; publishing for {} s",
        started["episode"],
        args.seconds
    );

    let published: Arc<BTreeMap<String, AtomicU64>> = Arc::new(
        rig.topics()
            .into_iter()
            .map(|t| (t.topic, AtomicU64::new(0)))
            .collect(),
    );
    let counts = published.clone();
    let cpu0 = cpu_seconds(pid);
    let t0 = Instant::now();
    let sim = SimOptions::new(rig.clone())
        .frame_cache(30)
        .on_publish(Arc::new(move |topic, _| {
            if let Some(c) = counts.get(topic) {
                c.fetch_add(1, Ordering::Relaxed);
            }
        }))
        .spawn(&session)?;
    std::thread::sleep(Duration::from_secs_f64(args.seconds));
    sim.stop();
    let window_s = t0.elapsed().as_secs_f64();
    // Let in-flight messages land and the writer drain before stopping.
    std::thread::sleep(Duration::from_millis(1500));
    let cpu1 = cpu_seconds(pid);
    session
        .put(&control, "stop")
        .wait()
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let finished = wait_status(&status, "finished", Duration::from_secs(60))?;
    let exit = child.wait()?;
    report(
        &args,
        compression,
        &published,
        &finished,
        window_s,
        cpu0.zip(cpu1),
        exit.code(),
        &out,
    )
}

#[allow(clippy::too_many_arguments)]
fn report(
    args: &BenchRecordArgs,
    compression: &str,
    published: &BTreeMap<String, AtomicU64>,
    finished: &serde_json::Value,
    window_s: f64,
    cpu: Option<(f64, f64)>,
    exit_code: Option<i32>,
    out: &Path,
) -> Result<Outcome> {
    let file = finished["path"].as_str().unwrap_or_default();
    let size = std::fs::metadata(file).map(|m| m.len()).unwrap_or(0);
    println!(
        "scaledp bench record: {:.1} s of reference load over loopback TCP, {compression} chunks",
        args.seconds
    );
    println!(
        "{:<44} {:>10} {:>9} {:>8} {:>9}",
        "topic", "published", "recorded", "dropped", "MB/s"
    );
    let (mut lost, mut total_mb) = (0u64, 0.0);
    for (topic, n) in published {
        let n = n.load(Ordering::Relaxed);
        let rec = finished["messages"][topic].as_u64().unwrap_or(0);
        let dropped = finished["dropped"][topic].as_u64().unwrap_or(0);
        lost += n.saturating_sub(rec) + dropped;
        let bytes = finished["bytes"][topic].as_u64().unwrap_or(0) as f64;
        total_mb += bytes / 1e6 / window_s;
        println!(
            "{topic:<44} {n:>10} {rec:>9} {dropped:>8} {:>9.1}",
            bytes / 1e6 / window_s
        );
    }
    println!(
        "{:<44} {:>10} {:>9} {:>8} {total_mb:>9.1}",
        "total", "", "", ""
    );
    println!("file: {file} ({:.0} MB on disk)", size as f64 / 1e6);
    let cpu_pct = match cpu {
        Some((a, b)) => {
            let pct = (b - a) / window_s * 100.0;
            println!(
                "recorder CPU: {:.2} s over {window_s:.1} s of load = {pct:.1} % of one core",
                b - a
            );
            Some(pct)
        }
        None => {
            println!("recorder CPU: unavailable (no /proc)");
            None
        }
    };
    if args.out.is_none() {
        println!(
            "(recording removed; pass --out DIR to keep it in {})",
            out.display()
        );
    }
    let pass = lost == 0 && cpu_pct.is_some_and(|p| p <= 50.0) && exit_code == Some(0);
    println!(
        "targets: 0 lost ({lost}), recorder ≤ 50 % of one core ({}): {}",
        cpu_pct.map_or("n/a".into(), |p| format!("{p:.1} %")),
        if pass { "met" } else { "NOT met" }
    );
    Ok(if lost > 0 {
        Outcome::DataLost
    } else {
        Outcome::Completed
    })
}
