//! Fan-out of large packets: one data output sending 1 MiB packets (`Vec<u8>`) to 4
//! fifo consumer components, against one producer thread sending `Arc<Vec<u8>>` to 4
//! consumer threads on 4 crossbeam-channel `bounded(16)` channels.
//!
//! The figure is CPU time per packet: the process's CPU time over a round (producer,
//! consumers and everything else the runtime runs) divided by the packets sent. A
//! packet sent to several inputs is shared, not copied (`docs/runtime.md`,
//! "Fan-out"), so the runtime should cost about what sharing by hand costs. Goal
//! <= 1.5x.
//!
//! - `fifo x4, recv_shared`: the consumers take `Arc<Vec<u8>>` (no copy anywhere).
//! - `fifo x4, recv`: the consumers take the packet by value: each copy a consumer
//!   takes while another still holds the packet is a copy (reported, no goal).
//!
//! Both sides make each packet the same way (`vec![0u8; 1 MiB]`, zeroed pages from
//! the allocator), and each consumer reads its first and last byte. The fifos use the
//! `block` policy, like a bounded channel's `send`: nothing is lost.
//!
//! `cargo bench -p coolbot --bench fanout` (add `-- --quick` for a smoke run).

#[macro_use]
mod common;

use std::sync::Arc;
use std::time::Duration;

use coolbot::port::{DataOut, FifoIn};
use coolbot::{Component, InputKind, OutputKind, OverflowPolicy, PortSet, Section, System};
use cpu_time::ProcessTime;
use crossbeam_channel::{Sender, bounded};

use common::{Figure, Glue, Goal, Mode, Table};

const SIZE: usize = 1 << 20;
const CAPACITY: usize = 16;
const CONSUMERS: usize = 4;
const ROUNDS: usize = 5;
const LIMIT: Duration = Duration::from_secs(120);

type Packet = Vec<u8>;

one_state_spec! {
    static PRODUCER = "Producer",
    inputs: [],
    outputs: [("output", OutputKind::Data)],
    on: [],
    periodic: None,
}

one_state_spec! {
    static CONSUMER = "Consumer",
    inputs: [("input", InputKind::Fifo { capacity: CAPACITY, policy: OverflowPolicy::Block })],
    outputs: [],
    on: [0],
    periodic: None,
}

/// What a consumer does with a packet: read its first and last byte.
fn touch(packet: &[u8]) -> u64 {
    u64::from(packet[0]) + u64::from(packet[packet.len() - 1])
}

/// One runtime round: CPU time per packet.
fn project_round(count: u64, shared: bool) -> Duration {
    let (done_tx, done) = bounded::<u64>(CONSUMERS);
    let mut system = System::new();
    for index in 0..CONSUMERS {
        let input = FifoIn::<Packet>::new(CAPACITY, OverflowPolicy::Block);
        let ports = PortSet::new().input(&input);
        let done_tx = done_tx.clone();
        let mut taken = 0;
        let body = Box::new(move |section: Section, _: &mut coolbot::Context| {
            if section == Section::Entry && taken < count {
                let mut sum = 0;
                if shared {
                    while let Some(packet) = input.recv_shared() {
                        sum += touch(&packet);
                        taken += 1;
                    }
                } else {
                    while let Some(packet) = input.recv() {
                        sum += touch(&packet);
                        taken += 1;
                    }
                }
                std::hint::black_box(sum);
                if taken == count {
                    let _ = done_tx.send(taken);
                }
            }
            Ok(())
        });
        let name = format!("consumer{index}");
        system
            .add(Component::new(name, Glue::boxed(&CONSUMER, body), ports))
            .expect("add consumer");
    }
    let output = DataOut::<Packet>::new();
    let ports = PortSet::new().output(&output);
    let (go_tx, go) = bounded::<()>(1);
    let mut sent = false;
    let body = Box::new(move |section: Section, _: &mut coolbot::Context| {
        if section == Section::Entry && !sent {
            sent = true;
            let _ = go.recv_timeout(LIMIT);
            for _ in 0..count {
                output.send(vec![0u8; SIZE]);
            }
        }
        Ok(())
    });
    system
        .add(Component::new(
            "producer",
            Glue::boxed(&PRODUCER, body),
            ports,
        ))
        .expect("add producer");
    for index in 0..CONSUMERS {
        system
            .connect("producer.output", &format!("consumer{index}.input"))
            .expect("connect");
    }
    system.run_all().expect("run");
    let started = ProcessTime::now();
    go_tx.send(()).expect("producer waiting");
    for _ in 0..CONSUMERS {
        common::expect(&done, LIMIT, "consumer");
    }
    let cpu = started.elapsed();
    let report = system.shutdown();
    assert!(report.clean(), "unclean shutdown: {report:?}");
    cpu / u32::try_from(count).expect("a round's count fits")
}

/// One baseline round: a producer thread sends `Arc<Vec<u8>>` to `CONSUMERS` threads.
fn baseline_round(count: u64) -> Duration {
    let (done_tx, done) = bounded::<u64>(CONSUMERS);
    let mut senders: Vec<Sender<Arc<Packet>>> = Vec::new();
    let mut threads = Vec::new();
    for _ in 0..CONSUMERS {
        let (tx, rx) = bounded::<Arc<Packet>>(CAPACITY);
        senders.push(tx);
        let done_tx = done_tx.clone();
        threads.push(std::thread::spawn(move || {
            let mut sum = 0;
            let mut taken = 0;
            for packet in rx.iter() {
                sum += touch(&packet);
                taken += 1;
            }
            std::hint::black_box(sum);
            let _ = done_tx.send(taken);
        }));
    }
    let started = ProcessTime::now();
    for _ in 0..count {
        let packet = Arc::new(vec![0u8; SIZE]);
        for sender in &senders {
            sender.send(Arc::clone(&packet)).expect("consumer alive");
        }
    }
    drop(senders);
    for _ in 0..CONSUMERS {
        assert_eq!(common::expect(&done, LIMIT, "baseline consumer"), count);
    }
    let cpu = started.elapsed();
    for thread in threads {
        thread.join().expect("baseline consumer");
    }
    cpu / u32::try_from(count).expect("a round's count fits")
}

fn median(mut samples: Vec<Duration>) -> Duration {
    samples.sort_unstable();
    samples[samples.len() / 2]
}

fn main() {
    let mode = Mode::from_env();
    let count = mode.scale(2000, 100) as u64;
    let mut table = Table::new(
        "Fan-out: 1 MiB packets to 4 fifo consumers, CPU per packet",
        mode,
    );
    for (name, shared, goal) in [
        ("fifo x4, recv_shared", true, Goal::AtMost(1.5)),
        ("fifo x4, recv", false, Goal::None),
    ] {
        let (project, baseline) = common::alternate(
            ROUNDS,
            || vec![project_round(count, shared)],
            || vec![baseline_round(count)],
        );
        table.row(
            name,
            Figure::Time(median(project)),
            Figure::Time(median(baseline)),
            goal,
        );
    }
    table.note(&format!(
        "{count} packets of {SIZE} bytes per round, {ROUNDS} rounds each side alternating, medians"
    ));
    table.print();
}
