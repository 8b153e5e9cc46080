//! Activation lateness of a 1 kHz periodic section against a bare sleep-to-deadline
//! loop on its own thread. Lateness is the time from a deadline to the start of the
//! code that runs for it.
//!
//! The component's deadlines are `entry + k * period` (absolute, no drift): its
//! periodic section knows the time since its state was entered
//! (`Context::in_state_for`) and counts its activations. The baseline sleeps with
//! `std::thread::sleep` until `start + k * period` and measures the same way. Both
//! re-anchor after a miss the same way (one period after the late activation ends),
//! and misses are counted. Goal (issue 3, item 8): p99 <= 1.2x the baseline.
//!
//! `cargo bench -p coolbot --bench periodic` (add `-- --quick` for a smoke run).

#[macro_use]
mod common;

use std::time::{Duration, Instant};

use coolbot::{Component, PeriodicSpec, PortSet, Section, System};
use crossbeam_channel::{Sender, bounded};

use common::{Figure, Glue, Goal, Mode, Samples, Table};

const PERIOD: Duration = Duration::from_millis(1);
const ROUNDS: usize = 20;
/// Activations discarded at the start of each round.
const WARMUP: usize = 20;

one_state_spec! {
    static TICKER = "Ticker",
    inputs: [],
    outputs: [],
    on: [],
    periodic: Some(PeriodicSpec { period: Some(PERIOD) }),
}

/// Lateness samples and misses of one round.
type Round = (Vec<Duration>, u64);

fn ticker(count: usize, done: Sender<Round>) -> Component {
    let mut samples = Vec::with_capacity(count + WARMUP);
    let mut activations = 0u32;
    // The state's clock reading the deadlines count from (moves on a miss).
    let mut base = Duration::ZERO;
    let mut misses = 0;
    let mut done = Some(done);
    let body = Box::new(move |section: Section, cx: &mut coolbot::Context| {
        if section != Section::Periodic || done.is_none() {
            return Ok(());
        }
        let now = cx.in_state_for();
        activations += 1;
        let deadline = base + PERIOD * activations;
        let late = now.saturating_sub(deadline);
        samples.push(late);
        if late >= PERIOD {
            // The runtime re-anchors one period after this section ends.
            misses += 1;
            base = cx.in_state_for();
            activations = 0;
        }
        if samples.len() >= count + WARMUP
            && let Some(done) = done.take()
        {
            let _ = done.send((samples.split_off(WARMUP), misses));
        }
        Ok(())
    });
    Component::new("ticker", Glue::boxed(&TICKER, body), PortSet::new())
}

fn project_round(count: usize) -> Round {
    let (done, rounds) = bounded(1);
    let mut system = System::new();
    let handle = system.add(ticker(count, done)).expect("add");
    system.run_all().expect("run");
    let round = common::expect(&rounds, Duration::from_secs(60), "ticker");
    let runtime_misses = handle.snapshot().missed_deadlines;
    assert!(system.shutdown().clean());
    assert!(
        runtime_misses >= round.1,
        "the runtime counted {runtime_misses} misses, the section saw {}",
        round.1
    );
    round
}

fn baseline_round(count: usize) -> Round {
    std::thread::spawn(move || {
        let mut samples = Vec::with_capacity(count + WARMUP);
        let mut misses = 0;
        let mut next = Instant::now() + PERIOD;
        while samples.len() < count + WARMUP {
            let now = Instant::now();
            if next > now {
                std::thread::sleep(next - now);
            }
            let late = Instant::now().saturating_duration_since(next);
            samples.push(late);
            next += PERIOD;
            let now = Instant::now();
            if next <= now {
                misses += 1;
                next = now + PERIOD;
            }
        }
        (samples.split_off(WARMUP), misses)
    })
    .join()
    .expect("baseline thread")
}

fn main() {
    let mode = Mode::from_env();
    let per_round = mode.scale(4_000, 100) / ROUNDS;
    let mut table = Table::new("Activation lateness of a 1 kHz periodic section", mode);
    let (project, baseline) = common::alternate(
        ROUNDS,
        || vec![project_round(per_round)],
        || vec![baseline_round(per_round)],
    );
    let misses = |rounds: &[Round]| rounds.iter().map(|r| r.1).sum::<u64>();
    let (project_misses, baseline_misses) = (misses(&project), misses(&baseline));
    let pool = |rounds: Vec<Round>| Samples::new(rounds.into_iter().flat_map(|r| r.0).collect());
    let (project, baseline) = (pool(project), pool(baseline));
    table.row(
        "lateness p50",
        Figure::Time(project.p50()),
        Figure::Time(baseline.p50()),
        Goal::None,
    );
    table.row(
        "lateness p99",
        Figure::Time(project.p99()),
        Figure::Time(baseline.p99()),
        Goal::AtMost(1.2),
    );
    table.note(&format!(
        "{} activations per side; missed deadlines: project {project_misses}, baseline \
         {baseline_misses}; max lateness project {:?}, baseline {:?}",
        project.len(),
        project.max(),
        baseline.max()
    ));
    table.print();
}
