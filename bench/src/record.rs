//! `scaledp bench record`: the reference load — 2 × 1280×720 bgra8 @ 30 Hz, 1 × 640×480 rgb8
//! @ 30 Hz, 2 arms @ 500 Hz (`bench/reference_rig.toml`) — published over loopback into a
//! `scaledp record` child process, so the recorder's CPU time is its own.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Child, Command as Process, Stdio};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{mpsc, Arc};
use std::time::{Duration, Instant};

use anyhow::{anyhow, bail, Context, Result};
use scaledp_recorder::net;
use scaledp_schema::Rig;
use scaledp_sim::SimOptions;
use scaledp_testkit::{cpu_seconds, free_port, loopback_endpoint};
use zenoh::Wait;

use crate::{BenchRecordArgs, Outcome};

const REFERENCE_RIG: &str = include_str!("../reference_rig.toml");
/// The recorder's share of one core the benchmark aims under.
const TARGET_CPU_PCT: f64 = 50.0;

/// The recorder child and the Zenoh session that drives it over its control keys.
struct Recorder {
    child: Child,
    session: zenoh::Session,
    control: String,
    status: mpsc::Receiver<serde_json::Value>,
}

/// What one run measured.
struct Measured {
    published: BTreeMap<String, u64>,
    finished: serde_json::Value,
    window_s: f64,
    cpu_s: Option<f64>,
    exit_code: Option<i32>,
}

pub fn run(args: BenchRecordArgs) -> Result<Outcome> {
    let tmp = tempfile::tempdir()?;
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| tmp.path().join("recording"));
    let rig_path = tmp.path().join("bench_reference.toml");
    std::fs::write(&rig_path, REFERENCE_RIG)?;
    let rig = Rig::load(&rig_path)?;
    let mut recorder = Recorder::spawn(&args, &rig_path, &out)?;
    let started = recorder.start()?;
    tracing::info!(
        "recorder started episode {}; publishing for {} s",
        started["episode"],
        args.seconds
    );
    let measured = publish(&mut recorder, &rig, args.seconds)?;
    report(&args, &measured, &out)
}

impl Recorder {
    /// `scaledp record` as a child process, connected to a session listening on a free
    /// loopback port, with its control and status keys under a prefix of its own.
    fn spawn(args: &BenchRecordArgs, rig: &Path, out: &Path) -> Result<Recorder> {
        let endpoint = loopback_endpoint(free_port()?);
        let prefix = format!("scaledp/bench/{}", std::process::id());
        let session = net::open(net::zenoh_config(
            None,
            &[],
            std::slice::from_ref(&endpoint),
        )?)?;
        let (tx, status) = mpsc::channel();
        session
            .declare_subscriber(format!("{prefix}/status"))
            .callback(move |s| {
                if let Ok(v) = serde_json::from_slice(&s.payload().to_bytes()) {
                    let _ = tx.send(v);
                }
            })
            .background()
            .wait()
            .map_err(|e| anyhow!("{e}"))?;
        let exe = std::env::current_exe().context("locating the scaledp executable")?;
        let child = Process::new(exe)
            .args(["record", "--task", "bench", "--episodes", "1"])
            .args(["--no-keyboard", "-q"])
            .args(["--compression", args.compression.flag()])
            .args(["--control-prefix", &prefix, "--connect", &endpoint])
            .arg("--rig")
            .arg(rig)
            .arg("--out")
            .arg(out)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .spawn()
            .context("starting the recorder")?;
        Ok(Recorder {
            child,
            session,
            control: format!("{prefix}/control"),
            status,
        })
    }

    fn send(&self, command: &str) -> Result<()> {
        self.session
            .put(&self.control, command)
            .wait()
            .map_err(|e| anyhow!("{e}"))
    }

    /// Repeats `start` until the recorder (which connects within a second or so) answers.
    fn start(&mut self) -> Result<serde_json::Value> {
        let deadline = Instant::now() + Duration::from_secs(20);
        loop {
            self.send("start")?;
            if let Ok(v) = self.wait_status("started", Duration::from_millis(300)) {
                return Ok(v);
            }
            if Instant::now() > deadline {
                let _ = self.child.kill();
                bail!("the recorder did not start within 20 s");
            }
        }
    }

    fn wait_status(&self, event: &str, timeout: Duration) -> Result<serde_json::Value> {
        let deadline = Instant::now() + timeout;
        while let Some(left) = deadline.checked_duration_since(Instant::now()) {
            match self.status.recv_timeout(left) {
                Ok(v) if v["event"] == event => return Ok(v),
                Ok(v) if v["event"] == "failed" => bail!("the recorder failed: {}", v["error"]),
                Ok(_) => {}
                Err(_) => break,
            }
        }
        bail!("no '{event}' from the recorder within {timeout:?}")
    }
}

/// Publishes the load for `seconds`, counting what was published, then stops the episode and
/// waits for the recorder to exit.
fn publish(recorder: &mut Recorder, rig: &Rig, seconds: f64) -> Result<Measured> {
    let published: Arc<BTreeMap<String, AtomicU64>> = Arc::new(
        rig.topics()
            .into_iter()
            .map(|t| (t.topic, AtomicU64::new(0)))
            .collect(),
    );
    let counts = published.clone();
    let pid = recorder.child.id();
    let cpu0 = cpu_seconds(pid);
    let t0 = Instant::now();
    let sim = SimOptions::new(rig.clone())
        .frame_cache(30)
        .on_publish(Arc::new(move |topic, _| {
            if let Some(c) = counts.get(topic) {
                c.fetch_add(1, Ordering::Relaxed);
            }
        }))
        .spawn(&recorder.session)?;
    std::thread::sleep(Duration::from_secs_f64(seconds));
    sim.stop();
    let window_s = t0.elapsed().as_secs_f64();
    // Let in-flight messages land and the writer drain before stopping.
    std::thread::sleep(Duration::from_millis(1500));
    let cpu1 = cpu_seconds(pid);
    recorder.send("stop")?;
    let finished = recorder.wait_status("finished", Duration::from_secs(60))?;
    let exit = recorder.child.wait()?;
    Ok(Measured {
        published: published
            .iter()
            .map(|(t, n)| (t.clone(), n.load(Ordering::Relaxed)))
            .collect(),
        finished,
        window_s,
        cpu_s: cpu0.zip(cpu1).map(|(a, b)| b - a),
        exit_code: exit.code(),
    })
}

fn report(args: &BenchRecordArgs, m: &Measured, out: &Path) -> Result<Outcome> {
    let file = PathBuf::from(m.finished["path"].as_str().unwrap_or_default());
    let size = std::fs::metadata(&file).map(|m| m.len()).unwrap_or(0);
    println!(
        "scaledp bench record: {:.1} s of reference load over loopback TCP, {} chunks",
        args.seconds,
        args.compression.flag()
    );
    let lost = print_topics(m);
    println!(
        "file: {} ({:.0} MB on disk)",
        file.display(),
        size as f64 / 1e6
    );
    let cpu_pct = m.cpu_s.map(|s| s / m.window_s * 100.0);
    match (m.cpu_s, cpu_pct) {
        (Some(s), Some(pct)) => println!(
            "recorder CPU: {s:.2} s over {:.1} s of load = {pct:.1} % of one core",
            m.window_s
        ),
        _ => println!("recorder CPU: unavailable (no /proc)"),
    }
    if args.out.is_none() {
        println!(
            "(recording removed; pass --out DIR to keep it in {})",
            out.display()
        );
    }
    let pass = lost == 0 && cpu_pct.is_some_and(|p| p <= TARGET_CPU_PCT) && m.exit_code == Some(0);
    println!(
        "targets: 0 lost ({lost}), recorder ≤ {TARGET_CPU_PCT:.0} % of one core ({}): {}",
        cpu_pct.map_or("n/a".into(), |p| format!("{p:.1} %")),
        if pass { "met" } else { "NOT met" }
    );
    Ok(if lost > 0 {
        Outcome::DataLost
    } else {
        Outcome::Completed
    })
}

/// The per-topic table: published, recorded, dropped, MB/s; returns the messages lost.
fn print_topics(m: &Measured) -> u64 {
    println!(
        "{:<44} {:>10} {:>9} {:>8} {:>9}",
        "topic", "published", "recorded", "dropped", "MB/s"
    );
    let (mut lost, mut total_mb) = (0u64, 0.0);
    for (topic, &n) in &m.published {
        let rec = m.finished["messages"][topic].as_u64().unwrap_or(0);
        let dropped = m.finished["dropped"][topic].as_u64().unwrap_or(0);
        lost += n.saturating_sub(rec) + dropped;
        let mb_s = m.finished["bytes"][topic].as_u64().unwrap_or(0) as f64 / 1e6 / m.window_s;
        total_mb += mb_s;
        println!("{topic:<44} {n:>10} {rec:>9} {dropped:>8} {mb_s:>9.1}");
    }
    println!(
        "{:<44} {:>10} {:>9} {:>8} {total_mb:>9.1}",
        "total", "", "", ""
    );
    lost
}
