//! Episode control vocabulary: what an operator, a foot pedal or a timer can ask for.

use std::str::FromStr;

pub use scaledp_schema::Label;

/// A request to the recorder.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Command {
    /// Open a new episode (ignored while one is open). A held episode (see [`Command::End`]) is
    /// kept first. Refused, with an [`crate::Event::Refused`] naming why, when the session
    /// checks topics before a start and one is missing or slow, or when the disk guard finds no
    /// room for the episode.
    Start,
    /// [`Command::Start`] even when topics are missing or slow; the episode's metadata lists
    /// them (`started_with_missing_topics`). The disk guard still applies.
    ForceStart,
    /// Close the open episode with this outcome and finish its file. With no episode open: a
    /// held episode takes the outcome; `Discarded` moves the episode finished last to
    /// `discarded/`; otherwise ignored.
    Stop(Label),
    /// Stop recording and hold the episode open for a decision: a label ([`Command::Stop`]),
    /// [`Command::Keep`], [`Command::Rerecord`]; the next start or quit keeps it unlabeled.
    /// Its verdict comes at once ([`crate::Event::Ended`]).
    End,
    /// Keep the held episode as it is (unlabeled).
    Keep,
    /// Throw away the open, held or last finished episode (to `discarded/`) and start again.
    Rerecord,
    /// Stop, or start when idle: one button for pedals.
    Toggle,
    /// The task instruction of the episodes started from now on.
    Task(String),
    /// The next of the session's tasks ([`crate::RecorderOptions::tasks`]), after the last the
    /// first again.
    NextTask,
    /// Close the session, finishing an open episode as `unlabeled`.
    Quit,
}

/// The words the Zenoh control key takes, for messages.
pub const CONTROL_WORDS: &str =
    "start, force, stop, end, toggle, success, failure, discard, keep, rerecord, task <text>, next-task, quit";

impl FromStr for Command {
    type Err = String;
    /// The words accepted on the Zenoh control key (case and surrounding whitespace ignored,
    /// but the task's text is kept as given): see [`CONTROL_WORDS`].
    fn from_str(s: &str) -> Result<Self, String> {
        let s = s.trim();
        let (word, rest) = s
            .split_once(char::is_whitespace)
            .map_or((s, ""), |(w, r)| (w, r.trim()));
        let word = word.to_ascii_lowercase();
        if word == "task" {
            if rest.is_empty() {
                return Err(
                    "'task' needs the instruction after it, e.g. 'task stack the cups'".into(),
                );
            }
            return Ok(Self::Task(rest.to_string()));
        }
        if !rest.is_empty() {
            return Err(format!("unknown command '{s}' ({CONTROL_WORDS})"));
        }
        Ok(match word.as_str() {
            "start" => Self::Start,
            "force" | "start!" => Self::ForceStart,
            "stop" => Self::Stop(Label::Unlabeled),
            "end" => Self::End,
            "toggle" => Self::Toggle,
            "success" => Self::Stop(Label::Success),
            "failure" | "fail" => Self::Stop(Label::Failure),
            "discard" => Self::Stop(Label::Discarded),
            "keep" => Self::Keep,
            "rerecord" | "re-record" | "redo" => Self::Rerecord,
            "next-task" => Self::NextTask,
            "quit" => Self::Quit,
            other => return Err(format!("unknown command '{other}' ({CONTROL_WORDS})")),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn words_parse() {
        assert_eq!(" Discard\n".parse(), Ok(Command::Stop(Label::Discarded)));
        assert_eq!("start".parse(), Ok(Command::Start));
        assert_eq!("FORCE".parse(), Ok(Command::ForceStart));
        assert_eq!("re-record".parse(), Ok(Command::Rerecord));
        assert_eq!("Next-Task".parse(), Ok(Command::NextTask));
        assert_eq!(
            "task  Stack the Cups \n".parse(),
            Ok(Command::Task("Stack the Cups".into()))
        );
        assert!("task"
            .parse::<Command>()
            .unwrap_err()
            .contains("needs the instruction"));
        assert!("start now"
            .parse::<Command>()
            .unwrap_err()
            .contains("'start now'"));
        assert!("launch"
            .parse::<Command>()
            .unwrap_err()
            .contains("unknown command 'launch'"));
    }
}
