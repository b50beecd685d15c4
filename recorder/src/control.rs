//! Episode control vocabulary: what an operator, a foot pedal or a timer can ask for.

use std::fmt;
use std::str::FromStr;

/// How an episode ended, stored in its metadata.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    /// The demonstration succeeded.
    Success,
    /// The demonstration failed (kept: failures are data too).
    Failure,
    /// Thrown away by the operator; the file moves to `discarded/`.
    Discarded,
    /// Ended without a verdict (plain `stop`, unattended runs, quitting mid-episode).
    Unlabeled,
}

impl Outcome {
    /// The word stored in metadata.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Success => "success",
            Self::Failure => "failure",
            Self::Discarded => "discarded",
            Self::Unlabeled => "unlabeled",
        }
    }
}

impl fmt::Display for Outcome {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A request to the recorder.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Command {
    /// Open a new episode (ignored while one is open).
    Start,
    /// Close the open episode with this outcome (ignored while none is open).
    Stop(Outcome),
    /// Stop, or start when idle: one button for pedals.
    Toggle,
    /// Close the session, finishing an open episode as `unlabeled`.
    Quit,
}

impl FromStr for Command {
    type Err = String;
    /// The words accepted on the Zenoh control key: `start`, `stop`, `toggle`, `success`,
    /// `failure`, `discard`, `quit` (case and surrounding whitespace ignored).
    fn from_str(s: &str) -> Result<Self, String> {
        Ok(match s.trim().to_ascii_lowercase().as_str() {
            "start" => Self::Start,
            "stop" => Self::Stop(Outcome::Unlabeled),
            "toggle" => Self::Toggle,
            "success" => Self::Stop(Outcome::Success),
            "failure" | "fail" => Self::Stop(Outcome::Failure),
            "discard" => Self::Stop(Outcome::Discarded),
            "quit" => Self::Quit,
            other => {
                return Err(format!(
                "unknown command '{other}' (start, stop, toggle, success, failure, discard, quit)"
            ))
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn words_parse() {
        assert_eq!(" Discard\n".parse(), Ok(Command::Stop(Outcome::Discarded)));
        assert_eq!("start".parse(), Ok(Command::Start));
        assert!("launch"
            .parse::<Command>()
            .unwrap_err()
            .contains("unknown command 'launch'"));
    }
}
