//! Throughput of 8-byte packets (`u64`) from one producer component to its consumers,
//! against crossbeam-channel `bounded(1024)` between bare threads.
//!
//! - fifo: a `fifo(1024)` input with the `block` overflow policy (like a bounded
//!   channel's `send`, nothing is lost), against one producer and one consumer thread
//!   on `bounded(1024)`. Goal >= 0.5x.
//! - last: updates delivered per second into a `last` input while its consumer keeps
//!   reading the newest one (`take_new` at every wake-up) until it has seen the final
//!   update, against the same `bounded(1024)` baseline (every packet delivered). A
//!   `last` connection keeps only the newest packet by design, so its figure is the
//!   rate of updates the consumer is kept current with. Goal >= 1.0x.
//! - poster: one poster output read by 4 consumer components, each reading the post at
//!   every wake-up until it has seen the final one; per consumer, posts per second
//!   until that consumer saw the last one, against one producer thread sending every
//!   packet to 4 consumer threads on 4 `bounded(1024)` channels. Goal >= 0.5x.
//!
//! The producer component sends its whole burst from one entry section (a burst
//! producer); every consumer re-enters its state on each arrival (`on input -> work`)
//! and reads everything available in its entry section.
//!
//! `cargo bench -p coolbot --bench throughput` (add `-- --quick` for a smoke run, or
//! `-- fifo last` for only the rows named).

#[macro_use]
mod common;

use std::time::{Duration, Instant};

use coolbot::port::{DataOut, FifoIn, LastIn, PosterIn, PosterOut};
use coolbot::{Component, InputKind, OutputKind, OverflowPolicy, PortSet, Section, System};
use crossbeam_channel::{Receiver, Sender, bounded};

use common::{Figure, Glue, Goal, Mode, Table};

const CAPACITY: usize = 1024;
const CONSUMERS: usize = 4;
const ROUNDS: usize = 5;
const LIMIT: Duration = Duration::from_secs(60);

one_state_spec! {
    static DATA_PRODUCER = "DataProducer",
    inputs: [],
    outputs: [("output", OutputKind::Data)],
    on: [],
    periodic: None,
}

one_state_spec! {
    static POSTER_PRODUCER = "PosterProducer",
    inputs: [],
    outputs: [("output", OutputKind::Poster)],
    on: [],
    periodic: None,
}

one_state_spec! {
    static FIFO_CONSUMER = "FifoConsumer",
    inputs: [("input", InputKind::Fifo { capacity: CAPACITY, policy: OverflowPolicy::Block })],
    outputs: [],
    on: [0],
    periodic: None,
}

one_state_spec! {
    static LAST_CONSUMER = "LastConsumer",
    inputs: [("input", InputKind::Last)],
    outputs: [],
    on: [0],
    periodic: None,
}

one_state_spec! {
    static POSTER_CONSUMER = "PosterConsumer",
    inputs: [("input", InputKind::Poster)],
    outputs: [],
    on: [0],
    periodic: None,
}

/// A producer sending `count` packets `0..count` from its first entry section; it
/// sends its start time on `started`.
fn producer(
    spec: &'static coolbot::Spec,
    ports: PortSet,
    send: impl Fn(u64) + Send + 'static,
    count: u64,
    started: Sender<Instant>,
) -> Component {
    let mut sent = false;
    let body = Box::new(move |section: Section, _: &mut coolbot::Context| {
        if section == Section::Entry && !sent {
            sent = true;
            let _ = started.send(Instant::now());
            for packet in 0..count {
                send(packet);
            }
        }
        Ok(())
    });
    Component::new("producer", Glue::boxed(spec, body), ports)
}

/// A consumer that takes packets with `take` at each wake-up and sends the time it got
/// packet `count - 1` on `done`, with the number of packets it took.
fn consumer(
    name: &str,
    spec: &'static coolbot::Spec,
    ports: PortSet,
    mut take: impl FnMut(&mut dyn FnMut(u64)) + Send + 'static,
    count: u64,
    done: Sender<(Instant, u64)>,
) -> Component {
    let mut taken = 0;
    let mut finished = false;
    let body = Box::new(move |section: Section, _: &mut coolbot::Context| {
        if section == Section::Entry && !finished {
            take(&mut |packet| {
                taken += 1;
                if packet == count - 1 {
                    finished = true;
                }
            });
            if finished {
                let _ = done.send((Instant::now(), taken));
            }
        }
        Ok(())
    });
    Component::new(name, Glue::boxed(spec, body), ports)
}

/// What one project round measured: packets per second per consumer, packets each
/// consumer took, packets lost.
struct Round {
    rate: f64,
    taken: u64,
    lost: u64,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Fifo,
    Last,
    Poster,
}

fn project_round(kind: Kind, count: u64) -> Round {
    let consumers = if kind == Kind::Poster { CONSUMERS } else { 1 };
    let (started_tx, started) = bounded(1);
    let (done_tx, done) = bounded(consumers);
    let mut system = System::new();
    let mut lost = Vec::new();
    // Consumers first: they must be running before the burst starts.
    for index in 0..consumers {
        let name = format!("consumer{index}");
        let component = match kind {
            Kind::Fifo => {
                let input = FifoIn::<u64>::new(CAPACITY, OverflowPolicy::Block);
                let ports = PortSet::new().input(&input);
                let reader = input.clone();
                lost.push(Box::new(move || reader.overflows()) as Box<dyn Fn() -> u64>);
                let take = move |f: &mut dyn FnMut(u64)| input.drain().for_each(f);
                consumer(&name, &FIFO_CONSUMER, ports, take, count, done_tx.clone())
            }
            Kind::Last => {
                let input = LastIn::<u64>::new();
                let ports = PortSet::new().input(&input);
                let take = move |f: &mut dyn FnMut(u64)| input.take_new().into_iter().for_each(f);
                consumer(&name, &LAST_CONSUMER, ports, take, count, done_tx.clone())
            }
            Kind::Poster => {
                let input = PosterIn::<u64>::new();
                let ports = PortSet::new().input(&input);
                let take = move |f: &mut dyn FnMut(u64)| {
                    if input.is_new() {
                        input.read().into_iter().for_each(f);
                    }
                };
                consumer(&name, &POSTER_CONSUMER, ports, take, count, done_tx.clone())
            }
        };
        system.add(component).expect("add consumer");
    }
    let producer = match kind {
        Kind::Fifo | Kind::Last => {
            let output = DataOut::<u64>::new();
            let ports = PortSet::new().output(&output);
            producer(
                &DATA_PRODUCER,
                ports,
                move |p| output.send(p),
                count,
                started_tx,
            )
        }
        Kind::Poster => {
            let output = PosterOut::<u64>::new();
            let ports = PortSet::new().output(&output);
            producer(
                &POSTER_PRODUCER,
                ports,
                move |p| output.post(p),
                count,
                started_tx,
            )
        }
    };
    system.add(producer).expect("add producer");
    for index in 0..consumers {
        system
            .connect("producer.output", &format!("consumer{index}.input"))
            .expect("connect");
    }
    system.run_all().expect("run");
    let start = common::expect(&started, LIMIT, "producer start");
    let mut rates = Vec::new();
    let mut taken = 0;
    for _ in 0..consumers {
        let (end, took) = common::expect(&done, LIMIT, "consumer");
        rates.push(count as f64 / end.duration_since(start).as_secs_f64());
        taken += took;
    }
    let lost = lost.iter().map(|f| f()).sum();
    let report = system.shutdown();
    assert!(report.clean(), "unclean shutdown: {report:?}");
    Round {
        rate: rates.iter().sum::<f64>() / rates.len() as f64,
        taken: taken / consumers as u64,
        lost,
    }
}

/// One producer thread sending `count` packets to `consumers` threads, each on its own
/// `bounded(1024)`; packets per second per consumer.
fn baseline_round(consumers: usize, count: u64) -> f64 {
    let (done_tx, done): (Sender<Instant>, Receiver<Instant>) = bounded(consumers);
    let mut senders = Vec::new();
    let mut threads = Vec::new();
    for _ in 0..consumers {
        let (tx, rx) = bounded::<u64>(CAPACITY);
        senders.push(tx);
        let done_tx = done_tx.clone();
        threads.push(std::thread::spawn(move || {
            for packet in rx.iter() {
                if packet == count - 1 {
                    let _ = done_tx.send(Instant::now());
                }
            }
        }));
    }
    let start = Instant::now();
    for packet in 0..count {
        for sender in &senders {
            sender.send(packet).expect("consumer alive");
        }
    }
    drop(senders);
    let mut rates = Vec::new();
    for _ in 0..consumers {
        let end = common::expect(&done, LIMIT, "baseline consumer");
        rates.push(count as f64 / end.duration_since(start).as_secs_f64());
    }
    for thread in threads {
        thread.join().expect("consumer thread");
    }
    rates.iter().sum::<f64>() / rates.len() as f64
}

fn median(mut values: Vec<f64>) -> f64 {
    values.sort_by(f64::total_cmp);
    values[values.len() / 2]
}

fn main() {
    let mode = Mode::from_env();
    let count = mode.scale(1_000_000, 50_000) as u64;
    let mut table = Table::new("Throughput of 8-byte packets", mode);
    // `cargo bench --bench throughput -- fifo last` measures only the kinds named.
    let named: Vec<String> = std::env::args().skip(1).collect();
    for (kind, goal) in [
        (Kind::Fifo, Goal::AtLeast(0.5)),
        (Kind::Last, Goal::AtLeast(1.0)),
        (Kind::Poster, Goal::AtLeast(0.5)),
    ] {
        let short = format!("{kind:?}").to_lowercase();
        if named.iter().any(|arg| !arg.starts_with('-')) && !named.contains(&short) {
            continue;
        }
        let consumers = if kind == Kind::Poster { CONSUMERS } else { 1 };
        let mut rounds = Vec::new();
        let mut baseline = Vec::new();
        for _ in 0..ROUNDS {
            baseline.push(baseline_round(consumers, count));
            rounds.push(project_round(kind, count));
        }
        let project = median(rounds.iter().map(|r| r.rate).collect());
        let name = match kind {
            Kind::Fifo => "fifo(1024), packets/s",
            Kind::Last => "last, updates/s",
            Kind::Poster => "poster x4, posts/s per consumer",
        };
        table.row(
            name,
            Figure::Rate(project),
            Figure::Rate(median(baseline)),
            goal,
        );
        let taken: u64 = rounds.iter().map(|r| r.taken).sum::<u64>() / ROUNDS as u64;
        let lost: u64 = rounds.iter().map(|r| r.lost).sum();
        table.note(&format!(
            "{kind:?}: {count} packets per round, median of {ROUNDS} rounds; a consumer took {taken} \
             packets per round on average; {lost} lost in all rounds"
        ));
    }
    table.print();
}
