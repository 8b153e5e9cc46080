//! An 8-stage chain at 1 kHz four ways, in one run: the 8 stages as components in
//! one execution group; a hand-written thread calling the same 8 stage functions in
//! order with the same packets, carried between stages by crossbeam channels as the
//! components' fifo connections carry them (the baseline), and handed on by value
//! (reported); and the same components threaded as by default, one thread each. Each stage does about 0.5 us of work (a calibrated
//! loop) on the packet's value and sends the packet on (a fifo connection); the first
//! stage is periodic and stamps the packet, the last one reads the stamp after its
//! work. The figure is the time from the stamp to the end of the last stage's work.
//! Goals: the group's p50 <= 1.5x and p99 <= 2x the hand loop's over channels; the
//! threaded chain at least 20x the group's (end to end, p50); the overhead per member
//! per cycle, (group p50 - hand loop p50) / 8, at most 150 ns. Every goal is printed
//! pass or miss.
//!
//! `cargo bench -p coolbot --bench group` (add `-- --quick` for a smoke run).

#[macro_use]
mod common;

use std::hint::black_box;
use std::time::{Duration, Instant};

use crossbeam_channel::bounded;

use common::chain::{self, CAPACITY, Collector, PERIOD, Stages};
use common::{Figure, Goal, Mode, Samples, Table};

const STAGES: usize = 8;
const ROUNDS: usize = 4;
/// The work of one stage.
const WORK: Duration = Duration::from_nanos(500);
/// The goal for the group's overhead per member per cycle.
const OVERHEAD_GOAL: Duration = Duration::from_nanos(150);

/// What travels along the chain: the first stage's stamp and the value each stage
/// works on.
type Packet = (Instant, u64);

/// One stage's work: `rounds` rounds of a mixing function.
fn work(value: u64, rounds: u32) -> u64 {
    let mut x = value;
    for _ in 0..rounds {
        x = black_box(x.wrapping_mul(0x9E37_79B9_7F4A_7C15).rotate_left(17) ^ 0x5bd1);
    }
    x
}

/// Every stage does `work` on the packet's value (`rounds` rounds).
#[derive(Clone, Copy)]
struct Working {
    rounds: u32,
}

impl Stages for Working {
    type Packet = Packet;

    fn first(&self) -> Packet {
        let stamp = Instant::now();
        (stamp, work(1, self.rounds))
    }

    fn pass(&self, (stamp, value): Packet) -> Packet {
        (stamp, work(value, self.rounds))
    }

    fn last(&self, (stamp, value): Packet) -> Instant {
        black_box(work(value, self.rounds));
        stamp
    }
}

/// How many rounds of `work` take about `WORK`, measured as the chain runs them: 8
/// calls in a row right after sleeping a period (after a sleep the core runs the same
/// loop markedly slower than in a busy loop, up to twice on a shared virtual machine;
/// calibrated in a busy loop, the stages took about 0.9 us each).
fn calibrate() -> u32 {
    let mut rounds = 300u32;
    for _ in 0..3 {
        let mut took = Vec::with_capacity(100);
        for _ in 0..100 {
            std::thread::sleep(PERIOD);
            let started = Instant::now();
            let mut x = 1;
            for _ in 0..STAGES {
                x = work(x, rounds);
            }
            black_box(x);
            took.push(started.elapsed() / STAGES as u32);
        }
        let per_call = Samples::new(took).p50();
        rounds = ((u128::from(rounds) * WORK.as_nanos()) / per_call.as_nanos().max(1)) as u32;
        rounds = rounds.max(1);
    }
    rounds
}

/// The chain as components, in one group (`grouped`) or one thread each.
fn components_round(count: usize, rounds: u32, grouped: bool) -> Vec<Duration> {
    let group = grouped.then_some("chain");
    chain::components_round(STAGES - 1, count, &Working { rounds }, group)
}

/// The hand loop: one thread sleeping to absolute deadlines, calling the 8 stage
/// functions in order. `queued`: each packet goes from one stage to the next through
/// a crossbeam `bounded(CAPACITY)` channel, as the components' fifo connections carry
/// it (the same packets, the same connections); otherwise it is handed on by value.
fn hand_round(count: usize, rounds: u32, queued: bool) -> Vec<Duration> {
    let links: Vec<_> = (1..STAGES).map(|_| bounded::<Packet>(CAPACITY)).collect();
    let mut samples = Collector::new(count);
    chain::paced(|| {
        let mut packet: Packet = (Instant::now(), work(1, rounds));
        for (sender, receiver) in &links {
            if queued {
                sender.try_send(packet).expect("room in the link");
                // A stage drains its input, as the components' stages do.
                while let Ok((stamp, value)) = receiver.try_recv() {
                    packet = (stamp, work(value, rounds));
                }
            } else {
                packet = black_box((packet.0, work(packet.1, rounds)));
            }
        }
        !samples.push(packet.0.elapsed())
    });
    samples.take()
}

fn main() {
    let mode = Mode::from_env();
    let per_round = mode.scale(4_000, 100) / ROUNDS;
    let rounds = calibrate();
    let mut table = Table::new(
        "8-stage chain at 1 kHz: one execution group against hand loops and one thread per stage",
        mode,
    );
    let (mut group, mut hand, mut queued, mut threaded) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for _ in 0..ROUNDS {
        hand.extend(hand_round(per_round, rounds, false));
        queued.extend(hand_round(per_round, rounds, true));
        group.extend(components_round(per_round, rounds, true));
        threaded.extend(components_round(per_round, rounds, false));
    }
    let (group, hand, queued, threaded) = (
        Samples::new(group),
        Samples::new(hand),
        Samples::new(queued),
        Samples::new(threaded),
    );
    table.row(
        "group vs hand loop over channels, p50",
        Figure::Time(group.p50()),
        Figure::Time(queued.p50()),
        Goal::AtMost(1.5),
    );
    table.row(
        "group vs hand loop over channels, p99",
        Figure::Time(group.p99()),
        Figure::Time(queued.p99()),
        Goal::AtMost(2.0),
    );
    table.row(
        "group vs hand loop by value, p50",
        Figure::Time(group.p50()),
        Figure::Time(hand.p50()),
        Goal::None,
    );
    table.row(
        "group vs hand loop by value, p99",
        Figure::Time(group.p99()),
        Figure::Time(hand.p99()),
        Goal::None,
    );
    table.row(
        "threaded vs group, p50",
        Figure::Time(threaded.p50()),
        Figure::Time(group.p50()),
        Goal::AtLeast(20.0),
    );
    table.row(
        "threaded vs group, p99",
        Figure::Time(threaded.p99()),
        Figure::Time(group.p99()),
        Goal::None,
    );
    let per_member = |a: Duration, b: Duration| a.saturating_sub(b) / STAGES as u32;
    table.row(
        "overhead per member per cycle over channels, p50",
        Figure::Time(per_member(group.p50(), queued.p50())),
        Figure::Time(OVERHEAD_GOAL),
        Goal::AtMost(1.0),
    );
    table.row(
        "overhead per member per cycle by value, p50",
        Figure::Time(per_member(group.p50(), hand.p50())),
        Figure::Time(OVERHEAD_GOAL),
        Goal::None,
    );
    table.note(&format!(
        "overhead per member per cycle: (group - hand loop) / {STAGES}, against its goal \
         {OVERHEAD_GOAL:?} as the baseline; p99 over channels {:?}, by value {:?}; {} work \
         rounds a stage (~{WORK:?} after a sleep; {:?} a stage in the hand loop by value, \
         p50); {} packets per side; max group {:?}, hand loop over channels {:?}, by value \
         {:?}, threaded {:?}",
        per_member(group.p99(), queued.p99()),
        per_member(group.p99(), hand.p99()),
        rounds,
        hand.p50() / STAGES as u32,
        group.len(),
        group.max(),
        queued.max(),
        hand.max(),
        threaded.max()
    ));
    table.print();
}
