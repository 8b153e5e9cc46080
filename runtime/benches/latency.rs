//! One-way latency: ping-pong between two components over a fifo, a last and a poster
//! connection, against crossbeam-channel `bounded(1)` ping-pong between two bare
//! threads. One-way latency is half a round trip; every round trip is one sample.
//! `fifo_labeled` is the fifo ping-pong between two aperiodic components with a
//! `max_response`: every packet is stamped on arrival (temporal labeling) and every
//! response timed, the cost of response times next to the plain fifo's
//! (reported, without a goal of its own).
//!
//! Goals: p50 <= 1.5x and p99 <= 2x the baseline.
//!
//! `cargo bench -p coolbot --bench latency` (add `-- --quick` for a smoke run).

#[macro_use]
mod common;

use std::time::{Duration, Instant};

use coolbot::port::{DataOut, FifoIn, LastIn, PosterIn, PosterOut};
use coolbot::{
    Component, InputKind, InputPort, OutputKind, OutputPort, OverflowPolicy, PortSet, Section,
    System,
};
use crossbeam_channel::{Sender, bounded};

use common::{Figure, Glue, Goal, Mode, Samples, Table};

/// Round trips discarded at the start of every round (thread wake-up, caches).
const WARMUP: usize = 200;
/// Rounds of project and baseline, alternated (many short rounds, so that a change in
/// the machine's load, which moves both sides between regimes, hits both alike).
const ROUNDS: usize = 40;

one_state_spec! {
    static FIFO_SPEC = "FifoEcho",
    inputs: [("input", InputKind::Fifo { capacity: 1, policy: OverflowPolicy::Reject })],
    outputs: [("output", OutputKind::Data)],
    on: [0],
    periodic: None,
}

one_state_spec! {
    static LAST_SPEC = "LastEcho",
    inputs: [("input", InputKind::Last)],
    outputs: [("output", OutputKind::Data)],
    on: [0],
    periodic: None,
}

one_state_spec! {
    static POSTER_SPEC = "PosterEcho",
    inputs: [("input", InputKind::Poster)],
    outputs: [("output", OutputKind::Poster)],
    on: [0],
    periodic: None,
}

/// The connection kind under test.
#[derive(Debug, Clone, Copy)]
enum Kind {
    Fifo,
    /// Fifo with temporal labeling on (both ends aperiodic with a `max_response`).
    FifoLabeled,
    Last,
    Poster,
}

/// One end of a ping-pong: how to take the next packet, how to send one, and the
/// ports to register.
struct End {
    recv: Box<dyn FnMut() -> Option<Instant> + Send>,
    send: Box<dyn Fn(Instant) + Send>,
    ports: PortSet,
    spec: &'static coolbot::Spec,
}

fn end(kind: Kind) -> End {
    match kind {
        Kind::Fifo | Kind::FifoLabeled => {
            let input = FifoIn::<Instant>::new(1, OverflowPolicy::Reject);
            let output = DataOut::<Instant>::new();
            let ports = ports(&input, &output);
            End {
                recv: Box::new(move || input.recv()),
                send: Box::new(move |t| output.send(t)),
                ports,
                spec: &FIFO_SPEC,
            }
        }
        Kind::Last => {
            let input = LastIn::<Instant>::new();
            let output = DataOut::<Instant>::new();
            let ports = ports(&input, &output);
            End {
                recv: Box::new(move || input.take_new()),
                send: Box::new(move |t| output.send(t)),
                ports,
                spec: &LAST_SPEC,
            }
        }
        Kind::Poster => {
            let input = PosterIn::<Instant>::new();
            let output = PosterOut::<Instant>::new();
            let ports = ports(&input, &output);
            End {
                recv: Box::new(move || input.take_new()),
                send: Box::new(move |t| output.post(t)),
                ports,
                spec: &POSTER_SPEC,
            }
        }
    }
}

fn ports(input: &impl InputPort, output: &impl OutputPort) -> PortSet {
    PortSet::new().input(input).output(output)
}

/// The echo side: sends back every packet it takes.
fn pong(kind: Kind) -> Component {
    let End {
        mut recv,
        send,
        ports,
        spec,
    } = end(kind);
    let body = Box::new(move |section: Section, _: &mut coolbot::Context| {
        if section == Section::Entry
            && let Some(stamp) = recv()
        {
            send(stamp);
        }
        Ok(())
    });
    Component::new("pong", Glue::boxed(spec, body), ports)
}

/// The measuring side: sends a stamp, takes the echo, records half the round trip;
/// after `count` samples sends them on `done`.
fn ping(kind: Kind, count: usize, done: Sender<Vec<Duration>>) -> Component {
    let End {
        mut recv,
        send,
        ports,
        spec,
    } = end(kind);
    let mut samples = Vec::with_capacity(count + WARMUP);
    let mut in_flight = false;
    let mut done = Some(done);
    let body = Box::new(move |section: Section, _: &mut coolbot::Context| {
        if section != Section::Entry {
            return Ok(());
        }
        if let Some(stamp) = recv() {
            samples.push(stamp.elapsed() / 2);
            in_flight = false;
        }
        if samples.len() >= count + WARMUP {
            if let Some(done) = done.take() {
                let _ = done.send(samples.split_off(WARMUP));
            }
        } else if !in_flight {
            in_flight = true;
            send(Instant::now());
        }
        Ok(())
    });
    Component::new("ping", Glue::boxed(spec, body), ports)
}

/// With [`Kind::FifoLabeled`], `component` aperiodic with a `max_response` (so its
/// inputs are labeled and its responses timed); else as it is.
fn labeled(kind: Kind, component: Component) -> Component {
    match kind {
        Kind::FifoLabeled => component.with_timing(coolbot::TimingSpec {
            max_response: Some(Duration::from_secs(1)),
            ..coolbot::TimingSpec::NONE
        }),
        _ => component,
    }
}

fn project_round(kind: Kind, count: usize) -> Vec<Duration> {
    let (done, samples) = bounded(1);
    let mut system = System::new();
    // The echo runs first, so that the first ping finds it running.
    system.add(labeled(kind, pong(kind))).expect("add pong");
    system
        .add(labeled(kind, ping(kind, count, done)))
        .expect("add ping");
    system
        .connect("ping.output", "pong.input")
        .expect("connect");
    system
        .connect("pong.output", "ping.input")
        .expect("connect");
    system.run_all().expect("run");
    let samples = common::expect(&samples, Duration::from_secs(60), "ping-pong");
    let report = system.shutdown();
    assert!(report.clean(), "unclean shutdown: {report:?}");
    samples
}

fn baseline_round(count: usize) -> Vec<Duration> {
    let (to_echo, echo_in) = bounded::<Instant>(1);
    let (to_ping, ping_in) = bounded::<Instant>(1);
    let echo = std::thread::spawn(move || {
        while let Ok(stamp) = echo_in.recv() {
            if to_ping.send(stamp).is_err() {
                break;
            }
        }
    });
    let mut samples = Vec::with_capacity(count + WARMUP);
    for _ in 0..count + WARMUP {
        to_echo.send(Instant::now()).expect("echo alive");
        let stamp = ping_in.recv().expect("echo alive");
        samples.push(stamp.elapsed() / 2);
    }
    drop(to_echo);
    echo.join().expect("echo thread");
    samples.split_off(WARMUP)
}

fn main() {
    let mode = Mode::from_env();
    let per_round = mode.scale(10_000, 500) / ROUNDS;
    let mut table = Table::new("One-way latency, ping-pong (half round trip)", mode);
    // `cargo bench --bench latency -- last poster` measures only the kinds named.
    let named: Vec<String> = std::env::args().skip(1).collect();
    for kind in [Kind::Fifo, Kind::FifoLabeled, Kind::Last, Kind::Poster] {
        let name = match kind {
            Kind::FifoLabeled => "fifo_labeled".to_owned(),
            _ => format!("{kind:?}").to_lowercase(),
        };
        if named.iter().any(|arg| !arg.starts_with('-')) && !named.contains(&name) {
            continue;
        }
        let (project, baseline) = common::alternate(
            ROUNDS,
            || project_round(kind, per_round),
            || baseline_round(per_round),
        );
        let (project, baseline) = (Samples::new(project), Samples::new(baseline));
        // Labeling is reported next to the plain fifo: the goals are the plain paths'.
        let goal = |ratio| match kind {
            Kind::FifoLabeled => Goal::None,
            _ => Goal::AtMost(ratio),
        };
        table.row(
            &format!("{name} p50"),
            Figure::Time(project.p50()),
            Figure::Time(baseline.p50()),
            goal(1.5),
        );
        table.row(
            &format!("{name} p99"),
            Figure::Time(project.p99()),
            Figure::Time(baseline.p99()),
            goal(2.0),
        );
        table.note(&format!(
            "{name}: {} samples per side; max project {:?}, baseline {:?}",
            project.len(),
            project.max(),
            baseline.max()
        ));
    }
    table.print();
}
