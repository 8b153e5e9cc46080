//! 1,000 components in one process: the time from `System::run_all` (spawn every
//! thread, run every `start` hook, command every component to `running`) until all of
//! them run their user automaton, and the resident memory each costs (RSS delta from
//! `/proc/self/statm`, divided by the count, measured while all of them run).
//!
//! Each component is a typical small one: a fifo(16) input, a data output, a periodic
//! state at 100 ms and an `on input` transition, with its ports connected in a ring.
//! The baseline spawns the same number of bare threads, each blocking on a
//! crossbeam-channel `bounded(16)` with a 100 ms timeout and acknowledging its start on
//! a channel. The same components also run in 10 execution groups of 100 consecutive
//! nodes (`System::group`), against one thread each: goal, at most 0.3x the memory per
//! component. Each round of each side runs in a fresh child process of the benchmark
//! (memory freed by one run would otherwise be reused by the next), after a warm-up
//! round of [`WARM_UP`] of the same side in that process: the pages of code and the
//! allocator's arenas the first use faults in are a cost per process, not per
//! component (about 0.8 KiB of the figure per component at 1,000 otherwise). The components
//! against bare threads have no goal; those figures are reported.
//!
//! `cargo bench -p coolbot --bench scale` (add `-- --quick` for a smoke run).

#[macro_use]
mod common;

use std::time::{Duration, Instant};

use coolbot::port::{DataOut, FifoIn};
use coolbot::{
    Component, InputKind, OutputKind, OverflowPolicy, PeriodicSpec, PortSet, Section, State, System,
};
use crossbeam_channel::bounded;

use common::{Figure, Glue, Goal, Mode, Table};

const ROUNDS: usize = 3;
/// The components (or bare threads) of the round each child runs, and shuts down,
/// before the one it measures.
const WARM_UP: usize = 10;
/// How many execution groups share the components on the grouped side.
const GROUPS: usize = 10;

one_state_spec! {
    static NODE = "Node",
    inputs: [("input", InputKind::Fifo { capacity: 16, policy: OverflowPolicy::Reject })],
    outputs: [("output", OutputKind::Data)],
    on: [0],
    periodic: Some(PeriodicSpec { period: Some(Duration::from_millis(100)) }),
}

fn node(index: usize) -> Component {
    let input = FifoIn::<u64>::new(16, OverflowPolicy::Reject);
    let output = DataOut::<u64>::new();
    let ports = PortSet::new().input(&input).output(&output);
    let body = Box::new(move |section: Section, _: &mut coolbot::Context| {
        if section == Section::Entry {
            for packet in input.drain() {
                output.send(packet);
            }
        }
        Ok(())
    });
    Component::new(format!("node{index}"), Glue::boxed(&NODE, body), ports)
}

/// Time to all running, and RSS bytes per component: one thread each, or (`grouped`)
/// in [`GROUPS`] execution groups of consecutive nodes.
fn project_round(count: usize, grouped: bool) -> Round {
    let before = common::rss_bytes().expect("/proc/self/statm");
    let mut system = System::new();
    let mut handles = Vec::with_capacity(count);
    for index in 0..count {
        handles.push(system.add(node(index)).expect("add"));
    }
    for index in 0..count {
        system
            .connect(
                &format!("node{index}.output"),
                &format!("node{}.input", (index + 1) % count),
            )
            .expect("connect");
    }
    if grouped {
        let names: Vec<String> = (0..count).map(|index| format!("node{index}")).collect();
        for (group, members) in names.chunks(count.div_ceil(GROUPS)).enumerate() {
            let members: Vec<&str> = members.iter().map(String::as_str).collect();
            system
                .group(&format!("group{group}"), &members)
                .expect("group");
        }
    }
    let (took, result) = common::time(|| system.run_all());
    result.expect("run all");
    assert!(
        handles.iter().all(|h| h.state() == State::Running),
        "every component runs"
    );
    let after = common::rss_bytes().expect("/proc/self/statm");
    let (stop, report) = common::time(|| system.shutdown());
    assert!(report.clean(), "unclean shutdown");
    (
        took,
        after.saturating_sub(before) as f64 / count as f64,
        stop,
    )
}

fn baseline_round(count: usize) -> Round {
    let before = common::rss_bytes().expect("/proc/self/statm");
    let (ack, acks) = bounded::<()>(count);
    let mut senders = Vec::with_capacity(count);
    let started = Instant::now();
    let mut threads = Vec::with_capacity(count);
    for index in 0..count {
        let (tx, rx) = bounded::<u64>(16);
        senders.push(tx);
        let ack = ack.clone();
        threads.push(
            std::thread::Builder::new()
                .name(format!("base{index}"))
                .spawn(move || {
                    let _ = ack.send(());
                    while !matches!(
                        rx.recv_timeout(Duration::from_millis(100)),
                        Err(crossbeam_channel::RecvTimeoutError::Disconnected)
                    ) {}
                })
                .expect("spawn"),
        );
    }
    for _ in 0..count {
        common::expect(&acks, Duration::from_secs(60), "baseline thread start");
    }
    let took = started.elapsed();
    let after = common::rss_bytes().expect("/proc/self/statm");
    let (stop, ()) = common::time(|| {
        drop(senders);
        for thread in threads {
            thread.join().expect("baseline thread");
        }
    });
    (
        took,
        after.saturating_sub(before) as f64 / count as f64,
        stop,
    )
}

fn median<T: Copy>(mut values: Vec<T>, key: impl Fn(&T) -> f64) -> T {
    values.sort_by(|a, b| key(a).total_cmp(&key(b)));
    values[values.len() / 2]
}

/// The figures of one round.
type Round = (Duration, f64, Duration);

/// Run one side in a fresh child process (this binary with `--child SIDE COUNT`) and
/// read its figures: in one process, the second side would reuse the thread stacks and
/// heap the first one freed, and its memory figure would be too low.
fn in_child(side: &str, count: usize) -> Round {
    let exe = std::env::current_exe().expect("current exe");
    let output = std::process::Command::new(exe)
        .args(["--child", side, &count.to_string()])
        .output()
        .expect("run child");
    assert!(
        output.status.success(),
        "child {side} failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    let text = String::from_utf8_lossy(&output.stdout);
    let numbers: Vec<f64> = text
        .split_whitespace()
        .map(|n| n.parse().expect("child output"))
        .collect();
    let [took, memory, stop] = numbers[..] else {
        panic!("child {side} printed {text:?}");
    };
    (
        Duration::from_secs_f64(took),
        memory,
        Duration::from_secs_f64(stop),
    )
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if let Some(at) = args.iter().position(|a| a == "--child") {
        let count = args[at + 2].parse().expect("count");
        let round = |count| match args[at + 1].as_str() {
            "project" => project_round(count, false),
            "grouped" => project_round(count, true),
            _ => baseline_round(count),
        };
        // A warm-up round: what is paid once per process, whatever the count (the
        // code's pages and the allocator's arenas, faulted in on first use), is not
        // memory per component.
        round(WARM_UP);
        let (took, memory, stop) = round(count);
        println!("{} {memory} {}", took.as_secs_f64(), stop.as_secs_f64());
        return;
    }
    let mode = Mode::from_env();
    let count = mode.scale(1_000, 100);
    let mut table = Table::new(&format!("{count} components in one process"), mode);
    let (mut project, mut baseline, mut grouped) = (Vec::new(), Vec::new(), Vec::new());
    for _ in 0..ROUNDS {
        baseline.push(in_child("baseline", count));
        project.push(in_child("project", count));
        grouped.push(in_child("grouped", count));
    }
    let start =
        |rounds: &[Round]| median(rounds.iter().map(|r| r.0).collect(), |d| d.as_secs_f64());
    let memory = |rounds: &[Round]| median(rounds.iter().map(|r| r.1).collect(), |m| *m);
    let stop = |rounds: &[Round]| median(rounds.iter().map(|r| r.2).collect(), |d| d.as_secs_f64());
    table.row(
        "start to all running",
        Figure::Time(start(&project)),
        Figure::Time(start(&baseline)),
        Goal::None,
    );
    table.row(
        "RSS per component",
        Figure::Bytes(memory(&project)),
        Figure::Bytes(memory(&baseline)),
        Goal::None,
    );
    table.row(
        "shutdown, all joined",
        Figure::Time(stop(&project)),
        Figure::Time(stop(&baseline)),
        Goal::None,
    );
    table.row(
        &format!("in {GROUPS} groups vs a thread each: start to all running"),
        Figure::Time(start(&grouped)),
        Figure::Time(start(&project)),
        Goal::None,
    );
    table.row(
        &format!("in {GROUPS} groups vs a thread each: RSS per component"),
        Figure::Bytes(memory(&grouped)),
        Figure::Bytes(memory(&project)),
        Goal::AtMost(0.3),
    );
    table.row(
        &format!("in {GROUPS} groups vs a thread each: shutdown, all joined"),
        Figure::Time(stop(&grouped)),
        Figure::Time(stop(&project)),
        Goal::None,
    );
    table.note(&format!(
        "median of {ROUNDS} rounds per side, alternated; each round runs in a fresh child \
         process of this benchmark so that neither side reuses memory the other freed"
    ));
    table.print();
}
