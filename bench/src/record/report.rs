//! The soak's printout (per-topic table, then the run's figures against the criteria) and its
//! JSON report.

use std::path::Path;

use anyhow::{Context, Result};

use super::figures::{Soak, RSS_GROWTH_LIMIT};

fn mb(bytes: u64) -> f64 {
    bytes as f64 / 1e6
}

/// Prints the soak and writes `report` (JSON).
pub fn report(soak: &Soak, report: &Path) -> Result<()> {
    let load_s = soak.load_s();
    let per_s = |n: u64| n as f64 / load_s.max(1e-9);
    println!(
        "scaledp bench record: {} episodes, {:.0} s of load ({:.0} s wall), offered {:.0} MB/s",
        soak.episodes.len(),
        load_s,
        soak.wall_s,
        soak.offered_mb_s
    );
    println!(
        "{:<58} {:>8} {:>8} {:>8} {:>8} {:>7} {:>7} {:>8}",
        "topic", "offer Hz", "sent Hz", "rec Hz", "sent", "lost", "q-drop", "rec MB/s"
    );
    let totals = soak.topic_totals();
    let (mut sent_b, mut rec_b) = (0u64, 0u64);
    for (topic, c) in &totals {
        let hz = soak.offered.get(topic).map_or(0.0, |o| o.0);
        println!(
            "{topic:<58} {hz:>8.1} {:>8.1} {:>8.1} {:>8} {:>7} {:>7} {:>8.1}",
            per_s(c.sent),
            per_s(c.recorded),
            c.sent,
            c.lost(),
            c.dropped,
            mb(c.recorded_bytes) / load_s.max(1e-9)
        );
        sent_b += c.sent_bytes;
        rec_b += c.recorded_bytes;
    }
    println!(
        "payload MB/s: offered {:.1}, sent {:.1}, recorded {:.1} ({:.0} % of offered)",
        soak.offered_mb_s,
        mb(sent_b) / load_s.max(1e-9),
        mb(rec_b) / load_s.max(1e-9),
        100.0 * mb(rec_b) / load_s.max(1e-9) / soak.offered_mb_s.max(1e-9)
    );
    let written: u64 = soak.episodes.iter().map(|e| e.file_bytes).sum();
    println!(
        "written: {:.0} MB in episode files, {:.1} MB/s over the episodes' wall time; files {}",
        mb(written),
        soak.written_mb_s(),
        if soak.episodes.iter().all(|e| e.deleted) {
            "deleted once checked"
        } else {
            "kept"
        }
    );
    let bad = soak.bad_files();
    println!(
        "files checked: {} of {} as recorded{}",
        soak.episodes.len() - bad,
        soak.episodes.len(),
        soak.episodes
            .iter()
            .find(|e| e.check != "ok")
            .map_or(String::new(), |e| format!(
                " (episode {}: {})",
                e.index, e.check
            ))
    );
    let undrained = soak.episodes.iter().filter(|e| !e.drained).count();
    if undrained > 0 {
        println!("{undrained} episodes stopped before the recorder had received all that was sent");
    }
    for e in soak.episodes.iter().filter(|e| e.cut.is_some()) {
        println!(
            "episode {} ended early: {}",
            e.index,
            e.cut.as_deref().unwrap_or_default()
        );
    }
    match (soak.rss_after_first, soak.rss_max_after_first, soak.rss_growth()) {
        (Some(base), Some(max), Some(g)) => println!(
            "recorder RSS under load: {:.0} MB at most in episode 1, {:.0} MB at most in the later ones ({:+.1} %: {}); between episodes {} MB",
            mb(base),
            mb(max),
            g * 100.0,
            if g <= RSS_GROWTH_LIMIT { "within 5 %" } else { "NOT within 5 %" },
            soak.episodes
                .iter()
                .filter_map(|e| e.rss_end)
                .map(|b| format!("{:.0}", mb(b)))
                .collect::<Vec<_>>()
                .join(", ")
        ),
        _ => println!(
            "recorder RSS: peak {:.0} MB (growth needs two episodes)",
            mb(soak.rss_peak.unwrap_or(0))
        ),
    }
    match soak.cpu_share() {
        Some(share) => println!(
            "recorder CPU: {:.0} s over {:.0} s = {:.0} % of one core ({:.0} % of the machine's {} cores); load average {} → {}",
            soak.cpu_s.unwrap_or(0.0),
            soak.wall_s,
            share * 100.0,
            share * 100.0 / soak.cores.max(1) as f64,
            soak.cores,
            soak.load_average.0.map_or("n/a".into(), |l| format!("{l:.2}")),
            soak.load_average.1.map_or("n/a".into(), |l| format!("{l:.2}")),
        ),
        None => println!("recorder CPU: unavailable (no /proc)"),
    }
    if let Some(p) = soak.publisher_cpu_s {
        println!(
            "publisher CPU (this process, the load's own cost): {p:.0} s = {:.0} % of one core",
            p / soak.wall_s.max(1e-9) * 100.0
        );
    }
    if let Some(why) = &soak.stopped_early {
        println!("stopped early: {why}");
    }
    let lost = soak.lost();
    let rss_ok = soak.rss_growth().is_none_or(|g| g <= RSS_GROWTH_LIMIT);
    let whole = soak.stopped_early.is_none() && !soak.episodes.is_empty();
    println!(
        "criteria: every episode run: {}; messages lost: {lost} (none wanted); files as recorded: {} of {}; RSS within 5 % of episode 1's: {} → {}",
        if whole { "yes" } else { "no" },
        soak.episodes.len() - bad,
        soak.episodes.len(),
        soak.rss_growth().map_or("n/a".into(), |g| format!("{:+.1} %", g * 100.0)),
        if whole && lost == 0 && bad == 0 && rss_ok { "met" } else { "NOT met" }
    );
    let json = serde_json::to_vec_pretty(soak)?;
    std::fs::write(report, json).with_context(|| format!("writing {}", report.display()))?;
    println!("report: {}", report.display());
    Ok(())
}
