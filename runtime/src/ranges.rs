//! What the control port accepts (`docs/runtime.md`, "Ranges of the control port"):
//! periods and `max_response` bounds within a range, priorities within a range,
//! real-time priorities only when the process allows them; and the short excerpt a
//! refusal quotes of what it refuses.
//!
//! The control port (every command, whoever sends it: a program, a supervisor, a
//! proxy, `coolctl`), a supervisor's [`Commander`](crate::Commander) and the network
//! layer's agent check with these functions, so a value is refused alike wherever it
//! comes from, before anything is applied.

use std::borrow::Cow;
use std::fmt::{self, Write as _};
use std::sync::atomic::{AtomicU8, Ordering};
use std::time::Duration;

use crate::monitor::Command;
use crate::refused::Refused;

/// The shortest period a command may set: 100 µs (10 kHz).
pub const MIN_PERIOD: Duration = Duration::from_micros(100);
/// The longest period a command may set: one hour.
pub const MAX_PERIOD: Duration = Duration::from_secs(3600);
/// The shortest `max_response` a command may set: 100 µs.
pub const MIN_MAX_RESPONSE: Duration = Duration::from_micros(100);
/// The longest `max_response` a command may set: one hour.
pub const MAX_MAX_RESPONSE: Duration = Duration::from_secs(3600);
/// The lowest priority a command may set: the nice range's span (a nice value 39
/// above the thread's own reaches the lowest, 19, from the highest, -20).
pub const MIN_PRIORITY: i32 = -39;
/// The highest priority a command may set: Linux's highest `SCHED_RR` static
/// priority.
pub const MAX_PRIORITY: i32 = 99;

/// The environment variable that lets a process's components take real-time
/// priorities (`1`, `true` or `yes`): read once, when the first priority is checked,
/// unless [`allow_realtime_priorities`] decided first.
pub const REALTIME_PRIORITIES_ENV: &str = "COOLBOT_REALTIME_PRIORITIES";

/// How many characters of what it refuses (a name, a value, a command) a refusal
/// quotes; the rest is replaced by a note of the full length.
pub const EXCERPT_CHARS: usize = 64;
/// How many characters of a reason written by other code (a component's own
/// refusal of a value or configuration, a decoder's error, which may quote what
/// they refuse) a refusal passes on.
pub const REASON_CHARS: usize = 256;

const UNDECIDED: u8 = 0;
const ALLOWED: u8 = 1;
const REFUSED: u8 = 2;

static REALTIME: AtomicU8 = AtomicU8::new(UNDECIDED);

/// Whether a value of [`REALTIME_PRIORITIES_ENV`] allows real-time priorities.
fn allows(value: Option<&std::ffi::OsStr>) -> bool {
    value.and_then(|value| value.to_str()).is_some_and(|value| {
        ["1", "true", "yes"]
            .iter()
            .any(|yes| value.trim().eq_ignore_ascii_case(yes))
    })
}

/// Whether this process's components may take real-time priorities (a positive
/// priority: `SCHED_RR` on Linux). No by default; [`REALTIME_PRIORITIES_ENV`] or
/// [`allow_realtime_priorities`] say yes.
pub fn realtime_priorities_allowed() -> bool {
    match REALTIME.load(Ordering::Acquire) {
        ALLOWED => true,
        REFUSED => false,
        _ => {
            let decided = if allows(std::env::var_os(REALTIME_PRIORITIES_ENV).as_deref()) {
                ALLOWED
            } else {
                REFUSED
            };
            // A call to `allow_realtime_priorities` in between wins.
            let _ =
                REALTIME.compare_exchange(UNDECIDED, decided, Ordering::AcqRel, Ordering::Acquire);
            REALTIME.load(Ordering::Acquire) == ALLOWED
        }
    }
}

/// Let this process's components take real-time priorities, or not, from now on
/// (over [`REALTIME_PRIORITIES_ENV`]). A priority already applied stays.
pub fn allow_realtime_priorities(allowed: bool) {
    REALTIME.store(if allowed { ALLOWED } else { REFUSED }, Ordering::Release);
}

/// A period a command may set: positive, from [`MIN_PERIOD`] to [`MAX_PERIOD`].
pub fn period(period: Duration) -> Result<(), Refused> {
    if period.is_zero() {
        Err(Refused::ZeroPeriod)
    } else if !(MIN_PERIOD..=MAX_PERIOD).contains(&period) {
        Err(Refused::PeriodOutOfRange {
            period,
            min: MIN_PERIOD,
            max: MAX_PERIOD,
        })
    } else {
        Ok(())
    }
}

/// A `max_response` a command may set: positive, from [`MIN_MAX_RESPONSE`] to
/// [`MAX_MAX_RESPONSE`].
pub fn max_response(bound: Duration) -> Result<(), Refused> {
    if bound.is_zero() {
        Err(Refused::ZeroMaxResponse)
    } else if !(MIN_MAX_RESPONSE..=MAX_MAX_RESPONSE).contains(&bound) {
        Err(Refused::MaxResponseOutOfRange {
            max_response: bound,
            min: MIN_MAX_RESPONSE,
            max: MAX_MAX_RESPONSE,
        })
    } else {
        Ok(())
    }
}

/// A priority a command may set: from [`MIN_PRIORITY`] to [`MAX_PRIORITY`], and
/// positive (real-time) only when [`realtime_priorities_allowed`].
pub fn priority(priority: i32) -> Result<(), Refused> {
    if !(MIN_PRIORITY..=MAX_PRIORITY).contains(&priority) {
        Err(Refused::PriorityOutOfRange {
            priority,
            min: MIN_PRIORITY,
            max: MAX_PRIORITY,
        })
    } else if priority > 0 && !realtime_priorities_allowed() {
        Err(Refused::RealtimePriority { priority })
    } else {
        Ok(())
    }
}

/// Check the values of `command` against the ranges above (the other commands have
/// none here: their values are checked against the component, by the component).
pub fn command(command: &Command) -> Result<(), Refused> {
    match command {
        Command::SetPeriod(value) => period(*value),
        Command::SetMaxResponse(value) => max_response(*value),
        Command::SetPriority(value) => priority(*value),
        Command::SetState(_)
        | Command::Configure(_)
        | Command::Set(..)
        | Command::SetQuality(_)
        | Command::SetDegradation(_) => Ok(()),
    }
}

/// `text` cut to its first `chars` characters, followed by a note of its full length
/// when it was longer; `text` itself when it was not.
pub fn excerpt(text: &str, chars: usize) -> Cow<'_, str> {
    match text.char_indices().nth(chars) {
        None => Cow::Borrowed(text),
        Some((end, _)) => Cow::Owned(format!("{}... ({} bytes in all)", &text[..end], text.len())),
    }
}

/// What `value`'s `Debug` writes, cut as [`excerpt`] cuts it, without ever holding
/// more than the excerpt (a command carrying a string of many megabytes is rendered
/// in a few dozen bytes).
pub fn excerpt_debug(value: &impl fmt::Debug, chars: usize) -> String {
    let mut cut = Cut {
        kept: String::new(),
        chars: 0,
        limit: chars,
        bytes: 0,
    };
    let _ = write!(cut, "{value:?}");
    if cut.chars > chars {
        format!("{}... ({} bytes in all)", cut.kept, cut.bytes)
    } else {
        cut.kept
    }
}

/// A writer that keeps the first `limit` characters and counts the rest.
struct Cut {
    kept: String,
    /// Characters written (counted up to `limit + 1`).
    chars: usize,
    limit: usize,
    /// Bytes written in all.
    bytes: usize,
}

impl fmt::Write for Cut {
    fn write_str(&mut self, text: &str) -> fmt::Result {
        self.bytes += text.len();
        if self.chars > self.limit {
            return Ok(());
        }
        for c in text.chars() {
            if self.chars == self.limit {
                self.chars += 1;
                break;
            }
            self.kept.push(c);
            self.chars += 1;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_environment_allows_realtime_priorities_only_when_it_says_yes() {
        for yes in ["1", "true", "YES", " yes "] {
            assert!(allows(Some(std::ffi::OsStr::new(yes))), "{yes}");
        }
        for no in ["", "0", "no", "false", "2"] {
            assert!(!allows(Some(std::ffi::OsStr::new(no))), "{no}");
        }
        assert!(!allows(None));
    }

    #[test]
    fn ranges_refuse_what_is_outside_and_take_their_ends() {
        assert_eq!(period(Duration::ZERO), Err(Refused::ZeroPeriod));
        assert_eq!(period(MIN_PERIOD), Ok(()));
        assert_eq!(period(MAX_PERIOD), Ok(()));
        for outside in [MIN_PERIOD - Duration::from_nanos(1), Duration::MAX] {
            assert!(
                matches!(period(outside), Err(Refused::PeriodOutOfRange { .. })),
                "{outside:?}"
            );
        }
        assert_eq!(max_response(Duration::ZERO), Err(Refused::ZeroMaxResponse));
        assert_eq!(max_response(MAX_MAX_RESPONSE), Ok(()));
        assert!(matches!(
            max_response(MAX_MAX_RESPONSE + Duration::from_nanos(1)),
            Err(Refused::MaxResponseOutOfRange { .. })
        ));
        assert_eq!(priority(MIN_PRIORITY), Ok(()));
        assert_eq!(priority(0), Ok(()));
        assert!(
            Refused::RealtimePriority { priority: 1 }
                .to_string()
                .contains(&format!("{REALTIME_PRIORITIES_ENV}=1")),
            "the refusal names the variable that allows"
        );
        for outside in [MIN_PRIORITY - 1, MAX_PRIORITY + 1, i32::MIN, i32::MAX] {
            assert!(
                matches!(priority(outside), Err(Refused::PriorityOutOfRange { .. })),
                "{outside}"
            );
        }
    }

    #[test]
    fn an_excerpt_keeps_a_short_prefix_and_says_how_long_the_whole_was() {
        assert_eq!(excerpt("short", 64), "short");
        let long = "é".repeat(100);
        let cut = excerpt(&long, 3);
        assert_eq!(cut, "ééé... (200 bytes in all)");
        let command = Command::Set("x".repeat(1 << 20), crate::Value::Unit);
        let rendered = excerpt_debug(&command, EXCERPT_CHARS);
        assert!(rendered.len() < 120, "{rendered}");
        assert!(rendered.starts_with("Set(\"xxx"), "{rendered}");
        assert!(rendered.ends_with("bytes in all)"), "{rendered}");
        assert_eq!(excerpt_debug(&Command::SetQuality(1), 64), "SetQuality(1)");
        assert_eq!(excerpt_debug(&"abcd", 4), "\"abc... (6 bytes in all)");
    }
}
