//! Response time as the paper defines it (3.6): for an aperiodic component, the delay
//! from a packet's arrival ("temporal labeling of input data") to the end of the `on`
//! transition that handled it, queueing included. A late response is a timing
//! violation: the component degrades its quality and is promoted back when responses
//! are short again. Work is simulated with sleeps (lower bounds), so the outcomes do
//! not depend on the machine's load; the tests assert outcomes, never timings.

mod support;

use std::sync::{Arc, Mutex};
use std::time::Duration;

use coolbot::adapt::AdaptAction;
use coolbot::port::{DataOut, FifoIn};
use coolbot::{
    Automaton, Component, Context, Fault, InputKind, InputSpec, MonitorEvent, OnSpec, OutputKind,
    OverflowPolicy, PortSet, Section, SectionResult, Spec, StateSpec, System, TimingSpec, Value,
};
use support::shell::{self, ShellBuilder};
use support::{WAIT, eventually};

const MAX_RESPONSE: Duration = Duration::from_millis(40);

static SERVER: Spec = Spec {
    type_name: "JobServer",
    doc: "",
    states: &[
        StateSpec {
            name: "idle",
            entry: false,
            exit: false,
            periodic: None,
            on: &[OnSpec { port: 0, target: 1 }],
            after: &[],
            may: &[],
        },
        StateSpec {
            name: "work",
            entry: true,
            exit: false,
            periodic: None,
            on: &[OnSpec { port: 0, target: 1 }],
            after: &[],
            may: &[],
        },
    ],
    initial: 0,
    inputs: &[InputSpec {
        name: "jobs",
        kind: InputKind::Fifo {
            capacity: 16,
            policy: OverflowPolicy::Reject,
        },
        packet: "u32",
        pull: false,
    }],
    outputs: &[],
    variables: &[],
    exceptions: &[],
    timing: TimingSpec {
        period: None,
        max_period: None,
        max_response: Some(MAX_RESPONSE),
        priority: 0,
        qualities: &["full", "quick"],
    },
};

/// The jobs done: each one's number and the quality it ran at.
type Done = Arc<Mutex<Vec<(u32, usize)>>>;

/// `on jobs -> work` in both states: each arrival enters `work`, whose entry takes one
/// job from the queue; a job `n > 0` queues job `n - 1` itself at the start of its
/// section (so that job waits behind it), then works: 25 ms at quality 0, 1 ms at
/// quality 1.
struct JobServer {
    jobs: FifoIn<u32>,
    again: DataOut<u32>,
    /// Each job's number and the quality it ran at.
    done: Done,
}

impl Automaton for JobServer {
    fn spec(&self) -> &'static Spec {
        &SERVER
    }
    fn start(&mut self, _cx: &mut Context) -> Result<(), Fault> {
        Ok(())
    }
    fn stop(&mut self, _cx: &mut Context) {}
    fn section(&mut self, _state: usize, _section: Section, cx: &mut Context) -> SectionResult {
        if let Some(job) = self.jobs.recv() {
            if job > 0 {
                self.again.send(job - 1);
            }
            let work = if cx.quality() == 0 { 25 } else { 1 };
            std::thread::sleep(Duration::from_millis(work));
            self.done.lock().expect("done").push((job, cx.quality()));
        }
        Ok(())
    }
    fn choose(&mut self, _state: usize, _cx: &mut Context) -> Option<usize> {
        None
    }
    fn exception(&mut self, _exception: usize, _message: &str, _cx: &mut Context) {}
    fn answer(&mut self, _output: usize, _cx: &mut Context) -> Result<(), Fault> {
        Ok(())
    }
    fn configure(&mut self, _configuration: &Value) -> Result<(), String> {
        Ok(())
    }
    fn set(&mut self, _variable: usize, _value: &Value) -> Result<(), String> {
        Err("no variables".to_owned())
    }
    fn get(&self, _variable: usize) -> Value {
        Value::Unit
    }
}

/// Poll `handle` until `pred` holds (a response that is not late announces nothing on
/// the monitoring port: `Handle::wait_for` would not wake for it).
fn poll(
    handle: &coolbot::Handle,
    what: &str,
    pred: impl Fn(&coolbot::Monitor) -> bool,
) -> coolbot::Monitor {
    eventually(|| pred(&handle.snapshot()), what);
    handle.snapshot()
}

/// The server `s` and a feeder `f` whose `jobs` output feeds it; the server's own
/// follow-up jobs go through a second feeder output to the same queue.
fn setup() -> (System, coolbot::Handle, DataOut<u32>, Done) {
    let jobs = FifoIn::new(16, OverflowPolicy::Reject);
    let again = DataOut::new();
    let done = Arc::new(Mutex::new(Vec::new()));
    let server = Component::new(
        "s",
        Box::new(JobServer {
            jobs: jobs.clone(),
            again: again.clone(),
            done: Arc::clone(&done),
        }),
        PortSet::new().input(&jobs),
    );
    let feed = DataOut::new();
    let feeder = ShellBuilder::new("f")
        .output(shell::output("jobs", OutputKind::Data, false), &feed)
        .output(shell::output("again", OutputKind::Data, false), &again)
        .build();
    let mut system = System::new();
    let handle = system.add(server).expect("add server");
    system.add(feeder).expect("add feeder");
    system.connect("f.jobs", "s.jobs").expect("connect");
    system.connect("f.again", "s.jobs").expect("connect");
    system.run_all().expect("run");
    (system, handle, feed, done)
}

#[test]
fn a_packet_that_waits_in_the_queue_makes_a_late_response_though_no_section_is_late() {
    let (system, handle, feed, done) = setup();
    let events = handle.subscribe();
    // Job 1 queues job 0 as it starts: job 0 waits the rest of job 1's 25 ms, then
    // runs its own 25 ms. Its response is at least 50 ms, beyond the 40 ms bound,
    // while each section takes 25 ms.
    feed.send(1);
    let monitor = poll(&handle, "two responses", |m| m.response.count >= 2);
    assert_eq!(
        *done.lock().expect("done"),
        [(1, 0), (0, 0)],
        "both jobs, in order"
    );
    assert_eq!(monitor.response.late, 1, "{:?}", monitor.response);
    assert!(
        monitor.response.worst >= Duration::from_millis(50),
        "the wait in the queue counts: {:?}",
        monitor.response
    );
    let late: Vec<_> = events
        .try_iter()
        .filter_map(|event| match event {
            MonitorEvent::LateResponse { took, bound, total } => Some((took, bound, total)),
            _ => None,
        })
        .collect();
    assert_eq!(late.len(), 1, "{late:?}");
    assert_eq!((late[0].1, late[0].2), (MAX_RESPONSE, 1));
    assert!(late[0].0 >= Duration::from_millis(50), "{late:?}");
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}

#[test]
fn late_responses_degrade_the_quality_and_short_ones_promote_it_back() {
    let (system, handle, feed, done) = setup();
    let monitor = handle.snapshot();
    assert!(
        monitor.adaptation.enabled,
        "on by default: no period, a max_response and quality levels"
    );
    // Chains of two: the second job of each chain is late (see above). Two late
    // responses in a window of four are a violation: quality 1.
    let mut sent = 0;
    while handle.snapshot().quality == 0 {
        assert!(sent < 10, "not degraded after {sent} chains");
        let before = handle.snapshot().response.count;
        feed.send(1);
        sent += 1;
        poll(&handle, "the chain's responses", |m| {
            m.response.count >= before + 2 || m.quality > 0
        });
    }
    let degraded = handle
        .wait_for(|m| m.adaptation.level == 1, WAIT)
        .expect("degraded");
    let step = degraded.adaptation.history.last().expect("a step");
    assert_eq!(step.action, AdaptAction::Degraded);
    assert_eq!(step.quality, Some(1));
    assert_eq!(
        step.period, None,
        "an aperiodic component has no period to stretch"
    );

    // At quality 1 a job takes 1 ms: single jobs, one at a time, respond within 30 ms
    // (0.75 of the bound) and make spare time: back to quality 0.
    let mut singles = 0;
    while handle.snapshot().adaptation.level == 1 {
        assert!(
            singles < 200,
            "not promoted after {singles} short responses"
        );
        let before = handle.snapshot().response.count;
        feed.send(0);
        singles += 1;
        poll(&handle, "a response", |m| m.response.count > before);
    }
    let promoted = handle.snapshot();
    let step = promoted.adaptation.history.last().expect("a step");
    assert_eq!(step.action, AdaptAction::Promoted, "{step}");
    assert_eq!(promoted.quality, 0);
    assert!(
        done.lock()
            .expect("done")
            .iter()
            .any(|(_, quality)| *quality == 1),
        "jobs ran at quality 1 meanwhile"
    );
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}
