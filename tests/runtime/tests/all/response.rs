//! Response time as the paper defines it (3.6): for an aperiodic component, the delay
//! from a packet's arrival ("temporal labeling of input data") to the end of the `on`
//! transition that handled it, queueing included. A late response is a timing
//! violation: the component degrades its quality and is promoted back when responses
//! are short again. Work is simulated with sleeps (lower bounds), so the outcomes do
//! not depend on the machine's load; the tests assert outcomes, never timings.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use coolbot::adapt::AdaptAction;
use coolbot::crossbeam_channel::{self, Sender};
use coolbot::port::DataOut;
use coolbot::{AdaptConfig, Clock, MonitorEvent, SectionResult, System, VirtualClock};
use coolbot_runtime_tests::generated::{job_feeder, job_server, retrying_server};
use coolbot_runtime_tests::support::{WAIT, eventually};

/// `JobServer`'s `max_response` (`cool/response.cool`).
const MAX_RESPONSE: Duration = Duration::from_millis(40);

/// The jobs done: each one's number and the quality it ran at.
type Done = Arc<Mutex<Vec<(u32, usize)>>>;

/// `on jobs -> work` in both states: each arrival enters `work`, whose entry takes one
/// job from the queue; a job `n > 0` queues job `n - 1` itself at the start of its
/// section (on `again`, connected to its own `jobs`, so that job waits behind it),
/// then works: 25 ms at quality 0, 1 ms at quality 1.
struct JobServer {
    /// Each job's number and the quality it ran at.
    done: Done,
}

impl job_server::Behavior for JobServer {
    fn work_entry(&mut self, cx: &mut job_server::Cx<'_>) -> SectionResult {
        if let Some(job) = cx.inputs.jobs.recv() {
            if job > 0 {
                cx.outputs.again.send(job - 1);
            }
            let work = if cx.rt.quality() == 0 { 25 } else { 1 };
            std::thread::sleep(Duration::from_millis(work));
            self.done.lock().expect("done").push((job, cx.rt.quality()));
        }
        Ok(())
    }
}

/// Hands the feeder's output to the test when it starts.
struct Hand(Sender<DataOut<u32>>);

impl job_feeder::Behavior for Hand {
    fn start(&mut self, cx: &mut job_feeder::Cx<'_>) -> SectionResult {
        let _ = self.0.send(cx.outputs.jobs.clone());
        Ok(())
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

/// The server `s`, whose follow-up jobs go from its `again` back to its own `jobs`,
/// and a feeder `f` whose `jobs` output feeds it.
fn setup() -> (System, coolbot::Handle, DataOut<u32>, Done) {
    let done = Arc::new(Mutex::new(Vec::new()));
    let server = job_server::component(
        "s",
        JobServer {
            done: Arc::clone(&done),
        },
    )
    // Spare time judged from the responses alone, so that promotion does not depend
    // on what else the machine runs (the idle probe has tests of its own).
    .with_adaptation(AdaptConfig {
        idle_probe: false,
        ..AdaptConfig::default()
    });
    let (hand, feed) = crossbeam_channel::bounded(1);
    let mut system = System::new();
    let handle = system.add(server).expect("add server");
    system
        .add(job_feeder::component("f", Hand(hand)))
        .expect("add feeder");
    system.connect("f.jobs", "s.jobs").expect("connect");
    system.connect("s.again", "s.jobs").expect("connect");
    system.run_all().expect("run");
    let feed = feed.recv_timeout(WAIT).expect("the feeder started");
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
    assert!(monitor.response.late >= 1, "{:?}", monitor.response);
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
    // Job 0's response, at least 50 ms, is late (job 1's 25 ms section could be too on
    // a very loaded machine: the assertion is on the queued one).
    assert!(
        late.iter()
            .any(|(took, bound, _)| *took >= Duration::from_millis(50) && *bound == MAX_RESPONSE),
        "{late:?}"
    );
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}

#[test]
fn late_responses_degrade_the_quality_and_short_ones_promote_it_back() {
    let (system, handle, feed, done) = setup();
    let monitor = handle.snapshot();
    assert!(
        monitor.adaptation.enabled,
        "on (`enabled: None`, the default): no period, a max_response and quality levels"
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

/// `RetryingServer`'s behaviour: the entry fails `refusals` times, then takes the job.
struct Refusing {
    refusals: u32,
}

impl retrying_server::Behavior for Refusing {
    fn work_entry(&mut self, cx: &mut retrying_server::Cx<'_>) -> SectionResult {
        if self.refusals > 0 {
            self.refusals -= 1;
            return Err(retrying_server::Exception::Busy.raise("not yet"));
        }
        cx.inputs.jobs.recv();
        Ok(())
    }

    fn on_busy(&mut self, _cx: &mut retrying_server::Cx<'_>, _message: &str) {}
}

/// The transition a job causes is over when its entry section's retry worked: on a
/// virtual clock, the entry fails at 0 and 10 ms and works at 20 ms, so the response
/// takes 20 ms, beyond the 15 ms bound.
#[test]
fn a_response_ends_when_the_retried_entry_of_its_transition_works() {
    retried_response(None);
}

/// The same with the server suspended for 500 ms between two attempts: time
/// suspended is no response time, the response still takes 20 ms.
#[test]
fn time_suspended_during_a_retry_is_no_response_time() {
    retried_response(Some(Duration::from_millis(500)));
}

/// A job to `RetryingServer` on a virtual clock, its entry refused twice; with
/// `pause`, suspended that long after the first retry.
fn retried_response(pause: Option<Duration>) {
    let clock = VirtualClock::new();
    let mut system = System::with_clock(Clock::virtual_clock(&clock));
    let handle = system
        .add(retrying_server::component("s", Refusing { refusals: 2 }))
        .expect("add server");
    let (hand, feed) = crossbeam_channel::bounded(1);
    system
        .add(job_feeder::component("f", Hand(hand)))
        .expect("add feeder");
    system.connect("f.jobs", "s.jobs").expect("connect");
    system.run_all().expect("run");
    let feed = feed.recv_timeout(WAIT).expect("the feeder started");
    clock.settle().expect("settled");
    feed.send(1);
    poll(&handle, "in `work`", |m| {
        m.user_state.as_deref() == Some("work")
    });
    // (Taken once the turn that entered `work`, with the entry's first attempt, is over.)
    handle
        .command(coolbot::Command::SetPriority(0))
        .expect("a round trip");
    assert_eq!(handle.snapshot().response.count, 0, "no response yet");
    clock.advance(Duration::from_millis(10)).expect("settled");
    if let Some(pause) = pause {
        let state = |target| coolbot::Command::SetState(target);
        handle
            .command(state(coolbot::Controllable::Suspended))
            .expect("suspended");
        clock.advance(pause).expect("settled");
        handle
            .command(state(coolbot::Controllable::Running))
            .expect("resumed");
    }
    clock.advance(Duration::from_millis(10)).expect("settled");
    let monitor = handle.snapshot();
    assert_eq!(monitor.response.count, 1, "{:?}", monitor.response);
    assert_eq!(monitor.response.worst, Duration::from_millis(20));
    assert_eq!(monitor.response.late, 1);
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}
