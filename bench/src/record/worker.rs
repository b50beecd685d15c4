//! The recorder under test, as a child process (`scaledp bench record --worker`), so its
//! memory and CPU time are its own: the recorder library recording the soak's rig
//! (`<out>/rig.toml`) into `<out>/episodes`, connected to the benchmark's endpoint, driven by
//! lines on stdin (`start`, `stop`, `quit`). It reports on stdout, one JSON object a line: its
//! figures every 250 ms (`{"status": …}`: per topic received, bytes, dropped; queued bytes;
//! Zenoh links) and every episode event (`{"event": "started" | "finished" | "failed" |
//! "other", …}`), `ready` once subscribed and `closed` at the end.

use std::io::{BufRead, Write};
use std::sync::mpsc;
use std::time::Duration;

use anyhow::{Context, Result};
use scaledp_recorder::{net, Command, Event, FreeSpace, Label, Recorder, RecorderOptions};
use scaledp_schema::Rig;
use serde_json::json;

use crate::{BenchRecordArgs, Outcome};

/// The task stored in the soak's episodes.
pub const TASK: &str = "scaledp bench record soak";

fn emit(v: &serde_json::Value) {
    let mut out = std::io::stdout().lock();
    let _ = writeln!(out, "{v}");
    let _ = out.flush();
}

fn event_json(e: &Event) -> serde_json::Value {
    match e {
        Event::Started { index, path } => {
            json!({"event": "started", "index": index, "path": path.display().to_string()})
        }
        Event::Finished(r) => json!({
            "event": "finished",
            "index": r.index,
            "path": r.summary.path.display().to_string(),
            "duration_s": r.duration_s,
            "messages": r.summary.messages,
            "bytes": r.summary.bytes,
            "dropped": r.dropped,
            "cut": r.cut,
        }),
        Event::Failed { index, error } => {
            json!({"event": "failed", "index": index, "error": error})
        }
        Event::Refused { reason, .. } => json!({"event": "refused", "reason": reason}),
        other => json!({"event": "other", "what": format!("{other:?}")}),
    }
}

fn status_json(r: &Recorder) -> serde_json::Value {
    let s = r.status();
    let topics: serde_json::Map<String, serde_json::Value> = s
        .topics
        .iter()
        .map(|t| (t.topic.clone(), json!([t.received, t.bytes, t.dropped])))
        .collect();
    json!({"status": {
        "topics": topics,
        "queued_bytes": s.queued_bytes,
        "links": r.zenoh_links(),
        "recording": s.episode.is_some(),
    }})
}

/// Runs the worker until `quit` on stdin (or stdin closes).
pub fn run(args: &BenchRecordArgs) -> Result<Outcome> {
    let out = args.out.clone().context("--worker needs --out")?;
    let endpoint = args.endpoint.clone().context("--worker needs --endpoint")?;
    let rig = Rig::load(&out.join("rig.toml"))?;
    let config = net::zenoh_config(None, &[endpoint], &[])?;
    let compression = args
        .compression
        .flag()
        .parse()
        .map_err(anyhow::Error::msg)?;
    // The recorder's own disk guard plans for the soak's episodes and keeps its floor: it sees
    // the disk's free space less --min-free-gb.
    let floor = (args.min_free_gb * 1e9) as u64;
    let system = FreeSpace::system();
    let free = FreeSpace::new(move |dir| system.query(dir).map(|f| f.saturating_sub(floor)));
    let recorder = RecorderOptions::new(rig, out.join("episodes"))
        .task(TASK)
        .operator("scaledp bench record")
        .compression(compression)
        .episode_time(Some(args.episode_seconds))
        .free_space(free)
        .start(config)?;
    let (tx, commands) = mpsc::channel::<String>();
    std::thread::Builder::new()
        .name("worker:stdin".into())
        .spawn(move || {
            for line in std::io::stdin().lock().lines() {
                let Ok(line) = line else { break };
                if tx.send(line.trim().to_string()).is_err() {
                    break;
                }
            }
            let _ = tx.send("quit".into());
        })?;
    emit(&json!({"event": "ready"}));
    loop {
        for e in recorder.events().try_iter() {
            emit(&event_json(&e));
        }
        emit(&status_json(&recorder));
        match commands.recv_timeout(Duration::from_millis(250)) {
            Ok(c) if c == "start" => recorder.send(Command::Start),
            Ok(c) if c == "stop" => recorder.send(Command::Stop(Label::Unlabeled)),
            Ok(c) if c == "quit" => break,
            Ok(other) => {
                emit(&json!({"event": "other", "what": format!("unknown command '{other}'")}))
            }
            Err(mpsc::RecvTimeoutError::Timeout) => {}
            Err(mpsc::RecvTimeoutError::Disconnected) => break,
        }
    }
    for e in recorder.events().try_iter() {
        emit(&event_json(&e));
    }
    recorder.finish()?;
    emit(&json!({"event": "closed"}));
    Ok(Outcome::Completed)
}
