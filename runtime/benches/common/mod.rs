//! The measurement kit shared by the runtime benchmarks: run modes, per-sample
//! statistics, the result table, the hand-written component glue, and a chain of
//! components at 1 kHz with its baselines' parts (`chain`).
//!
//! Every benchmark measures the runtime and its baseline in the same process,
//! alternating rounds of each so that a change in machine load hits both sides, and
//! prints one table row per figure: project, baseline, ratio, goal, pass or miss.

#![allow(
    dead_code,
    unused_macros,
    reason = "each bench binary includes this module and uses a different part of it"
)]

use std::time::{Duration, Instant};

use coolbot::{Automaton, Context, Section, SectionResult, Spec};

/// How much work a run does.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// The figures of `docs/performance.md`.
    Full,
    /// A smoke run: a tenth of the samples (`--quick` or `COOLBOT_BENCH_QUICK=1`).
    Quick,
}

impl Mode {
    /// From the command line (`cargo bench ... -- --quick`) or the environment.
    pub fn from_env() -> Mode {
        let flag = std::env::args().any(|arg| arg == "--quick");
        let env = std::env::var("COOLBOT_BENCH_QUICK").is_ok_and(|v| !v.is_empty() && v != "0");
        if flag || env { Mode::Quick } else { Mode::Full }
    }

    /// `full` samples in a full run, a tenth (at least `floor`) in a quick one.
    pub fn scale(self, full: usize, floor: usize) -> usize {
        match self {
            Mode::Full => full,
            Mode::Quick => (full / 10).max(floor),
        }
    }

    /// The name printed in the header.
    pub fn name(self) -> &'static str {
        match self {
            Mode::Full => "full",
            Mode::Quick => "quick",
        }
    }
}

/// Sorted per-sample durations.
#[derive(Debug, Clone)]
pub struct Samples {
    sorted: Vec<Duration>,
}

impl Samples {
    /// Sort `samples` (at least one).
    pub fn new(mut samples: Vec<Duration>) -> Samples {
        assert!(!samples.is_empty(), "a measurement needs samples");
        samples.sort_unstable();
        Samples { sorted: samples }
    }

    /// The `q` quantile (0.0 to 1.0), nearest rank.
    pub fn quantile(&self, q: f64) -> Duration {
        let rank = (q * self.sorted.len() as f64).ceil() as usize;
        self.sorted[rank.clamp(1, self.sorted.len()) - 1]
    }

    /// The median.
    pub fn p50(&self) -> Duration {
        self.quantile(0.50)
    }

    /// The 99th percentile.
    pub fn p99(&self) -> Duration {
        self.quantile(0.99)
    }

    /// The largest sample.
    pub fn max(&self) -> Duration {
        self.sorted[self.sorted.len() - 1]
    }

    /// How many samples.
    pub fn len(&self) -> usize {
        self.sorted.len()
    }
}

/// What a figure must achieve, as the ratio project / baseline.
#[derive(Debug, Clone, Copy)]
pub enum Goal {
    /// Lower is better: the ratio must be at most this (latencies, times).
    AtMost(f64),
    /// Higher is better: the ratio must be at least this (throughputs).
    AtLeast(f64),
    /// Reported only.
    None,
}

impl Goal {
    fn text(self) -> String {
        match self {
            Goal::AtMost(x) => format!("<= {x}x"),
            Goal::AtLeast(x) => format!(">= {x}x"),
            Goal::None => "-".to_owned(),
        }
    }

    fn verdict(self, ratio: f64) -> &'static str {
        match self {
            Goal::AtMost(x) if ratio <= x => "pass",
            Goal::AtLeast(x) if ratio >= x => "pass",
            Goal::None => "info",
            _ => "MISS",
        }
    }
}

/// A figure's value, with its unit.
#[derive(Debug, Clone, Copy)]
pub enum Figure {
    /// A duration (printed in µs).
    Time(Duration),
    /// A rate (printed in M/s).
    Rate(f64),
    /// Bytes (printed in KiB).
    Bytes(f64),
}

impl Figure {
    fn value(self) -> f64 {
        match self {
            Figure::Time(d) => d.as_secs_f64(),
            Figure::Rate(r) | Figure::Bytes(r) => r,
        }
    }

    fn text(self) -> String {
        match self {
            Figure::Time(d) if d >= Duration::from_millis(10) => {
                format!("{:.1} ms", d.as_secs_f64() * 1e3)
            }
            Figure::Time(d) if d >= Duration::from_micros(10) => {
                format!("{:.1} us", d.as_secs_f64() * 1e6)
            }
            Figure::Time(d) => format!("{:.2} us", d.as_secs_f64() * 1e6),
            Figure::Rate(r) => format!("{:.2} M/s", r / 1e6),
            Figure::Bytes(b) => format!("{:.1} KiB", b / 1024.0),
        }
    }
}

/// The result table of one benchmark binary.
pub struct Table {
    title: String,
    rows: Vec<[String; 6]>,
    misses: usize,
}

impl Table {
    /// A table headed by `title` (the run mode is added).
    pub fn new(title: &str, mode: Mode) -> Table {
        Table {
            title: format!("{title} ({} run)", mode.name()),
            rows: Vec::new(),
            misses: 0,
        }
    }

    /// One figure: project against baseline.
    pub fn row(&mut self, name: &str, project: Figure, baseline: Figure, goal: Goal) {
        let ratio = project.value() / baseline.value();
        let verdict = goal.verdict(ratio);
        if verdict == "MISS" {
            self.misses += 1;
        }
        self.rows.push([
            name.to_owned(),
            project.text(),
            baseline.text(),
            format!("{ratio:.2}x"),
            goal.text(),
            verdict.to_owned(),
        ]);
        // Print as we go, so a long run shows progress.
        println!(
            "  {name}: project {} baseline {} ratio {ratio:.2}x goal {} {verdict}",
            project.text(),
            baseline.text(),
            goal.text()
        );
    }

    /// A free-form line under the table (counters, checks).
    pub fn note(&mut self, text: &str) {
        println!("  note: {text}");
        self.rows.push([
            format!("note: {text}"),
            String::new(),
            String::new(),
            String::new(),
            String::new(),
            String::new(),
        ]);
    }

    /// Print the table as Markdown.
    pub fn print(&self) {
        println!();
        println!("### {}", self.title);
        println!();
        println!("| figure | project | baseline | ratio | goal | result |");
        println!("|---|---|---|---|---|---|");
        for row in &self.rows {
            if row[0].starts_with("note: ") {
                continue;
            }
            println!("| {} |", row.join(" | "));
        }
        for row in &self.rows {
            if let Some(note) = row[0].strip_prefix("note: ") {
                println!("\n{note}");
            }
        }
        println!();
        println!("{} goal(s) missed", self.misses);
    }
}

/// Alternate `rounds` rounds of `project` and `baseline` (baseline first), each round
/// returning samples, and pool them per side.
pub fn alternate<T>(
    rounds: usize,
    mut project: impl FnMut() -> Vec<T>,
    mut baseline: impl FnMut() -> Vec<T>,
) -> (Vec<T>, Vec<T>) {
    let mut p = Vec::new();
    let mut b = Vec::new();
    for _ in 0..rounds {
        b.extend(baseline());
        p.extend(project());
    }
    (p, b)
}

/// Wait on `done` for at most `limit`, panicking with `what` if nothing arrives (a
/// benchmark that hangs is a bug worth a loud message).
pub fn expect<T>(done: &crossbeam_channel::Receiver<T>, limit: Duration, what: &str) -> T {
    match done.recv_timeout(limit) {
        Ok(value) => value,
        Err(_) => panic!("benchmark stalled: {what} did not finish within {limit:?}"),
    }
}

/// Resident set size of this process, in bytes (Linux `/proc/self/statm`).
pub fn rss_bytes() -> Option<u64> {
    let statm = std::fs::read_to_string("/proc/self/statm").ok()?;
    let resident: u64 = statm.split_whitespace().nth(1)?.parse().ok()?;
    Some(resident * 4096)
}

/// Elapsed time of `f`.
pub fn time<R>(f: impl FnOnce() -> R) -> (Duration, R) {
    let started = Instant::now();
    let result = f();
    (started.elapsed(), result)
}

/// What a hand-written component does in its sections: the body `coolc` would have
/// generated a glue for (one user state per spec in these benchmarks, so the state
/// index is not passed on).
pub type Body = Box<dyn FnMut(Section, &mut Context) -> SectionResult + Send>;

/// The hand-written equivalent of the glue `coolc` generates: it dispatches
/// `section` to the body and has no variables, exceptions or pull outputs.
pub struct Glue {
    spec: &'static Spec,
    body: Body,
}

impl Glue {
    /// A component of shape `spec` whose sections run `body`.
    pub fn boxed(spec: &'static Spec, body: Body) -> Box<dyn Automaton> {
        Box::new(Glue { spec, body })
    }
}

impl Automaton for Glue {
    fn spec(&self) -> &'static Spec {
        self.spec
    }

    fn section(&mut self, _state: usize, section: Section, cx: &mut Context) -> SectionResult {
        (self.body)(section, cx)
    }
}

/// Define a `static` [`Spec`] with one user state `work`. `on` is the input index whose
/// arrivals re-enter `work` (running its entry section again), `periodic` the state's
/// period. Inputs and outputs are `(name, kind)` lists.
macro_rules! one_state_spec {
    (
        $vis:vis static $name:ident = $type_name:literal,
        inputs: [$(($in_name:literal, $in_kind:expr)),* $(,)?],
        outputs: [$(($out_name:literal, $out_kind:expr)),* $(,)?],
        on: [$($on_port:literal),* $(,)?],
        periodic: $periodic:expr $(,)?
    ) => {
        $vis static $name: coolbot::Spec = coolbot::Spec::new($type_name, "benchmark component")
            .with_states(&[coolbot::StateSpec {
                periodic: $periodic,
                ..coolbot::StateSpec::new("work")
            }
            .with_entry()
            .with_on(&[$(coolbot::OnSpec { port: $on_port, target: 0 }),*])])
            .with_inputs(&[$(coolbot::InputSpec::new($in_name, $in_kind, "bench")),*])
            .with_outputs(&[$(coolbot::OutputSpec::new($out_name, $out_kind, "bench")),*]);
    };
}

pub mod chain;
