//! Activation lateness of a 1 kHz periodic section against a bare sleep-to-deadline
//! loop on its own thread. Lateness is the time from a deadline to the start of the
//! code that runs for it.
//!
//! The component's deadlines are `entry + k * period` (absolute, no drift): its
//! periodic section knows the time since its state was entered
//! (`Context::in_state_for`) and counts its activations. Two bare threads run beside
//! it, **at the same time** (so that a burst of other load on the machine hits all
//! three alike), their deadlines offset by a third and two thirds of a period from the
//! component's (so that they do not wake together):
//!
//! - the baseline (the goal's): the same thread setup as a component thread (timer
//!   slack set to the runtime's `TIMER_SLACK`, 1 us, with `PR_SET_TIMERSLACK`) and the
//!   same sleep primitive as the component's doorbell (`std::thread::park_timeout`
//!   until the deadline, in a loop: a futex wait with a timeout);
//! - a classic loop, for reference: `std::thread::sleep` (`nanosleep`) with the
//!   default timer slack (50 us), what a bare thread gets without setup.
//!
//! All re-anchor after a miss the same way (one period after the late activation
//! ends), and misses are counted. Goal: p99 <= 1.2x the baseline.
//!
//! `cargo bench -p coolbot --bench periodic` (add `-- --quick` for a smoke run).

#[macro_use]
mod common;

use std::time::{Duration, Instant};

use coolbot::{Component, OsPriority, PeriodicSpec, PortSet, Section, System, TimingSpec};
use crossbeam_channel::{Receiver, Sender, bounded};

use common::{Figure, Glue, Goal, Mode, Samples, Table};

const PERIOD: Duration = Duration::from_millis(1);
const ROUNDS: usize = 20;
/// Activations discarded at the start of each round.
const WARMUP: usize = 20;
/// The priority of the second measurement.
const PRIORITY: u8 = 10;
/// The runtime's timer slack for component threads (`runtime/src/thread.rs`).
const TIMER_SLACK_NS: u64 = 1_000;

one_state_spec! {
    static TICKER = "Ticker",
    inputs: [],
    outputs: [],
    on: [],
    periodic: Some(PeriodicSpec { period: Some(PERIOD) }),
}

/// Lateness samples, misses and the thread's CPU time of one round.
type Round = (Vec<Duration>, u64, Duration);

/// The component; its first activation sends the instant its deadlines count from on
/// `anchors` (once per bare thread).
fn ticker(count: usize, done: Sender<Round>, anchors: Sender<Instant>) -> Component {
    let mut samples = Vec::with_capacity(count + WARMUP);
    let mut activations = 0u32;
    // The state's clock reading the deadlines count from (moves on a miss).
    let mut base = Duration::ZERO;
    let mut misses = 0;
    let mut done = Some(done);
    let mut anchors = Some(anchors);
    let body = Box::new(move |section: Section, cx: &mut coolbot::Context| {
        if section != Section::Periodic || done.is_none() {
            return Ok(());
        }
        let now = cx.in_state_for();
        if let Some(anchors) = anchors.take() {
            let entered = Instant::now() - now;
            let _ = anchors.send(entered);
            let _ = anchors.send(entered);
        }
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
            let cpu = cpu_time::ThreadTime::now().as_duration();
            let _ = done.send((samples.split_off(WARMUP), misses, cpu));
        }
        Ok(())
    });
    Component::new("ticker", Glue::boxed(&TICKER, body), PortSet::new())
}

/// How a bare thread waits for its deadline.
#[derive(Debug, Clone, Copy)]
enum Sleep {
    /// As a component thread: 1 us timer slack, `park_timeout` until the deadline.
    LikeComponent,
    /// `std::thread::sleep`, default timer slack.
    Classic,
}

/// A bare sleep-to-deadline loop; its deadlines are `anchor + offset + k * period`.
fn bare_loop(
    count: usize,
    sleep: Sleep,
    anchor: Receiver<Instant>,
    offset: Duration,
    priority: u8,
) -> Round {
    if matches!(sleep, Sleep::LikeComponent) {
        rustix::thread::set_current_timer_slack(std::num::NonZeroU64::new(TIMER_SLACK_NS))
            .expect("timer slack");
        if priority > 0 {
            // As the runtime does for `priority N`: SCHED_RR at N (may be refused; the
            // rows are printed only if the component's was applied).
            let _ = thread_priority::set_thread_priority_and_policy(
                thread_priority::thread_native_id(),
                thread_priority::ThreadPriority::Crossplatform(
                    priority.try_into().expect("priority in range"),
                ),
                thread_priority::ThreadSchedulePolicy::Realtime(
                    thread_priority::RealtimeThreadSchedulePolicy::RoundRobin,
                ),
            );
        }
    }
    let anchor = anchor.recv().expect("the component's anchor");
    let mut samples = Vec::with_capacity(count + WARMUP);
    let mut misses = 0;
    let mut next = anchor + offset;
    while next <= Instant::now() {
        next += PERIOD;
    }
    while samples.len() < count + WARMUP {
        match sleep {
            Sleep::LikeComponent => loop {
                let now = Instant::now();
                if now >= next {
                    break;
                }
                std::thread::park_timeout(next - now);
            },
            Sleep::Classic => {
                let now = Instant::now();
                if next > now {
                    std::thread::sleep(next - now);
                }
            }
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
    let cpu = cpu_time::ThreadTime::now().as_duration();
    (samples.split_off(WARMUP), misses, cpu)
}

/// One round: the component and both bare loops at once; with a `priority`, the
/// component's timing block asks for it and the baseline thread gets the same
/// scheduling (the classic loop stays a normal thread). Also returns how the
/// component's priority was applied.
fn round(count: usize, priority: u8) -> ([Round; 3], OsPriority) {
    let (anchor_out, anchor_in) = bounded(2);
    let spawn = |sleep: Sleep, offset: Duration| {
        let anchor = anchor_in.clone();
        std::thread::spawn(move || bare_loop(count, sleep, anchor, offset, priority))
    };
    let baseline = spawn(Sleep::LikeComponent, PERIOD / 3);
    let classic = spawn(Sleep::Classic, PERIOD * 2 / 3);
    let (done, rounds) = bounded(1);
    let mut system = System::new();
    let timing = TimingSpec {
        priority: i32::from(priority),
        ..TICKER.timing
    };
    let component = ticker(count, done, anchor_out).with_timing(timing);
    let handle = system.add(component).expect("add");
    system.run_all().expect("run");
    let project = common::expect(&rounds, Duration::from_secs(60), "ticker");
    let snapshot = handle.snapshot();
    let runtime_misses = snapshot.missed_deadlines;
    assert!(system.shutdown().clean());
    assert!(
        runtime_misses >= project.1,
        "the runtime counted {runtime_misses} misses, the section saw {}",
        project.1
    );
    let baseline = baseline.join().expect("baseline thread");
    let classic = classic.join().expect("classic thread");
    ([project, baseline, classic], snapshot.os_priority)
}

/// Each side's pooled samples, misses and CPU time per activation.
type Side = (Samples, u64, Duration);

/// `rounds` rounds of `count` activations per side.
fn measure(rounds: usize, count: usize, priority: u8) -> ([Side; 3], OsPriority) {
    let mut sides: [Vec<Round>; 3] = Default::default();
    let mut applied = OsPriority::Inherited;
    for _ in 0..rounds {
        let (round, os_priority) = round(count, priority);
        applied = os_priority;
        for (side, round) in sides.iter_mut().zip(round) {
            side.push(round);
        }
    }
    let sides = sides.map(|rounds| {
        let misses = rounds.iter().map(|r| r.1).sum::<u64>();
        let cpu = rounds.iter().map(|r| r.2).sum::<Duration>();
        let samples = Samples::new(rounds.into_iter().flat_map(|r| r.0).collect());
        // Thread CPU time per activation, warm-up and start-up included.
        let per = cpu / u32::try_from(samples.len()).unwrap_or(u32::MAX).max(1);
        (samples, misses, per)
    });
    (sides, applied)
}

fn main() {
    let mode = Mode::from_env();
    let per_round = mode.scale(10_000, 100) / ROUNDS;
    let mut table = Table::new("Activation lateness of a 1 kHz periodic section", mode);
    let ([project, baseline, classic], _) = measure(ROUNDS, per_round, 0);
    table.row(
        "lateness p50",
        Figure::Time(project.0.p50()),
        Figure::Time(baseline.0.p50()),
        Goal::None,
    );
    table.row(
        "lateness p99",
        Figure::Time(project.0.p99()),
        Figure::Time(baseline.0.p99()),
        Goal::AtMost(1.2),
    );
    table.row(
        "lateness p50, against a classic loop",
        Figure::Time(project.0.p50()),
        Figure::Time(classic.0.p50()),
        Goal::None,
    );
    table.row(
        "lateness p99, against a classic loop",
        Figure::Time(project.0.p99()),
        Figure::Time(classic.0.p99()),
        Goal::None,
    );
    table.note(&format!(
        "{} activations per side, the three sides at once; missed deadlines: project {}, \
         baseline {}, classic {}; max lateness project {:?}, baseline {:?}, classic {:?}; \
         thread CPU time per activation project {:?}, baseline {:?}, classic {:?}",
        project.0.len(),
        project.1,
        baseline.1,
        classic.1,
        project.0.max(),
        baseline.0.max(),
        classic.0.max(),
        project.2,
        baseline.2,
        classic.2
    ));

    // The same with `priority 10` (SCHED_RR where permitted) on the component and the
    // baseline thread: what applying the priority buys on a loaded machine.
    let ([project, baseline, classic], applied) = measure(ROUNDS / 2, per_round, PRIORITY);
    if applied == OsPriority::RoundRobin(i32::from(PRIORITY)) {
        table.row(
            &format!("priority {PRIORITY}: lateness p50"),
            Figure::Time(project.0.p50()),
            Figure::Time(baseline.0.p50()),
            Goal::None,
        );
        table.row(
            &format!("priority {PRIORITY}: lateness p99"),
            Figure::Time(project.0.p99()),
            Figure::Time(baseline.0.p99()),
            Goal::None,
        );
        table.row(
            &format!("priority {PRIORITY}: lateness p99, against a classic loop (normal)"),
            Figure::Time(project.0.p99()),
            Figure::Time(classic.0.p99()),
            Goal::None,
        );
        table.note(&format!(
            "priority {PRIORITY} (SCHED_RR, component and baseline): {} activations per side; \
             missed deadlines: project {}, baseline {}, classic {}",
            project.0.len(),
            project.1,
            baseline.1,
            classic.1
        ));
    } else {
        table.note(&format!(
            "priority {PRIORITY} rows skipped: the component's priority was {applied:?}"
        ));
    }
    table.print();
}
