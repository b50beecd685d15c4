//! A recording session as the operator runs it: the recorder's pilot (timed episodes, resets,
//! the verdict of each episode, the count of episodes kept) with the keys of the terminal and a
//! live status line. Keys and Zenoh control words act alike, in every phase.

use std::io::{IsTerminal, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::Result;
use crossterm::event::{self, Event as TermEvent, KeyCode, KeyEvent, KeyEventKind, KeyModifiers};
use scaledp_recorder::{Command, Event, Label, Phase, Pilot, Plan, Recorder};

use super::session::{show, Tally};
use super::viewer;
use crate::ui::StatusLine;

/// The keys, shown when the session starts and after each episode.
pub const KEYS_HELP: &str = "[space] start/stop  [y] success  [n] failure  [d] discard  \
                             [r] re-record  [k] keep  [f] start anyway  [t] task  [q] quit";

/// What drives a session besides the pilot.
pub struct Attended<'a> {
    /// Read keys from the terminal (raw mode while the session runs).
    pub keyboard: bool,
    /// The `--task` list: several are cycled by `t`, one makes `t` ask for a new task.
    pub tasks: &'a [String],
    /// Set by Ctrl-C or SIGTERM.
    pub stop: &'a AtomicBool,
    /// Short labels of the rig's topics, for the status line.
    pub labels: Vec<String>,
}

/// Restores the terminal however the session ends.
struct RawMode;

impl RawMode {
    fn enable() -> Result<Self> {
        crossterm::terminal::enable_raw_mode()?;
        Ok(Self)
    }
}

impl Drop for RawMode {
    fn drop(&mut self) {
        let _ = crossterm::terminal::disable_raw_mode();
        eprintln!();
    }
}

/// What a key asks for.
enum Key {
    Send(Command),
    Task,
    Quit,
}

/// The key's meaning now: space starts, or ends the episode being recorded (held for a label).
fn key(code: KeyCode, modifiers: KeyModifiers, recording: bool) -> Option<Key> {
    Some(Key::Send(match code {
        KeyCode::Char('c') if modifiers.contains(KeyModifiers::CONTROL) => return Some(Key::Quit),
        KeyCode::Char(' ') | KeyCode::Enter if recording => Command::End,
        KeyCode::Char(' ') | KeyCode::Enter => Command::Start,
        KeyCode::Char('y') => Command::Stop(Label::Success),
        KeyCode::Char('n') => Command::Stop(Label::Failure),
        KeyCode::Char('d') => Command::Stop(Label::Discarded),
        KeyCode::Char('r') => Command::Rerecord,
        KeyCode::Char('k') => Command::Keep,
        KeyCode::Char('f') => Command::ForceStart,
        KeyCode::Char('t') => return Some(Key::Task),
        KeyCode::Char('q') | KeyCode::Esc => return Some(Key::Quit),
        _ => return None,
    }))
}

/// A line read in cooked mode: the terminal leaves raw mode while the operator types.
fn read_task(current: &str, eol: &str) -> Option<String> {
    let _ = crossterm::terminal::disable_raw_mode();
    eprint!("\r\x1b[2Knew task (empty keeps \"{current}\"): ");
    let _ = std::io::stderr().flush();
    let mut line = String::new();
    let read = std::io::stdin().read_line(&mut line);
    let _ = crossterm::terminal::enable_raw_mode();
    eprint!("{eol}");
    let task = line.trim();
    (read.is_ok() && !task.is_empty()).then(|| task.to_string())
}

/// The status line cut to the terminal's width (a wrapped line would not be redrawn in place).
fn fit(line: String) -> String {
    // A terminal that does not say its size (a bare pseudo-terminal says 0) gets 200 columns.
    let cols = match crossterm::terminal::size() {
        Ok((c, _)) if c > 0 => usize::from(c),
        _ => 200,
    };
    if line.chars().count() < cols {
        return line;
    }
    line.chars().take(cols.saturating_sub(1)).collect()
}

/// Runs a session along `plan` until its episodes are kept, `q`, `quit` or Ctrl-C.
pub fn run(recorder: &Recorder, plan: Plan, how: Attended<'_>) -> Result<Tally> {
    let confirm = plan.confirm;
    let mut pilot = Pilot::new(plan);
    let mut tally = Tally::default();
    let mut line = StatusLine::new(how.labels);
    let show_line = std::io::stderr().is_terminal();
    let _raw = if how.keyboard {
        eprintln!("{KEYS_HELP}");
        Some(RawMode::enable()?)
    } else {
        None
    };
    let eol = if how.keyboard { "\r\n" } else { "\n" };
    let mut last_draw = Instant::now() - Duration::from_secs(1);
    while !how.stop.load(Ordering::Relaxed) {
        viewer::live::update(recorder, None);
        let events = pilot.poll(recorder);
        if show_line && !events.is_empty() {
            // The events' lines replace the status line, which is drawn again below them.
            eprint!("\r\x1b[2K");
            let _ = std::io::stderr().flush();
        }
        for ev in events {
            if show(recorder, &ev, &mut tally, eol) && how.keyboard {
                eprint!("{KEYS_HELP}{eol}");
            }
            let rejected = match &ev {
                Event::Ended { verdict, .. } => !verdict.accepted,
                Event::Finished(r) => !r.verdict.accepted && r.outcome != Label::Discarded,
                _ => false,
            };
            if rejected && confirm {
                eprint!("convert would reject it: [k] keep it, [r] record it again{eol}");
            }
            if let Event::Refused { force: true, .. } = &ev {
                if how.keyboard {
                    eprint!("[f] starts it anyway{eol}");
                }
            }
        }
        if let Some(why) = pilot.done() {
            tracing::info!("session over: {why}");
            break;
        }
        if show_line && last_draw.elapsed() >= Duration::from_millis(200) {
            let phase = pilot.phase();
            eprint!(
                "\r\x1b[2K{}",
                fit(line.render_phase(recorder.status(), &phase))
            );
            last_draw = Instant::now();
        }
        if !how.keyboard {
            std::thread::sleep(Duration::from_millis(50));
            continue;
        }
        if !event::poll(Duration::from_millis(50))? {
            continue;
        }
        let TermEvent::Key(KeyEvent {
            code,
            modifiers,
            kind: KeyEventKind::Press,
            ..
        }) = event::read()?
        else {
            continue;
        };
        let recording = matches!(pilot.phase(), Phase::Recording { .. });
        match key(code, modifiers, recording) {
            Some(Key::Send(cmd)) => pilot.command(recorder, cmd),
            Some(Key::Quit) => break,
            Some(Key::Task) if how.tasks.len() > 1 => pilot.command(recorder, Command::NextTask),
            Some(Key::Task) if recording => {
                eprint!("\r\x1b[2Kthe task changes between episodes{eol}");
            }
            Some(Key::Task) => {
                if let Some(task) = read_task(&recorder.status().task, eol) {
                    pilot.command(recorder, Command::Task(task));
                }
            }
            None => {}
        }
    }
    if show_line {
        eprint!("\r\x1b[2K");
    }
    recorder.send(Command::Quit);
    let deadline = Instant::now() + Duration::from_secs(60);
    while recorder.is_running() && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(20));
    }
    for ev in pilot.poll(recorder) {
        show(recorder, &ev, &mut tally, eol);
    }
    tally.stopped = pilot.stopped().map(String::from);
    Ok(tally)
}
