//! End-to-end latency of an 8-hop chain at 1 kHz: a periodic source component stamps a
//! packet every millisecond and sends it through 7 relay components to a sink
//! component (8 fifo connections, 9 components), against the same chain of bare
//! threads on crossbeam-channel `bounded(16)` channels, the source sleeping to absolute
//! deadlines. The figure is the time from the stamp to the sink's section reading it.
//! Goal: p50 <= 1.1x the baseline.
//!
//! `cargo bench -p coolbot --bench chain` (add `-- --quick` for a smoke run).

#[macro_use]
mod common;

use std::time::{Duration, Instant};

use crossbeam_channel::bounded;

use common::chain::{self, CAPACITY, Collector, Stages};
use common::{Figure, Goal, Mode, Samples, Table};

const HOPS: usize = 8;
const ROUNDS: usize = 20;

/// The stamp alone, passed on as it is.
#[derive(Clone)]
struct Stamp;

impl Stages for Stamp {
    type Packet = Instant;

    fn first(&self) -> Instant {
        Instant::now()
    }

    fn pass(&self, stamp: Instant) -> Instant {
        stamp
    }

    fn last(&self, stamp: Instant) -> Instant {
        stamp
    }
}

fn baseline_round(count: usize) -> Vec<Duration> {
    let (first, mut upstream) = bounded::<Instant>(CAPACITY);
    let mut relays = Vec::new();
    for _ in 1..HOPS {
        let (tx, rx) = bounded::<Instant>(CAPACITY);
        let input = std::mem::replace(&mut upstream, rx);
        relays.push(std::thread::spawn(move || {
            for stamp in input.iter() {
                if tx.send(stamp).is_err() {
                    break;
                }
            }
        }));
    }
    let sink = std::thread::spawn(move || {
        let mut samples = Collector::new(count);
        for stamp in upstream.iter() {
            if samples.push(stamp.elapsed()) {
                break;
            }
        }
        samples.take()
    });
    chain::paced(|| !sink.is_finished() && first.send(Instant::now()).is_ok());
    drop(first);
    let samples = sink.join().expect("sink thread");
    for relay in relays {
        relay.join().expect("relay thread");
    }
    samples
}

fn main() {
    let mode = Mode::from_env();
    let per_round = mode.scale(4_000, 100) / ROUNDS;
    let mut table = Table::new("8-hop chain at 1 kHz, end-to-end latency", mode);
    let (project, baseline) = common::alternate(
        ROUNDS,
        || chain::components_round(HOPS, per_round, &Stamp, None),
        || baseline_round(per_round),
    );
    let (project, baseline) = (Samples::new(project), Samples::new(baseline));
    table.row(
        "end-to-end p50",
        Figure::Time(project.p50()),
        Figure::Time(baseline.p50()),
        Goal::AtMost(1.1),
    );
    table.row(
        "end-to-end p99",
        Figure::Time(project.p99()),
        Figure::Time(baseline.p99()),
        Goal::None,
    );
    table.note(&format!(
        "{} packets per side; max project {:?}, baseline {:?}",
        project.len(),
        project.max(),
        baseline.max()
    ));
    table.print();
}
