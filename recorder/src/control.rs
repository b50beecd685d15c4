//! Episode control vocabulary: what an operator, a foot pedal or a timer can ask for.

use std::str::FromStr;

pub use scaledp_schema::Label;

/// A request to the recorder.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Command {
    /// Open a new episode (ignored while one is open).
    Start,
    /// Close the open episode with this outcome (ignored while none is open).
    Stop(Label),
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
            "stop" => Self::Stop(Label::Unlabeled),
            "toggle" => Self::Toggle,
            "success" => Self::Stop(Label::Success),
            "failure" | "fail" => Self::Stop(Label::Failure),
            "discard" => Self::Stop(Label::Discarded),
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
        assert_eq!(" Discard\n".parse(), Ok(Command::Stop(Label::Discarded)));
        assert_eq!("start".parse(), Ok(Command::Start));
        assert!("launch"
            .parse::<Command>()
            .unwrap_err()
            .contains("unknown command 'launch'"));
    }
}
