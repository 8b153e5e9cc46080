//! A chain of components at 1 kHz, as the chain and group benchmarks run it: a
//! periodic first stage makes a stamped packet every period, relays pass it on, and
//! the last stage reads the stamp; fifo connections between them. What each stage
//! does with the packet is the benchmark's ([`Stages`]). Also the baselines' parts:
//! a loop paced to absolute deadlines ([`paced`]) and the samples kept after a
//! warm-up ([`Collector`]).

use std::time::{Duration, Instant};

use coolbot::port::{DataOut, FifoIn};
use coolbot::{
    Component, InputKind, OutputKind, OverflowPolicy, PeriodicSpec, PortSet, Section, System,
};
use crossbeam_channel::{Sender, bounded};

use super::Glue;

/// The chain's period.
pub const PERIOD: Duration = Duration::from_millis(1);
/// Each fifo connection's capacity.
pub const CAPACITY: usize = 16;
/// Packets each side sends before the ones it measures.
pub const WARMUP: usize = 20;

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

/// What the stages of a chain do with its packets.
pub trait Stages: Clone + Send + 'static {
    /// What travels along the chain.
    type Packet: coolbot::Packet;
    /// The first stage's packet, stamped now.
    fn first(&self) -> Self::Packet;
    /// A relay's work: the packet it sends on.
    fn pass(&self, packet: Self::Packet) -> Self::Packet;
    /// The last stage's work; the packet's stamp.
    fn last(&self, packet: Self::Packet) -> Instant;
}

/// The samples a side keeps: `count` after the first [`WARMUP`].
pub struct Collector {
    samples: Vec<Duration>,
    count: usize,
}

impl Collector {
    pub fn new(count: usize) -> Collector {
        Collector {
            samples: Vec::with_capacity(count + WARMUP),
            count,
        }
    }

    /// Keep `sample`; true once there are enough.
    pub fn push(&mut self, sample: Duration) -> bool {
        self.samples.push(sample);
        self.full()
    }

    /// Whether there are enough.
    pub fn full(&self) -> bool {
        self.samples.len() >= self.count + WARMUP
    }

    /// The samples after the warm-up.
    pub fn take(&mut self) -> Vec<Duration> {
        self.samples.split_off(WARMUP.min(self.samples.len()))
    }
}

/// Run `step` every [`PERIOD`], each time at the next absolute deadline (a late step
/// starts the next period from now), until it returns false.
pub fn paced(mut step: impl FnMut() -> bool) {
    let mut next = Instant::now() + PERIOD;
    loop {
        let now = Instant::now();
        if next > now {
            std::thread::sleep(next - now);
        }
        if !step() {
            break;
        }
        next += PERIOD;
        let now = Instant::now();
        if next <= now {
            next = now + PERIOD;
        }
    }
}

fn source<S: Stages>(stages: S) -> Component {
    let output = DataOut::<S::Packet>::new();
    let ports = PortSet::new().output(&output);
    let body = Box::new(move |section: Section, _: &mut coolbot::Context| {
        if section == Section::Periodic {
            output.send(stages.first());
        }
        Ok(())
    });
    Component::new("stage0", Glue::boxed(&SOURCE, body), ports)
}

fn relay<S: Stages>(index: usize, stages: S) -> Component {
    let input = FifoIn::<S::Packet>::new(CAPACITY, OverflowPolicy::Reject);
    let output = DataOut::<S::Packet>::new();
    let ports = PortSet::new().input(&input).output(&output);
    let body = Box::new(move |section: Section, _: &mut coolbot::Context| {
        if section == Section::Entry {
            for packet in input.drain() {
                output.send(stages.pass(packet));
            }
        }
        Ok(())
    });
    Component::new(format!("stage{index}"), Glue::boxed(&RELAY, body), ports)
}

fn sink<S: Stages>(
    index: usize,
    count: usize,
    stages: S,
    done: Sender<Vec<Duration>>,
) -> Component {
    let input = FifoIn::<S::Packet>::new(CAPACITY, OverflowPolicy::Reject);
    let ports = PortSet::new().input(&input);
    let mut samples = Collector::new(count);
    let mut done = Some(done);
    let body = Box::new(move |section: Section, _: &mut coolbot::Context| {
        if section == Section::Entry && done.is_some() {
            for packet in input.drain() {
                samples.push(stages.last(packet).elapsed());
            }
            if samples.full()
                && let Some(done) = done.take()
            {
                let _ = done.send(samples.take());
            }
        }
        Ok(())
    });
    Component::new(format!("stage{index}"), Glue::boxed(&SINK, body), ports)
}

/// One round of a chain of `links` fifo connections (`links + 1` components,
/// `stage0` to `stage<links>`), in the execution group `group` or one thread each:
/// `count` samples of the time from a packet's stamp to the last stage's work.
pub fn components_round<S: Stages>(
    links: usize,
    count: usize,
    stages: &S,
    group: Option<&str>,
) -> Vec<Duration> {
    let (done, samples) = bounded(1);
    let mut system = System::new();
    // Downstream first, so that every stage runs before packets reach it.
    system
        .add(sink(links, count, stages.clone(), done))
        .expect("add sink");
    for index in (1..links).rev() {
        system.add(relay(index, stages.clone())).expect("add relay");
    }
    system.add(source(stages.clone())).expect("add source");
    for index in 0..links {
        system
            .connect(
                &format!("stage{index}.output"),
                &format!("stage{}.input", index + 1),
            )
            .expect("connect");
    }
    if let Some(group) = group {
        let names: Vec<String> = (0..=links).map(|index| format!("stage{index}")).collect();
        let names: Vec<&str> = names.iter().map(String::as_str).collect();
        system.group(group, &names).expect("group");
    }
    system.run_all().expect("run");
    let samples = super::expect(&samples, Duration::from_secs(60), "chain");
    let report = system.shutdown();
    assert!(report.clean(), "unclean shutdown: {report:?}");
    samples
}
