//! Every packet accounted for across kills of the consumer's process: a producer here
//! streams poses through an outlet while the consumer, another OS process
//! (`inlet-under-test`), is killed with `kill -9` and started again fifty times.
//!
//! The consumer prints what its inlet's ledger records (every message received, every
//! acknowledgment answered); the outlet counts at its input what it could not send
//! (nobody subscribed) and what a killed consumer was sent and never acknowledged.
//! Then, with P the poses produced, R those received (over every life of the
//! consumer), G the numbers the consumer counted missing, and L the outlet's count:
//! P = R + G + L − O, where O, the poses a killed consumer received after its last
//! acknowledgment that reached the outlet (counted both received and lost), lies
//! between what the consumer's own lines allow: from its last acknowledgment (it
//! reached the outlet) to the one before (the last was lost with the process).

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

use coolbot::crossbeam_channel::{self, Receiver, Sender};
use coolbot::port::DataOut;
use coolbot::{InputKind, System};
use coolbot_zenoh_tests::generated::pose_source;
use coolbot_zenoh_tests::generated::types::Pose;
use coolbot_zenoh_tests::support::{self, PATIENCE, wait_until};
use zenoh::Wait;

const KEY: &str = "test/accounting";
const ROUNDS: usize = 50;

/// The producer's behaviour: hands its output to the test when it starts.
struct Hand(Sender<DataOut<Pose>>);

impl pose_source::Behavior for Hand {
    fn start(&mut self, cx: &mut pose_source::Cx<'_>) -> coolbot::SectionResult {
        let _ = self.0.send(cx.outputs.out.clone());
        Ok(())
    }
}

/// A consumer process, killed when dropped.
struct Consumer(Child);

impl Drop for Consumer {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// What one life of the consumer printed.
#[derive(Default, Debug)]
struct Life {
    ready: bool,
    received: Vec<u64>,
    missing: u64,
    acknowledged: Vec<u64>,
}

impl Life {
    /// Received after `newest` (None: no acknowledgment reached the outlet).
    fn after(&self, newest: Option<u64>) -> u64 {
        let newest = newest.unwrap_or(0);
        self.received.iter().filter(|&&seq| seq > newest).count() as u64
    }

    fn read(&mut self, line: &str) {
        let words: Vec<&str> = line.split_whitespace().collect();
        let number = |at: usize| words.get(at).and_then(|w| w.parse::<u64>().ok());
        if line.trim() == "ready" {
            self.ready = true;
        } else if let Some(at) = words.iter().position(|w| *w == "received") {
            self.received.push(number(at + 2).expect("a number"));
            self.missing += number(at + 4).expect("a count");
        } else if let Some(at) = words.iter().position(|w| *w == "acknowledged") {
            self.acknowledged.push(number(at + 2).expect("a number"));
        }
    }
}

fn spawn(endpoint: &str, life: usize, lines: &Sender<(usize, String)>) -> Consumer {
    let mut child = Command::new(env!("CARGO_BIN_EXE_inlet-under-test"))
        .args([endpoint, KEY])
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("the consumer starts");
    let stdout = child.stdout.take().expect("piped");
    let lines = lines.clone();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            let _ = lines.send((life, line));
        }
    });
    Consumer(child)
}

/// Read what the consumers printed into `lives` until `condition` holds (or the
/// patience runs out: false).
fn read_until(
    lines: &Receiver<(usize, String)>,
    lives: &mut Vec<Life>,
    mut condition: impl FnMut(&[Life]) -> bool,
) -> bool {
    let deadline = std::time::Instant::now() + PATIENCE;
    loop {
        while let Ok((life, line)) = lines.try_recv() {
            if lives.len() <= life {
                lives.resize_with(life + 1, Life::default);
            }
            lives[life].read(&line);
        }
        if condition(lives) {
            return true;
        }
        if std::time::Instant::now() >= deadline {
            return false;
        }
        if let Ok((life, line)) = lines.recv_timeout(Duration::from_millis(20)) {
            if lives.len() <= life {
                lives.resize_with(life + 1, Life::default);
            }
            lives[life].read(&line);
        }
    }
}

#[test]
fn a_consumer_killed_fifty_times_has_every_packet_received_or_counted_lost() {
    let (source, endpoint) = support::node("source", &[]);
    let mut producer = System::new();
    let kind = InputKind::Ufifo {
        initial: 64,
        max: Some(1 << 20),
    };
    producer
        .add(source.outlet::<Pose>("outlet", KEY, kind).build().unwrap())
        .unwrap();
    let (hand, handed) = crossbeam_channel::bounded(1);
    producer
        .add(pose_source::component("producer", Hand(hand)))
        .unwrap();
    producer.connect("producer.out", "outlet.input").unwrap();
    producer.run_all().unwrap();
    let out = handed
        .recv_timeout(PATIENCE)
        .expect("the producer's output");
    let outlet = producer.handle("outlet").unwrap();

    // A pose a millisecond, all along: while a consumer runs, while it is killed,
    // while the next one starts.
    let produced = Arc::new(AtomicU64::new(0));
    let stop = Arc::new(AtomicBool::new(false));
    let pump = {
        let (produced, stop) = (Arc::clone(&produced), Arc::clone(&stop));
        std::thread::spawn(move || {
            while !stop.load(Ordering::Acquire) {
                let seq = produced.load(Ordering::Acquire) + 1;
                out.send(Pose { x: seq as f64, seq });
                produced.store(seq, Ordering::Release);
                std::thread::sleep(Duration::from_millis(1));
            }
        })
    };

    let (lines, printed) = crossbeam_channel::unbounded();
    let mut lives = Vec::new();
    // A fixed sequence of lifetimes from 20 to 200 ms after the first receipt: some
    // consumers die before acknowledging anything, some after several answers.
    let mut state = 0x2545_f491_4f6c_dd1d_u64;
    let inlets_gone = || {
        wait_until(PATIENCE, || {
            source
                .session()
                .liveliness()
                .get(format!("{KEY}/@in/**"))
                .timeout(Duration::from_millis(200))
                .wait()
                .map(|replies| replies.recv().is_err())
                .unwrap_or(false)
        })
    };
    for life in 0..ROUNDS {
        let consumer = spawn(&endpoint, life, &lines);
        assert!(
            read_until(&printed, &mut lives, |lives| lives
                .get(life)
                .is_some_and(|l| !l.received.is_empty())),
            "consumer {life} receives"
        );
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        std::thread::sleep(Duration::from_millis(20 + state % 180));
        drop(consumer); // kill -9
        assert!(inlets_gone(), "the outlet's node sees consumer {life} gone");
    }
    let last = ROUNDS;
    let _final = spawn(&endpoint, last, &lines);
    assert!(read_until(&printed, &mut lives, |lives| lives
        .get(last)
        .is_some_and(|l| !l.received.is_empty())));
    stop.store(true, Ordering::Release);
    pump.join().unwrap();
    let p = produced.load(Ordering::Acquire);

    // R + G + L − O: with O as small as the consumers' lines allow (each last
    // acknowledgment reached the outlet), and as large.
    let counts = |lives: &[Life]| {
        let killed = &lives[..ROUNDS];
        let r: u64 = lives.iter().map(|l| l.received.len() as u64).sum();
        let g: u64 = lives.iter().map(|l| l.missing).sum();
        let l = outlet.snapshot().overflows;
        let low: u64 = killed
            .iter()
            .map(|l| l.after(l.acknowledged.last().copied()))
            .sum();
        let high: u64 = killed
            .iter()
            .map(|l| {
                let before_last = l.acknowledged.len().checked_sub(2);
                l.after(before_last.map(|at| l.acknowledged[at]))
            })
            .sum();
        (r, g, l, low, high)
    };
    let accounted = read_until(&printed, &mut lives, |lives| {
        let (r, g, l, low, _) = counts(lives);
        r + g + l >= p + low
    });
    let (r, g, l, low, high) = counts(&lives);
    let upheld = r + g + l <= p + high;
    if !(accounted && upheld) {
        for (i, life) in lives.iter().enumerate() {
            eprintln!(
                "consumer {i}: received {:?}..={:?} ({}), acknowledged {:?}",
                life.received.first(),
                life.received.last(),
                life.received.len(),
                life.acknowledged
            );
        }
    }
    let acknowledged: usize = lives.iter().map(|l| l.acknowledged.len()).sum();
    eprintln!(
        "produced {p}, received {r}, counted missing {g}, counted lost at the outlet {l}, \
         received after the last acknowledgment {low}..={high}, {acknowledged} acknowledgments"
    );
    assert!(
        accounted,
        "packets lost without a count: produced {p} > received {r} + missing {g} + lost {l} - {low}"
    );
    assert!(
        upheld,
        "counted lost more than was lost: received {r} + missing {g} + lost {l} - {high} > produced {p}"
    );
}
