//! The ping-pong the latency benchmarks share: a pinging component that stamps what
//! it sends and measures half of each round trip, a pong that sends back what it
//! takes, a kicker that starts rounds, and the wait for a round's samples.

use std::sync::OnceLock;
use std::time::{Duration, Instant};

use coolbot::port::{DataOut, FifoIn, TickIn, TickOut};
use coolbot::{Component, InputKind, OutputKind, OverflowPolicy, PortSet, Section, System};
use crossbeam_channel::{Receiver, Sender, bounded};

use crate::common::{self, Glue};

const QUEUE: InputKind = InputKind::Fifo {
    capacity: 4,
    policy: OverflowPolicy::Reject,
};

one_state_spec! {
    static PING_SPEC = "Ping",
    inputs: [("input", QUEUE), ("kick", InputKind::Tick)],
    outputs: [("output", OutputKind::Data)],
    on: [0, 1],
    periodic: None,
}

one_state_spec! {
    static PONG_SPEC = "Pong",
    inputs: [("input", QUEUE)],
    outputs: [("output", OutputKind::Data)],
    on: [0],
    periodic: None,
}

one_state_spec! {
    static KICK_SPEC = "Kick",
    inputs: [],
    outputs: [("kick", OutputKind::Tick)],
    on: [],
    periodic: None,
}

/// Stamps are nanoseconds since one instant of this process (both ends are in it).
pub fn stamp() -> u64 {
    static BASE: OnceLock<Instant> = OnceLock::new();
    BASE.get_or_init(Instant::now).elapsed().as_nanos() as u64
}

/// The time since `stamp_ns` (a [`stamp`]).
pub fn since(stamp_ns: u64) -> Duration {
    Duration::from_nanos(stamp().saturating_sub(stamp_ns))
}

/// A packet that carries a stamp.
pub trait Stamped: coolbot::Packet {
    /// The packet stamped `nanos`.
    fn at(nanos: u64) -> Self;
    /// Its stamp.
    fn nanos(&self) -> u64;
}

impl Stamped for u64 {
    fn at(nanos: u64) -> u64 {
        nanos
    }
    fn nanos(&self) -> u64 {
        *self
    }
}

/// When the pinging side starts a round trip.
#[derive(Debug, Clone, Copy)]
pub enum Pace {
    /// A kick starts a round: `count + warm-up` round trips back to back.
    Burst,
    /// Each kick starts one round trip unless one is in flight; the round ends
    /// after `count + warm-up` of them.
    PerKick,
}

/// The pinging side `name`: on its kicks (`pace`), round trips, each sample half of
/// one; after `count + warmup` samples, sends them (the first `warmup` dropped) on
/// `done` and starts over.
pub fn ping<P: Stamped>(
    name: &str,
    pace: Pace,
    count: usize,
    warmup: usize,
    done: Sender<Vec<Duration>>,
) -> Component {
    let input = FifoIn::<P>::new(4, OverflowPolicy::Reject);
    let kick = TickIn::new();
    let output = DataOut::<P>::new();
    let ports = PortSet::new().input(&input).input(&kick).output(&output);
    let round = count + warmup;
    let mut samples = Vec::with_capacity(round);
    let mut remaining = 0usize;
    let mut in_flight = false;
    let body = Box::new(move |section: Section, _: &mut coolbot::Context| {
        if section != Section::Entry {
            return Ok(());
        }
        let kicked = kick.take() > 0;
        if kicked && matches!(pace, Pace::Burst) {
            remaining = round;
            samples.clear();
        }
        if let Some(sent) = input.recv() {
            samples.push(since(sent.nanos()) / 2);
            in_flight = false;
            if samples.len() == round {
                let _ = done.send(samples.split_off(warmup));
                samples.clear();
            }
        }
        let start = match pace {
            Pace::Burst => remaining > 0,
            Pace::PerKick => kicked,
        };
        if start && !in_flight {
            remaining = remaining.saturating_sub(1);
            in_flight = true;
            output.send(P::at(stamp()));
        }
        Ok(())
    });
    Component::new(name, Glue::boxed(&PING_SPEC, body), ports)
}

/// The echo side `name`: sends back every packet it takes.
pub fn pong<P: Stamped>(name: &str) -> Component {
    let input = FifoIn::<P>::new(4, OverflowPolicy::Reject);
    let output = DataOut::<P>::new();
    let ports = PortSet::new().input(&input).output(&output);
    let body = Box::new(move |section: Section, _: &mut coolbot::Context| {
        if section == Section::Entry {
            while let Some(packet) = input.recv() {
                output.send(packet);
            }
        }
        Ok(())
    });
    Component::new(name, Glue::boxed(&PONG_SPEC, body), ports)
}

/// The pinging side of a ping-pong, started from outside: its kicker's output and
/// the rounds' samples.
pub struct Pinger {
    pace: Pace,
    kick: TickOut,
    samples: Receiver<Vec<Duration>>,
}

impl Pinger {
    /// Add `<prefix>ping` and its kicker `<prefix>kicker` to `system`, connected; the
    /// pong and the way between them are the caller's.
    pub fn add<P: Stamped>(
        system: &mut System,
        prefix: &str,
        pace: Pace,
        count: usize,
        warmup: usize,
    ) -> Pinger {
        let (done, samples) = bounded(1);
        let kick = TickOut::new();
        let (ping_name, kicker) = (format!("{prefix}ping"), format!("{prefix}kicker"));
        system
            .add(ping::<P>(&ping_name, pace, count, warmup, done))
            .expect("ping");
        system
            .add(Component::new(
                &kicker,
                Glue::boxed(&KICK_SPEC, Box::new(|_, _| Ok(()))),
                PortSet::new().output(&kick),
            ))
            .expect("kicker");
        system
            .connect(&format!("{kicker}.kick"), &format!("{ping_name}.kick"))
            .expect("connect the kicker");
        Pinger {
            pace,
            kick,
            samples,
        }
    }

    /// One round: its samples, the warm-up dropped. `what` names the ping-pong if it
    /// stalls.
    pub fn round(&self, what: &str) -> Vec<Duration> {
        let patience = Duration::from_secs(120);
        match self.pace {
            Pace::Burst => {
                self.kick.emit();
                common::expect(&self.samples, patience, what)
            }
            Pace::PerKick => {
                let deadline = Instant::now() + patience;
                loop {
                    self.kick.emit();
                    if let Ok(samples) = self.samples.recv_timeout(KICK) {
                        return samples;
                    }
                    assert!(Instant::now() < deadline, "benchmark stalled: {what}");
                }
            }
        }
    }
}

/// How often a [`Pace::PerKick`] round kicks.
pub const KICK: Duration = Duration::from_millis(1);

/// `<prefix>ping` and `<prefix>pong` in `system`, connected both ways.
pub fn pair<P: Stamped>(
    system: &mut System,
    prefix: &str,
    pace: Pace,
    count: usize,
    warmup: usize,
) -> Pinger {
    let pinger = Pinger::add::<P>(system, prefix, pace, count, warmup);
    let (ping, pong_name) = (format!("{prefix}ping"), format!("{prefix}pong"));
    system.add(pong::<P>(&pong_name)).expect("pong");
    system
        .connect(&format!("{ping}.output"), &format!("{pong_name}.input"))
        .expect("connect");
    system
        .connect(&format!("{pong_name}.output"), &format!("{ping}.input"))
        .expect("connect");
    pinger
}
