//! Log lines that a peer or a fault can repeat at packet or retry rate (a packet that
//! does not decode, a retry that fails): let through at most once per interval, each
//! with a count of the lines held back before it.
//!
//! A [`Limiter`] lets the first line of a key through, then at most one line of that
//! key per interval ([`EVERY`], 10 s); the line let through tells how many were held
//! back since the one before ([`Held`], written after the message:
//! ` (and 199,999 more in the last 10 s)`). The count of a burst that stops is told
//! with the next line of its key. Each call site has a limiter of its own
//! ([`limited!`](crate::limited)); the key separates what one site logs about (a
//! bridge key, a component), so that one noisy key does not silence the others.
//!
//! ```
//! for packet in 0..1000 {
//!     coolbot::limited!("robot/scan", |held| {
//!         tracing::warn!(key = "robot/scan", "packet {packet} does not decode{held}")
//!     });
//! }
//! ```

use std::collections::BTreeMap;
use std::hash::{DefaultHasher, Hash, Hasher};
use std::sync::{Mutex, PoisonError};
use std::time::{Duration, Instant};

/// How often a key's line is let through at most, by [`limited!`](crate::limited).
pub const EVERY: Duration = Duration::from_secs(10);

/// How many keys a limiter tells apart; beyond, new keys share one window (their
/// lines are still let through and counted, only not separately).
pub const KEYS: usize = 1024;

/// The key the keys beyond [`KEYS`] share.
const OVERFLOW: u64 = u64::MAX;

/// One key's window: when its last line went out, and how many were held back since.
#[derive(Debug, Clone, Copy)]
struct Window {
    since: Instant,
    held: u64,
}

/// Lets one line per key and interval through (module documentation).
#[derive(Debug)]
pub struct Limiter {
    every: Duration,
    windows: Mutex<BTreeMap<u64, Window>>,
}

impl Limiter {
    /// A limiter that lets a key's line through at most once per `every`.
    pub const fn new(every: Duration) -> Limiter {
        Limiter {
            every,
            windows: Mutex::new(BTreeMap::new()),
        }
    }

    /// Whether a line of `key` goes out now: `Some` with the count held back since
    /// the last one, or `None` (held back, and counted).
    pub fn admit(&self, key: impl Hash) -> Option<Held> {
        self.admit_at(key, Instant::now())
    }

    /// [`Limiter::admit`] at `now` (tests give the time).
    pub fn admit_at(&self, key: impl Hash, now: Instant) -> Option<Held> {
        let mut hasher = DefaultHasher::new();
        key.hash(&mut hasher);
        let mut key = hasher.finish();
        let mut windows = self.windows.lock().unwrap_or_else(PoisonError::into_inner);
        if !windows.contains_key(&key) && windows.len() >= KEYS {
            // Windows that have closed with nothing held back tell nothing more.
            windows.retain(|_, window| {
                window.held > 0 || now.saturating_duration_since(window.since) < self.every
            });
            if windows.len() >= KEYS {
                key = OVERFLOW;
            }
        }
        match windows.get_mut(&key) {
            None => {
                windows.insert(
                    key,
                    Window {
                        since: now,
                        held: 0,
                    },
                );
                Some(Held::NONE)
            }
            Some(window) => {
                let open = now.saturating_duration_since(window.since);
                if open < self.every {
                    window.held = window.held.saturating_add(1);
                    return None;
                }
                let held = Held {
                    count: window.held,
                    over: open,
                };
                *window = Window {
                    since: now,
                    held: 0,
                };
                Some(held)
            }
        }
    }
}

/// The lines of a key held back before the one let through: written after its
/// message, nothing when there were none, else ` (and 12 more in the last 10 s)`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Held {
    count: u64,
    over: Duration,
}

impl Held {
    /// Nothing held back.
    pub const NONE: Held = Held {
        count: 0,
        over: Duration::ZERO,
    };

    /// How many lines were held back.
    pub fn count(&self) -> u64 {
        self.count
    }

    /// Since when they were held back: the time from the line before to this one.
    pub fn over(&self) -> Duration {
        self.over
    }
}

impl std::fmt::Display for Held {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.count == 0 {
            return Ok(());
        }
        let over = if self.over >= Duration::from_secs(1) {
            format!("{} s", self.over.as_secs())
        } else {
            format!("{} ms", self.over.as_millis())
        };
        write!(f, " (and {} more in the last {over})", grouped(self.count))
    }
}

/// `n` with its thousands separated by commas (`199,999`).
fn grouped(n: u64) -> String {
    let digits = n.to_string();
    let mut out = String::with_capacity(digits.len() + digits.len() / 3);
    for (i, digit) in digits.chars().enumerate() {
        if i > 0 && (digits.len() - i).is_multiple_of(3) {
            out.push(',');
        }
        out.push(digit);
    }
    out
}

/// Log through a limiter of this call site's own ([`Limiter`], [`EVERY`]):
/// `limited!(key, |held| tracing::warn!("...{held}"))` runs the logging expression
/// only when a line of `key` is let through, with `held` the [`Held`] count to write
/// after the message.
#[macro_export]
macro_rules! limited {
    ($key:expr, |$held:ident| $log:expr $(,)?) => {{
        static LIMITER: $crate::log::Limiter = $crate::log::Limiter::new($crate::log::EVERY);
        if let ::std::option::Option::Some($held) = LIMITER.admit($key) {
            $log;
        }
    }};
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(t0: Instant, ms: u64) -> Instant {
        t0 + Duration::from_millis(ms)
    }

    #[test]
    fn the_first_line_goes_out_then_one_per_interval_with_the_count_held_back() {
        let limiter = Limiter::new(EVERY);
        let t0 = Instant::now();
        assert_eq!(limiter.admit_at("k", t0), Some(Held::NONE));
        // 199,999 more within the interval: held back.
        for i in 1..200_000u64 {
            assert_eq!(limiter.admit_at("k", at(t0, i * 9_999 / 200_000)), None);
        }
        // The interval is over: the next line goes out with the count.
        let held = limiter.admit_at("k", at(t0, 10_000)).expect("let through");
        assert_eq!(held.count(), 199_999);
        assert_eq!(held.to_string(), " (and 199,999 more in the last 10 s)");
        // Then quiet for a minute: the next line goes out alone.
        let held = limiter.admit_at("k", at(t0, 70_000)).expect("let through");
        assert_eq!(
            held,
            Held {
                count: 0,
                over: Duration::from_secs(60)
            }
        );
        assert_eq!(held.to_string(), "");
        // One held back, told with the line after the interval, whenever it comes.
        assert_eq!(limiter.admit_at("k", at(t0, 71_000)), None);
        let held = limiter.admit_at("k", at(t0, 95_000)).expect("let through");
        assert_eq!(held.to_string(), " (and 1 more in the last 25 s)");
    }

    #[test]
    fn keys_are_limited_apart() {
        let limiter = Limiter::new(EVERY);
        let t0 = Instant::now();
        assert!(limiter.admit_at("a", t0).is_some());
        assert!(limiter.admit_at("a", at(t0, 1)).is_none());
        assert!(limiter.admit_at("b", at(t0, 2)).is_some());
        assert!(limiter.admit_at(("a", 1), at(t0, 3)).is_some());
    }

    #[test]
    fn keys_beyond_the_bound_share_one_window_and_closed_windows_are_forgotten() {
        let limiter = Limiter::new(EVERY);
        let t0 = Instant::now();
        for key in 0..KEYS {
            assert!(limiter.admit_at(key, t0).is_some());
        }
        // Every window open: a new key shares the overflow window.
        assert!(limiter.admit_at(KEYS, at(t0, 1)).is_some());
        assert!(limiter.admit_at(KEYS + 1, at(t0, 2)).is_none());
        // Once the windows have closed with nothing held, they make room; the shared
        // one, holding a line back, stays to tell it.
        assert!(limiter.admit_at(KEYS + 3, at(t0, 20_000)).is_some());
        assert!(limiter.admit_at(KEYS + 4, at(t0, 20_001)).is_some());
        assert_eq!(limiter.windows.lock().unwrap().len(), 3);
        assert_eq!(limiter.windows.lock().unwrap()[&OVERFLOW].held, 1);
    }

    #[test]
    fn each_call_site_of_the_macro_has_its_own_limiter() {
        let mut first = Vec::new();
        let mut second = Vec::new();
        for n in 0..5 {
            crate::limited!("key", |held| first.push((n, held.count())));
            crate::limited!("key", |held| second.push((n, held.count())));
        }
        assert_eq!(first, [(0, 0)]);
        assert_eq!(second, [(0, 0)]);
    }

    #[test]
    fn counts_are_grouped_by_thousands() {
        for (n, text) in [
            (0, "0"),
            (999, "999"),
            (1_000, "1,000"),
            (199_999, "199,999"),
            (1_234_567, "1,234,567"),
        ] {
            assert_eq!(grouped(n), text);
        }
        let held = Held {
            count: 3,
            over: Duration::from_millis(250),
        };
        assert_eq!(held.to_string(), " (and 3 more in the last 250 ms)");
    }
}
