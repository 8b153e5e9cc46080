//! An error and its sources as one line for a person ([`Chain`]).
//!
//! Every error type of the runtime says what failed in its own message and keeps what
//! caused it as its [`source`](std::error::Error::source), never in its message, so
//! that `{error}` alone shows only the outermost context. Where an error is shown to a
//! person (a log line, a program's last words, a component's `error` text), it is
//! shown with its chain:
//!
//! ```
//! use coolbot::Chain;
//!
//! #[derive(Debug, thiserror::Error)]
//! #[error("cannot read the map")]
//! struct MapError(#[source] std::io::Error);
//!
//! let error = MapError(std::io::Error::other("disk on fire"));
//! assert_eq!(error.to_string(), "cannot read the map");
//! assert_eq!(Chain(&error).to_string(), "cannot read the map: disk on fire");
//! ```

use std::error::Error;
use std::fmt;

/// Displays an error followed by each of its sources, `: ` between them, each once: a
/// source whose message the text shown so far already holds is left out (an error of
/// another library may print its source in its own message too).
#[derive(Clone, Copy)]
pub struct Chain<'a>(pub &'a (dyn Error + 'a));

impl fmt::Display for Chain<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut shown = self.0.to_string();
        let mut source = self.0.source();
        while let Some(cause) = source {
            let text = cause.to_string();
            if !shown.contains(&text) {
                shown.push_str(": ");
                shown.push_str(&text);
            }
            source = cause.source();
        }
        f.write_str(&shown)
    }
}

impl fmt::Debug for Chain<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Display::fmt(self, f)
    }
}

#[cfg(test)]
mod tests {
    use super::Chain;

    #[derive(Debug, thiserror::Error)]
    enum Outer {
        #[error("cannot start `{0}`")]
        Start(String, #[source] Middle),
    }

    #[derive(Debug, thiserror::Error)]
    #[error("its thread")]
    struct Middle(#[source] std::io::Error);

    /// An error of another library that prints its source itself.
    #[derive(Debug, thiserror::Error)]
    #[error("wrapped: {0}")]
    struct Loud(#[source] std::io::Error);

    #[test]
    fn each_source_is_shown_once_after_the_context() {
        let error = Outer::Start(
            "w".to_owned(),
            Middle(std::io::Error::other("no more threads")),
        );
        assert_eq!(error.to_string(), "cannot start `w`");
        assert_eq!(
            Chain(&error).to_string(),
            "cannot start `w`: its thread: no more threads"
        );
        let loud = Loud(std::io::Error::other("gone"));
        assert_eq!(Chain(&loud).to_string(), "wrapped: gone");
    }
}
