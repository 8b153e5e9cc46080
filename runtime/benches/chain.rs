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

use coolbot::port::{DataOut, FifoIn};
use coolbot::{
    Component, InputKind, OutputKind, OverflowPolicy, PeriodicSpec, PortSet, Section, System,
};
use crossbeam_channel::{Sender, bounded};

use common::{Figure, Glue, Goal, Mode, Samples, Table};

const HOPS: usize = 8;
const PERIOD: Duration = Duration::from_millis(1);
const CAPACITY: usize = 16;
const ROUNDS: usize = 20;
const WARMUP: usize = 20;

one_state_spec! {
    static SOURCE = "Source",
    inputs: [],
    outputs: [("output", OutputKind::Data)],
    on: [],
    periodic: Some(PeriodicSpec { period: Some(PERIOD) }),
}

one_state_spec! {
    static RELAY = "Relay",
    inputs: [("input", InputKind::Fifo { capacity: CAPACITY, policy: OverflowPolicy::Reject })],
    outputs: [("output", OutputKind::Data)],
    on: [0],
    periodic: None,
}

one_state_spec! {
    static SINK = "Sink",
    inputs: [("input", InputKind::Fifo { capacity: CAPACITY, policy: OverflowPolicy::Reject })],
    outputs: [],
    on: [0],
    periodic: None,
}

fn source() -> Component {
    let output = DataOut::<Instant>::new();
    let ports = PortSet::new().output(&output);
    let body = Box::new(move |section: Section, _: &mut coolbot::Context| {
        if section == Section::Periodic {
            output.send(Instant::now());
        }
        Ok(())
    });
    Component::new("stage0", Glue::boxed(&SOURCE, body), ports)
}

fn relay(index: usize) -> Component {
    let input = FifoIn::<Instant>::new(CAPACITY, OverflowPolicy::Reject);
    let output = DataOut::<Instant>::new();
    let ports = PortSet::new().input(&input).output(&output);
    let body = Box::new(move |section: Section, _: &mut coolbot::Context| {
        if section == Section::Entry {
            for stamp in input.drain() {
                output.send(stamp);
            }
        }
        Ok(())
    });
    Component::new(format!("stage{index}"), Glue::boxed(&RELAY, body), ports)
}

fn sink(count: usize, done: Sender<Vec<Duration>>) -> Component {
    let input = FifoIn::<Instant>::new(CAPACITY, OverflowPolicy::Reject);
    let ports = PortSet::new().input(&input);
    let mut samples = Vec::with_capacity(count + WARMUP);
    let mut done = Some(done);
    let body = Box::new(move |section: Section, _: &mut coolbot::Context| {
        if section == Section::Entry && done.is_some() {
            for stamp in input.drain() {
                samples.push(stamp.elapsed());
            }
            if samples.len() >= count + WARMUP
                && let Some(done) = done.take()
            {
                let _ = done.send(samples.split_off(WARMUP));
            }
        }
        Ok(())
    });
    Component::new(format!("stage{HOPS}"), Glue::boxed(&SINK, body), ports)
}

fn project_round(count: usize) -> Vec<Duration> {
    let (done, samples) = bounded(1);
    let mut system = System::new();
    // Downstream first, so that every stage runs before packets reach it.
    system.add(sink(count, done)).expect("add sink");
    for index in (1..HOPS).rev() {
        system.add(relay(index)).expect("add relay");
    }
    system.add(source()).expect("add source");
    for index in 0..HOPS {
        system
            .connect(
                &format!("stage{index}.output"),
                &format!("stage{}.input", index + 1),
            )
            .expect("connect");
    }
    system.run_all().expect("run");
    let samples = common::expect(&samples, Duration::from_secs(60), "chain");
    let report = system.shutdown();
    assert!(report.clean(), "unclean shutdown: {report:?}");
    samples
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
        let mut samples = Vec::with_capacity(count + WARMUP);
        for stamp in upstream.iter() {
            samples.push(stamp.elapsed());
            if samples.len() >= count + WARMUP {
                break;
            }
        }
        samples.split_off(WARMUP)
    });
    let mut next = Instant::now() + PERIOD;
    while !sink.is_finished() {
        let now = Instant::now();
        if next > now {
            std::thread::sleep(next - now);
        }
        if first.send(Instant::now()).is_err() {
            break;
        }
        next += PERIOD;
        let now = Instant::now();
        if next <= now {
            next = now + PERIOD;
        }
    }
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
        || project_round(per_round),
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
