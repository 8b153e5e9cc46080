//! Equalization (paper 3.6): "uniforming load distribution" among the components that
//! share a processor, from their "peak-valley load profiles". It operates transparently:
//! no description asks for it.
//!
//! Two periodic components with the same period whose deadlines coincide ask for the
//! CPU at the same moments: a peak, then a valley for the rest of the period. When they
//! share one core they wait for each other every period (the scheduler slices the core
//! between them, or one starts after the other). The symptom is in each one's elapsed
//! time against its CPU time: time in which it was ready to run and got no CPU. On
//! Linux the runner reads exactly that from the thread's `schedstat` (time on a CPU,
//! time waiting on a run queue), one read per period; elsewhere it takes the section's
//! elapsed time less its CPU time. Equalization moves one component's phase once,
//! into the widest valley the others leave in the period, so that the sections stop
//! coinciding.
//!
//! The parts:
//!
//! - [`Board`]: one per process ([`Board::process`]; tests make their own): where each
//!   seated component last had a deadline, its period, and how long its sections take.
//! - [`Seat`]: a component's place on the board and its peak detector. The runner seats
//!   every periodic component whose adaptation is on (on the real clock) and feeds it
//!   one [`Activation`] per periodic section; it answers with a [`Shift`] when the
//!   component should delay its next deadline, published as an
//!   [`crate::adapt::AdaptAction::Equalized`] step. Decisions are taken under the
//!   board's lock against the others' latest phases, and a shift is written to the
//!   board at once, so two suffering components never both move into the same valley.
//! - [`place`]: the arithmetic, free of threads and clocks: where in the period a busy
//!   interval fits best among the others'.
//!
//! Only components with the same period are equalized against each other (harmonic
//! periods are not, yet: see `docs/runtime.md`, "What is partial").

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

/// When a section counts as a peak, and how often equalization may act.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EqualizeConfig {
    /// A period in which the component waited for a CPU longer than this share of the
    /// period was a peak. Default 0.05.
    pub late_share: f64,
    /// The periods a verdict looks at. Default 8.
    pub window: u32,
    /// Peaks among the last `window` periods that make a component move. Default 4.
    pub peaks: u32,
    /// Periods after a move (or a failed search for a valley) before the next one.
    /// Default 16.
    pub hold_periods: u32,
}

impl Default for EqualizeConfig {
    fn default() -> EqualizeConfig {
        EqualizeConfig {
            late_share: 0.05,
            window: 8,
            peaks: 4,
            hold_periods: 16,
        }
    }
}

/// One periodic section, as equalization sees it.
#[derive(Debug, Clone, Copy)]
pub struct Activation {
    /// The deadline the section was due at.
    pub deadline: Instant,
    /// The CPU time the component's thread used since its previous periodic section:
    /// what it asks of the processor each period.
    pub cpu: Duration,
    /// How long, over the same time, it was ready to run and waited for a CPU.
    pub waited: Duration,
    /// The component's period.
    pub period: Duration,
}

/// A decision to move: delay the next deadline by `delay`.
#[derive(Debug, Clone, PartialEq)]
pub struct Shift {
    /// How much later the next deadline comes (less than one period).
    pub delay: Duration,
    /// The components whose sections the component's coincided with.
    pub away_from: Vec<String>,
}

/// Where each seated component stands.
#[derive(Debug)]
struct Place {
    id: u64,
    name: String,
    period: Duration,
    /// Its latest deadline (any deadline gives its phase modulo the period).
    deadline: Instant,
    /// The CPU it asks for each period: the most of its recent periods.
    busy: Duration,
}

/// The seated components of one system.
#[derive(Debug, Default)]
pub struct Board {
    places: Mutex<Vec<Place>>,
    next_id: AtomicU64,
}

/// The process's board.
static PROCESS: std::sync::OnceLock<Arc<Board>> = std::sync::OnceLock::new();

impl Board {
    /// The board of every component of this process (they share its processors).
    pub fn process() -> &'static Arc<Board> {
        PROCESS.get_or_init(Board::new)
    }

    /// An empty board.
    pub fn new() -> Arc<Board> {
        Arc::new(Board::default())
    }

    /// Seat a component (named for the steps that mention it).
    pub fn seat(self: &Arc<Board>, name: &str, config: EqualizeConfig) -> Seat {
        let id = self.next_id.fetch_add(1, Ordering::Relaxed);
        Seat {
            board: Arc::clone(self),
            id,
            name: name.to_owned(),
            config,
            recent: Vec::new(),
            busy: Vec::new(),
            hold: 0,
            seated: false,
        }
    }

    fn places(&self) -> std::sync::MutexGuard<'_, Vec<Place>> {
        self.places.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

/// A component's place on its system's [`Board`]; it leaves the board when dropped.
#[derive(Debug)]
pub struct Seat {
    board: Arc<Board>,
    id: u64,
    name: String,
    config: EqualizeConfig,
    /// Peak flags of the last `window` sections.
    recent: Vec<bool>,
    /// CPU times of the last `window` periods.
    busy: Vec<Duration>,
    hold: u32,
    /// Whether the board has this component's place.
    seated: bool,
}

impl Drop for Seat {
    fn drop(&mut self) {
        self.board.places().retain(|place| place.id != self.id);
    }
}

impl Seat {
    /// One periodic section; a [`Shift`] when the component should move its phase.
    pub fn observe(&mut self, activation: Activation) -> Option<Shift> {
        let window = self.config.window.max(1) as usize;
        let share = if self.config.late_share.is_finite() {
            self.config.late_share.clamp(0.0, 1.0)
        } else {
            EqualizeConfig::default().late_share
        };
        let peak = activation.waited > activation.period.mul_f64(share);
        push_window(&mut self.recent, peak, window);
        push_window(
            &mut self.busy,
            activation.cpu.min(activation.period),
            window,
        );
        let busy = self.busy.iter().copied().max().unwrap_or_default();

        let mut places = self.board.places();
        match places.iter_mut().find(|place| place.id == self.id) {
            Some(place) => {
                place.period = activation.period;
                place.deadline = activation.deadline;
                place.busy = busy;
            }
            None => {
                places.push(Place {
                    id: self.id,
                    name: self.name.clone(),
                    period: activation.period,
                    deadline: activation.deadline,
                    busy,
                });
                self.seated = true;
            }
        }
        if self.hold > 0 {
            self.hold -= 1;
            return None;
        }
        let peaks = self.recent.iter().filter(|peak| **peak).count();
        if peaks < self.config.peaks.max(1) as usize {
            return None;
        }
        // A peak: find who coincides and the widest valley they leave.
        let period = activation.period;
        // Rivals: the same period, and a deadline within the last two periods (a
        // component that stopped its periodic sections, suspended or in another
        // state, keeps its place but is no rival).
        let active = |place: &Place| {
            crate::time::later(place.deadline, period.saturating_mul(2)) >= activation.deadline
        };
        let others: Vec<(Duration, Duration, &str)> = places
            .iter()
            .filter(|place| place.id != self.id && place.period == period && active(place))
            .map(|place| {
                (
                    phase(place.deadline, activation.deadline, period),
                    place.busy,
                    place.name.as_str(),
                )
            })
            .collect();
        let away_from: Vec<String> = others
            .iter()
            .filter(|(start, len, _)| overlaps(Duration::ZERO, busy, *start, *len, period))
            .map(|(_, _, name)| (*name).to_owned())
            .collect();
        self.recent.clear();
        self.hold = self.config.hold_periods;
        if away_from.is_empty() {
            return None; // Late for another reason (another process, a longer period).
        }
        let spans: Vec<(Duration, Duration)> = others.iter().map(|(s, l, _)| (*s, *l)).collect();
        let delay = place(period, busy, &spans)?;
        if let Some(place) = places.iter_mut().find(|place| place.id == self.id) {
            place.deadline = crate::time::later(activation.deadline, delay);
        }
        Some(Shift { delay, away_from })
    }
}

/// A thread's CPU time and run-queue wait, read on the thread itself: Linux's
/// `/proc/thread-self/schedstat` (one `pread` of a file opened once), else the thread's
/// CPU time and, for the wait, whatever elapsed time the caller says went unused.
#[derive(Debug)]
pub(crate) struct ThreadStats {
    #[cfg(target_os = "linux")]
    file: Option<std::fs::File>,
    /// The previous reading ([`ThreadStats::since_last`]).
    last: Option<(Duration, Option<Duration>)>,
}

impl ThreadStats {
    /// The calling thread's statistics (only that thread may read them).
    pub(crate) fn of_current_thread() -> ThreadStats {
        ThreadStats {
            #[cfg(target_os = "linux")]
            file: std::fs::File::open("/proc/thread-self/schedstat").ok(),
            last: None,
        }
    }

    /// The CPU time and the wait since the previous call (`None` at the first call,
    /// or when unreadable).
    pub(crate) fn since_last(&mut self) -> Option<(Duration, Option<Duration>)> {
        let (cpu, waiting) = self.read()?;
        let (cpu_then, waiting_then) = self.last.replace((cpu, waiting))?;
        let waited = match (waiting, waiting_then) {
            (Some(now), Some(then)) => Some(now.saturating_sub(then)),
            _ => None,
        };
        Some((cpu.saturating_sub(cpu_then), waited))
    }

    /// `(time on a CPU, time waiting for one)` so far; the wait is `None` where the OS
    /// does not tell it.
    pub(crate) fn read(&self) -> Option<(Duration, Option<Duration>)> {
        #[cfg(target_os = "linux")]
        if let Some(file) = &self.file {
            use std::os::unix::fs::FileExt;
            let mut buffer = [0u8; 96];
            let read = file.read_at(&mut buffer, 0).ok()?;
            let text = std::str::from_utf8(buffer.get(..read)?).ok()?;
            let mut fields = text.split_ascii_whitespace().map(str::parse::<u64>);
            let on_cpu = fields.next()?.ok()?;
            let waiting = fields.next()?.ok()?;
            return Some((
                Duration::from_nanos(on_cpu),
                Some(Duration::from_nanos(waiting)),
            ));
        }
        let cpu = cpu_time::ThreadTime::try_now().ok()?.as_duration();
        Some((cpu, None))
    }
}

fn push_window<T>(values: &mut Vec<T>, value: T, window: usize) {
    values.push(value);
    if values.len() > window {
        let extra = values.len() - window;
        values.drain(..extra);
    }
}

/// `deadline - reference` modulo `period`.
fn phase(deadline: Instant, reference: Instant, period: Duration) -> Duration {
    let period_ns = period.as_nanos().max(1);
    let (ahead, behind) = match deadline.checked_duration_since(reference) {
        Some(ahead) => (ahead.as_nanos() % period_ns, false),
        None => (
            reference.duration_since(deadline).as_nanos() % period_ns,
            true,
        ),
    };
    let ns = if behind && ahead != 0 {
        period_ns - ahead
    } else {
        ahead
    };
    Duration::from_nanos(u64::try_from(ns).unwrap_or(u64::MAX))
}

/// Whether `[a, a + a_len)` and `[b, b + b_len)` overlap on a circle of `period`.
fn overlaps(a: Duration, a_len: Duration, b: Duration, b_len: Duration, period: Duration) -> bool {
    if a_len.is_zero() || b_len.is_zero() {
        return false;
    }
    let start_b = phase_of(b, a, period);
    // `b` starts `start_b` after `a`: they overlap if it starts before `a` ends, or if
    // it wraps around past `a`'s start.
    start_b < a_len || start_b + b_len > period
}

/// `b - a` modulo `period`, for offsets within one period.
fn phase_of(b: Duration, a: Duration, period: Duration) -> Duration {
    if b >= a {
        b - a
    } else {
        period.saturating_sub(a - b)
    }
}

/// Where a busy interval of `busy` fits best in a `period` whose other busy intervals
/// are `others` (`(start, length)`, starts relative to the interval's current start,
/// within the period): the delay that centres it in the widest gap between them.
/// `None` when it already overlaps none, or when no gap is wider than `busy`.
pub fn place(
    period: Duration,
    busy: Duration,
    others: &[(Duration, Duration)],
) -> Option<Duration> {
    let others: Vec<(Duration, Duration)> = others
        .iter()
        .filter(|(_, len)| !len.is_zero())
        .map(|(start, len)| (*start, (*len).min(period)))
        .collect();
    if others
        .iter()
        .all(|(start, len)| !overlaps(Duration::ZERO, busy, *start, *len, period))
    {
        return None;
    }
    // The busy arcs of the others, sorted by start; the gaps are between the end of
    // each arc and the start of the next one, around the circle.
    let mut arcs = others;
    arcs.sort();
    let mut best: Option<(Duration, Duration)> = None; // (gap start, gap length)
    for (i, (start, len)) in arcs.iter().enumerate() {
        let end = *start + *len;
        // The arc that starts next after this one ends, around the circle: the gap is
        // up to the nearest start at or after `end`.
        let gap = arcs
            .iter()
            .enumerate()
            .filter(|(j, _)| *j != i)
            .map(|(_, (s, _))| {
                let s_abs = if *s >= *start { *s } else { *s + period };
                s_abs.saturating_sub(end)
            })
            .min()
            .unwrap_or_else(|| period.saturating_sub(*len));
        // Another arc covering `end` leaves no gap here.
        let end_in_period = Duration::from_nanos(
            u64::try_from(end.as_nanos() % period.as_nanos().max(1)).unwrap_or(0),
        );
        let covered = arcs
            .iter()
            .enumerate()
            .any(|(j, (s, l))| j != i && phase_of(end_in_period, *s, period) < *l);
        if covered {
            continue;
        }
        if best.is_none_or(|(_, length)| gap > length) {
            best = Some((end, gap));
        }
    }
    let (start, gap) = best?;
    if gap <= busy {
        return None;
    }
    let target = start + (gap - busy) / 2;
    let nanos = target.as_nanos() % period.as_nanos().max(1);
    Some(Duration::from_nanos(u64::try_from(nanos).unwrap_or(0)))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ms(n: u64) -> Duration {
        Duration::from_millis(n)
    }

    #[test]
    fn a_busy_interval_goes_to_the_middle_of_the_widest_valley() {
        // Another component busy over [0, 6) of 20 ms: the valley is [6, 20), 14 ms
        // wide; a 6 ms interval centred in it starts at 10.
        assert_eq!(place(ms(20), ms(6), &[(ms(0), ms(6))]), Some(ms(10)));
        // Two others at [0, 4) and [10, 12): valleys [4, 10) (6 ms) and [12, 20)
        // (8 ms); 2 ms goes to 12 + 3 = 15.
        assert_eq!(
            place(ms(20), ms(2), &[(ms(0), ms(4)), (ms(10), ms(2))]),
            Some(ms(15))
        );
        // An arc that wraps around the end of the period: [16, 24) is [16, 20) and
        // [0, 4); the valley is [4, 16); a 4 ms interval starting at 2 overlaps it.
        assert_eq!(place(ms(20), ms(4), &[(ms(16), ms(8))]), Some(ms(8)));
    }

    #[test]
    fn nothing_moves_without_an_overlap_or_without_room() {
        assert_eq!(place(ms(20), ms(6), &[(ms(8), ms(6))]), None, "no overlap");
        assert_eq!(place(ms(20), ms(12), &[(ms(0), ms(10))]), None, "no room");
        assert_eq!(place(ms(20), ms(6), &[]), None, "alone");
    }

    fn activation(at: Instant, deadline_ms: u64, waited_ms: u64, cpu_ms: u64) -> Activation {
        Activation {
            deadline: at + ms(deadline_ms),
            cpu: ms(cpu_ms),
            waited: ms(waited_ms),
            period: ms(20),
        }
    }

    #[test]
    fn the_component_that_waits_moves_once_and_the_other_stays() {
        let board = Board::new();
        let config = EqualizeConfig {
            window: 4,
            peaks: 2,
            hold_periods: 100,
            ..EqualizeConfig::default()
        };
        let mut first = board.seat("first", config);
        let mut second = board.seat("second", config);
        let t0 = Instant::now();
        let mut shifts = Vec::new();
        let mut moved = 0;
        for n in 0..6 {
            // Same deadlines; `first` runs on time, `second` waits 6 ms for it until
            // it moves, then runs on time `moved` ms later.
            let due = 20 * n;
            assert_eq!(first.observe(activation(t0, due, 0, 6)), None);
            let late = if moved == 0 { 6 } else { 0 };
            if let Some(shift) = second.observe(activation(t0, due + moved, late, 6)) {
                moved = u64::try_from(shift.delay.as_millis()).expect("ms");
                shifts.push((n, shift));
            }
        }
        assert_eq!(
            shifts,
            [(
                1,
                Shift {
                    delay: ms(10),
                    away_from: vec!["first".to_owned()],
                }
            )]
        );
        // After the shift the board has them apart: `first` late now would find no
        // overlap to flee.
        let mut late_first = Vec::new();
        for n in 6..12 {
            let due = 20 * n;
            late_first.extend(first.observe(activation(t0, due, 3, 6)));
            assert_eq!(second.observe(activation(t0, due + moved, 0, 6)), None);
        }
        assert_eq!(late_first, []);
        drop(second);
        assert_eq!(board.places().len(), 1, "a dropped seat leaves the board");
    }

    #[test]
    fn a_long_wait_for_the_cpu_is_a_peak_and_components_with_other_periods_are_not_rivals() {
        let board = Board::new();
        let config = EqualizeConfig {
            window: 2,
            peaks: 2,
            hold_periods: 0,
            ..EqualizeConfig::default()
        };
        let mut other = board.seat("other", config);
        let mut me = board.seat("me", config);
        let t0 = Instant::now();
        let mut other_period = activation(t0, 0, 0, 5);
        other_period.period = ms(30);
        assert_eq!(other.observe(other_period), None);
        let waited = activation(t0, 0, 4, 5);
        assert_eq!(me.observe(waited), None);
        // A peak twice, but the only overlapping component has another period.
        assert_eq!(me.observe(waited), None);
        // A rival with the same period. Waits within 5 % of the period are no peak...
        let mut rival = board.seat("rival", config);
        assert_eq!(rival.observe(activation(t0, 0, 0, 5)), None);
        let short_wait = activation(t0, 0, 1, 5);
        assert_eq!(me.observe(short_wait), None);
        assert_eq!(me.observe(short_wait), None);
        // ... but two longer waits for the CPU make `me` move away from it, not from
        // `other`.
        assert_eq!(me.observe(waited), None);
        let shift = me.observe(waited).expect("a shift");
        assert_eq!(shift.away_from, ["rival"]);
        assert_eq!(shift.delay, ms(10));
    }

    #[test]
    fn a_rival_that_stopped_its_periodic_sections_is_no_rival() {
        let board = Board::new();
        let config = EqualizeConfig {
            window: 2,
            peaks: 2,
            hold_periods: 0,
            ..EqualizeConfig::default()
        };
        let mut gone = board.seat("gone", config);
        let mut me = board.seat("me", config);
        let t0 = Instant::now();
        assert_eq!(gone.observe(activation(t0, 0, 0, 6)), None);
        // Three periods later `gone` has not run again: waits find nobody to flee.
        assert_eq!(me.observe(activation(t0, 60, 5, 6)), None);
        assert_eq!(me.observe(activation(t0, 80, 5, 6)), None);
        // It runs again, in phase: now it is a rival.
        assert_eq!(gone.observe(activation(t0, 100, 0, 6)), None);
        assert_eq!(me.observe(activation(t0, 100, 5, 6)), None);
        let shift = me.observe(activation(t0, 120, 5, 6)).expect("a shift");
        assert_eq!(shift.away_from, ["gone"]);
    }

    #[test]
    fn odd_settings_do_not_panic() {
        let board = Board::new();
        let mut seat = board.seat(
            "odd",
            EqualizeConfig {
                late_share: f64::NAN,
                window: 0,
                peaks: 0,
                ..EqualizeConfig::default()
            },
        );
        let t0 = Instant::now();
        assert_eq!(seat.observe(activation(t0, 0, 5, 6)), None, "alone");
        assert_eq!(
            place(Duration::ZERO, ms(1), &[(ms(0), ms(1))]),
            None,
            "a zero period"
        );
    }

    #[test]
    fn a_thread_reads_its_own_cpu_time() {
        let mut stats = ThreadStats::of_current_thread();
        assert_eq!(stats.since_last(), None, "nothing to compare with yet");
        let started = cpu_time::ThreadTime::now();
        while started.elapsed() < ms(2) {
            std::hint::spin_loop();
        }
        let (cpu, waited) = stats.since_last().expect("readable");
        assert!(cpu >= ms(2), "{cpu:?}");
        #[cfg(target_os = "linux")]
        assert!(waited.is_some(), "Linux tells the run-queue wait");
        let _ = waited;
    }

    #[test]
    fn phases_are_taken_modulo_the_period_in_both_directions() {
        let t0 = Instant::now() + ms(1000);
        assert_eq!(phase(t0 + ms(45), t0, ms(20)), ms(5));
        assert_eq!(phase(t0 - ms(5), t0, ms(20)), ms(15));
        assert_eq!(phase(t0 - ms(40), t0, ms(20)), ms(0));
        assert!(overlaps(ms(18), ms(4), ms(0), ms(1), ms(20)), "wraps");
        assert!(!overlaps(ms(2), ms(4), ms(6), ms(4), ms(20)), "touching");
    }
}
