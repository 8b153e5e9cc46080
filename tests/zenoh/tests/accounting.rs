//! Every packet accounted for across kills of either end's process: fifty times in a
//! row, `kill -9` of another OS process and a new one started in its place.
//!
//! **The consumer killed.** A producer here streams poses through an outlet to a
//! consumer process (`inlet-under-test`), which prints what its inlet's ledger records
//! (every message received, every acknowledgment answered). The outlet counts at its
//! input what it could not send (nobody subscribed) and what a killed consumer was
//! sent and never acknowledged, and says, for each killed consumer, from which number
//! it counted. With P the poses produced, R those received (over every life of the
//! consumer), G the numbers the consumer counted missing, and L the outlet's count:
//! P = R + G + L − O exactly, where O is what both sides counted: the numbers a killed
//! consumer received, or counted missing, after the number the outlet counted from
//! (its newest acknowledgment that reached the outlet). O is at least what follows
//! the consumer's own last acknowledgment line.
//!
//! **The producer killed.** A producer process (`outlet-under-test`) streams poses to
//! a consumer here and prints each number its outlet hands to Zenoh, after writing it
//! to its tally; each new producer reads the tally its killed predecessor left and
//! reports that epoch's newest number to the inlets. With S the numbers the producers
//! printed (each life's newest), R the poses received and G the numbers the inlet
//! counted missing (gaps and reports): S ≤ R + G ≤ S + kills (a producer killed
//! between its tally and its line reports one more than it printed).
//!
//! Each soak runs twice: with poses, small and a millisecond apart or faster, and with
//! chunks of 4 MiB at 30 Hz, which go through shared memory (both ends are on this
//! host). With chunks, the soak also counts the shared-memory segments the killed
//! processes had open: once a node opens after the soak, none is left that no process
//! maps. A consumer keeps mapped each producer life's pool and metadata (Zenoh 1.10
//! never unmaps a sender's segments: eclipse-zenoh/zenoh#2787); the soak bounds that
//! at two per life.

use std::collections::BTreeSet;
use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

use coolbot::System;
use coolbot::crossbeam_channel::{self, Receiver, Sender};
use coolbot::port::UfifoIn;
use coolbot_zenoh_tests::generated::types::{Chunk, Pose};
use coolbot_zenoh_tests::soak::Streamed;
use coolbot_zenoh_tests::support::{self, PATIENCE, wait_until};
use zenoh::Wait;

const KEY: &str = "test/accounting";
const ROUNDS: usize = 50;

/// Held by each soak: one at a time (each keeps a process streaming as fast as it can
/// or every millisecond, on a 2-core machine).
static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn one_at_a_time() -> std::sync::MutexGuard<'static, ()> {
    ONE_AT_A_TIME
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// A process of the test, killed (`kill -9`) when dropped.
struct Process(Child);

impl Drop for Process {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// What one life of a process printed.
#[derive(Default, Debug)]
struct Life {
    ready: bool,
    /// A consumer's: its process, the numbers received (each with how many it counted
    /// missing just before it), the newest number of each acknowledgment.
    process: Option<String>,
    received: Vec<(u64, u64)>,
    missing: u64,
    acknowledged: Vec<u64>,
    /// A producer's: the newest number it handed to Zenoh.
    sent: u64,
    /// A consumer's: the resets its ledger counted (none from an honest outlet).
    resets: u64,
}

impl Life {
    /// The numbers after `from` this consumer received or counted missing.
    fn after(&self, from: u64) -> u64 {
        self.received
            .iter()
            .filter(|&&(seq, _)| seq > from)
            .map(|&(seq, missing)| 1 + missing.min(seq - 1 - from))
            .sum()
    }

    fn read(&mut self, line: &str) {
        let words: Vec<&str> = line.split_whitespace().collect();
        let number = |at: usize| words.get(at).and_then(|w| w.parse::<u64>().ok());
        if line.trim() == "ready" {
            self.ready = true;
        } else if let Some(at) = words.iter().position(|w| *w == "process") {
            self.process = words.get(at + 1).map(|w| (*w).to_owned());
        } else if let Some(at) = words.iter().position(|w| *w == "received") {
            let missing = number(at + 4).expect("a count");
            self.received
                .push((number(at + 2).expect("a number"), missing));
            self.missing += missing;
        } else if let Some(at) = words.iter().position(|w| *w == "acknowledged") {
            self.acknowledged.push(number(at + 2).expect("a number"));
        } else if let Some(at) = words.iter().position(|w| *w == "sent") {
            self.sent = self.sent.max(number(at + 2).expect("a number"));
        } else if words.contains(&"reset") {
            self.resets += 1;
        }
    }
}

/// Start `command`, its lines sent to `lines` as life `life`'s.
fn spawn(command: &mut Command, life: usize, lines: &Sender<(usize, String)>) -> Process {
    // Its standard input stays open while the test lives: it ends when it closes.
    let mut child = command
        .stdin(Stdio::piped())
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
    Process(child)
}

/// The consumer process, reading `key` (packets `P`) from the node at `endpoint`, its
/// state directory `state` (not the user's).
fn consumer<P: Streamed>(
    endpoint: &str,
    key: &str,
    state: &std::path::Path,
    life: usize,
    lines: &Sender<(usize, String)>,
) -> Process {
    spawn(
        Command::new(env!("CARGO_BIN_EXE_inlet-under-test"))
            .args([endpoint, key, P::ARG])
            .env("COOLBOT_STATE_DIR", state),
        life,
        lines,
    )
}

/// The shared-memory segments (`/dev/shm/*.zenoh`) that process `pid` has open: its
/// own pool, and those of the processes it reads from.
fn segments_of(pid: &str) -> BTreeSet<PathBuf> {
    std::fs::read_dir(format!("/proc/{pid}/fd"))
        .map(|entries| {
            entries
                .filter_map(|entry| std::fs::read_link(entry.ok()?.path()).ok())
                .filter(|target| {
                    target.starts_with("/dev/shm")
                        && target.extension().is_some_and(|e| e == "zenoh")
                })
                .collect()
        })
        .unwrap_or_default()
}

/// The segments some live process of this host has open.
fn segments_in_use() -> BTreeSet<PathBuf> {
    std::fs::read_dir("/proc")
        .expect("/proc")
        .filter_map(|entry| entry.ok()?.file_name().into_string().ok())
        .filter(|name| name.bytes().all(|b| b.is_ascii_digit()))
        .flat_map(|pid| segments_of(&pid))
        .collect()
}

/// The segments the killed lives of a soak had open, each read just before its kill.
#[derive(Default)]
struct Segments {
    killed: BTreeSet<PathBuf>,
}

impl Segments {
    fn before_kill(&mut self, process: &Process) {
        self.killed.extend(segments_of(&process.0.id().to_string()));
    }

    /// Once every life is killed: the killed processes had segments open (the chunks
    /// went through shared memory); those that still exist with no live process
    /// mapping them are removed when a node opens; and those a live process still has
    /// open are at most `retained`. This process keeps every segment it has read from
    /// (Zenoh 1.10 never unmaps a sender's pool nor its metadata:
    /// eclipse-zenoh/zenoh#2787), so with Zenoh 1.10 nothing is left unmapped and the
    /// count of kept segments is the figure: two for each producer life.
    fn check_reclaimed(&self, retained: usize) {
        assert!(
            !self.killed.is_empty(),
            "no killed process had a segment open: the chunks did not go through shared memory"
        );
        let orphans = |in_use: &BTreeSet<PathBuf>| -> Vec<PathBuf> {
            self.killed
                .iter()
                .filter(|s| s.exists() && !in_use.contains(*s))
                .cloned()
                .collect()
        };
        let before = orphans(&segments_in_use());
        let _reclaimer = coolbot_zenoh::Node::open(
            "soak-reclaimer",
            coolbot_zenoh::peer_config(&[], &[], false).expect("config"),
        )
        .expect("the node opens");
        let in_use = segments_in_use();
        let leaked = orphans(&in_use);
        let kept = self.killed.iter().filter(|s| in_use.contains(*s)).count();
        eprintln!(
            "segments the killed processes had open: {}, left behind before a node opened: {}, \
             after: {}, still open by a live process: {kept}",
            self.killed.len(),
            before.len(),
            leaked.len(),
        );
        assert!(leaked.is_empty(), "segments left behind: {leaked:?}");
        assert!(
            kept <= retained,
            "{kept} segments of the killed processes are still open, more than {retained}"
        );
    }
}

/// Whether `pattern`'s liveliness tokens are all gone, as `node` sees them, within
/// the patience.
fn gone(node: &coolbot_zenoh::Node, pattern: &str) -> bool {
    wait_until(PATIENCE, || {
        node.session()
            .liveliness()
            .get(pattern)
            .timeout(Duration::from_millis(200))
            .wait()
            .map(|replies| replies.recv().is_err())
            .unwrap_or(false)
    })
}

/// A fixed sequence of lifetimes from 20 to 200 ms (xorshift).
fn lifetimes() -> impl FnMut() -> Duration {
    let mut state = 0x2545_f491_4f6c_dd1d_u64;
    move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        Duration::from_millis(20 + state % 180)
    }
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

/// What the outlets of this process counted for ended inlets
/// (`coolbot_zenoh::OUTLET_LEDGER_TARGET`): per inlet process, the number counted
/// from. Installed once for the test binary.
fn outlet_counts() -> Arc<std::sync::Mutex<Vec<u8>>> {
    static LINES: std::sync::OnceLock<Arc<std::sync::Mutex<Vec<u8>>>> = std::sync::OnceLock::new();
    Arc::clone(LINES.get_or_init(|| {
        let lines = Arc::new(std::sync::Mutex::new(Vec::new()));
        let written = Arc::clone(&lines);
        tracing_subscriber::fmt()
            .with_env_filter(tracing_subscriber::EnvFilter::new(format!(
                "{}=trace",
                coolbot_zenoh::OUTLET_LEDGER_TARGET
            )))
            .with_writer(move || Lines(Arc::clone(&written)))
            .with_ansi(false)
            .without_time()
            .init();
        lines
    }))
}

/// A writer appending to shared bytes.
struct Lines(Arc<std::sync::Mutex<Vec<u8>>>);

impl std::io::Write for Lines {
    fn write(&mut self, bytes: &[u8]) -> std::io::Result<usize> {
        self.0.lock().unwrap().extend_from_slice(bytes);
        Ok(bytes.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// The number the outlet counted from, per inlet process (the last chunk of the inlet's
/// id in `<key> counted <node>/<name>/<process> from <n> to <end>`).
fn counted_from(lines: &std::sync::Mutex<Vec<u8>>) -> std::collections::HashMap<String, u64> {
    String::from_utf8_lossy(&lines.lock().unwrap())
        .lines()
        .filter_map(|line| {
            let words: Vec<&str> = line.split_whitespace().collect();
            let at = words.iter().position(|w| *w == "counted")?;
            let process = words.get(at + 1)?.rsplit('/').next()?.to_owned();
            let from = words.get(at + 3)?.parse().ok()?;
            Some((process, from))
        })
        .collect()
}

#[test]
fn a_consumer_killed_fifty_times_has_every_packet_received_or_counted_lost() {
    let _alone = one_at_a_time();
    consumer_killed::<Pose>(KEY, None);
}

#[test]
fn a_consumer_of_chunks_in_shared_memory_killed_fifty_times_loses_no_count_nor_segment() {
    let _alone = one_at_a_time();
    let mut segments = Segments::default();
    consumer_killed::<Chunk>("test/accounting-chunks", Some(&mut segments));
    // The producer's own pool and metadata, which the consumers read.
    segments.check_reclaimed(2);
}

/// The consumer soak with packets `P` on `key`; the segments of the killed consumers
/// noted in `segments` when given.
fn consumer_killed<P: Streamed>(key: &str, mut segments: Option<&mut Segments>) {
    let outlet_lines = outlet_counts();
    let state = tempfile::tempdir().unwrap();
    let (source, endpoint) = support::node("source", &[]);
    let mut producer = System::new();
    producer
        .add(
            source
                .outlet::<P>("outlet", key, P::OUTLET)
                .build()
                .unwrap(),
        )
        .unwrap();
    let (hand, handed) = crossbeam_channel::bounded(1);
    producer.add(P::source("producer", hand)).unwrap();
    producer.connect("producer.out", "outlet.input").unwrap();
    producer.run_all().unwrap();
    let out = handed
        .recv_timeout(PATIENCE)
        .expect("the producer's output");
    let outlet = producer.handle("outlet").unwrap();

    // A pose a millisecond (a chunk each 33 ms), all along: while a consumer runs,
    // while it is killed, while the next one starts.
    let produced = Arc::new(AtomicU64::new(0));
    let stop = Arc::new(AtomicBool::new(false));
    let pause = P::PAUSE.max(Duration::from_millis(1));
    let pump = {
        let (produced, stop) = (Arc::clone(&produced), Arc::clone(&stop));
        std::thread::spawn(move || {
            while !stop.load(Ordering::Acquire) {
                let seq = produced.load(Ordering::Acquire) + 1;
                out.send(P::numbered(seq));
                produced.store(seq, Ordering::Release);
                std::thread::sleep(pause);
            }
        })
    };
    // Stops the pump however this function ends (a failed assertion too).
    struct Stop(Arc<AtomicBool>);
    impl Drop for Stop {
        fn drop(&mut self) {
            self.0.store(true, Ordering::Release);
        }
    }
    let stopping = Stop(Arc::clone(&stop));

    let (lines, printed) = crossbeam_channel::unbounded();
    let mut lives = Vec::new();
    // Lifetimes from 20 to 200 ms after the first receipt: some consumers die before
    // acknowledging anything, some after several answers.
    let mut lifetime = lifetimes();
    for life in 0..ROUNDS {
        let mut process = consumer::<P>(&endpoint, key, state.path(), life, &lines);
        assert!(
            read_until(&printed, &mut lives, |lives| lives
                .get(life)
                .is_some_and(|l| !l.received.is_empty())),
            "consumer {life} receives"
        );
        // Every fifth lives long enough to acknowledge several times (checked below):
        // the outlet asks when a consumer is 16 packets behind, or a second after its
        // last question; 48 packets are three questions.
        let long = Duration::from_millis(450).max(pause * 48);
        std::thread::sleep(if life % 5 == 4 { long } else { lifetime() });
        assert!(
            matches!(process.0.try_wait(), Ok(None)),
            "consumer {life} ended before its kill"
        );
        if let Some(segments) = segments.as_deref_mut() {
            segments.before_kill(&process);
        }
        drop(process); // kill -9
        assert!(
            gone(&source, &format!("{key}/@in/**")),
            "the outlet's node sees consumer {life} gone"
        );
    }
    let last = ROUNDS;
    let final_consumer = consumer::<P>(&endpoint, key, state.path(), last, &lines);
    assert!(read_until(&printed, &mut lives, |lives| lives
        .get(last)
        .is_some_and(|l| !l.received.is_empty())));
    drop(stopping);
    pump.join().unwrap();
    let p = produced.load(Ordering::Acquire);

    // R + G + L − O, O from where the outlet counted each killed consumer from.
    let counts = |lives: &[Life]| {
        let from = counted_from(&outlet_lines);
        let r: u64 = lives.iter().map(|l| l.received.len() as u64).sum();
        let g: u64 = lives.iter().map(|l| l.missing).sum();
        let l = outlet.snapshot().overflows;
        let mut o = 0;
        let mut settled = 0;
        for life in &lives[..ROUNDS] {
            let process = life
                .process
                .as_ref()
                .expect("each consumer says its process");
            if let Some(&from) = from.get(process) {
                settled += 1;
                o += life.after(from);
            }
        }
        (r, g, l, o, settled)
    };
    let accounted = read_until(&printed, &mut lives, |lives| {
        let (r, g, l, o, settled) = counts(lives);
        settled == ROUNDS && r + g + l >= p + o
    });
    let (r, g, l, o, settled) = counts(&lives);
    // The outlet counted from no further than each consumer's last acknowledgment.
    let own: u64 = lives[..ROUNDS]
        .iter()
        .map(|l| l.after(l.acknowledged.last().copied().unwrap_or(0)))
        .sum();
    let acknowledged: usize = lives.iter().map(|l| l.acknowledged.len()).sum();
    eprintln!(
        "produced {p}, received {r}, counted missing {g}, counted lost at the outlet {l}, \
         counted both ways {o} (after the last acknowledgment line: {own}), \
         {acknowledged} acknowledgments, {settled} consumers settled"
    );
    if !(accounted && r + g + l == p + o) {
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
    assert_eq!(
        settled, ROUNDS,
        "the outlet counted for every killed consumer"
    );
    assert_eq!(
        r + g + l,
        p + o,
        "produced = received + missing + lost - counted both ways"
    );
    assert!(o >= own, "the outlet counted from beyond an acknowledgment");
    assert_eq!(
        lives.iter().map(|l| l.resets).sum::<u64>(),
        0,
        "an honest outlet's numbers stay within the ledger's window"
    );
    // And from no nearer than the acknowledgment before the last: that answer was
    // made a round or more before the kill, so it reached the outlet. (An outlet that
    // ignored acknowledgments, counting from where it first saw each consumer, keeps
    // the equation above and fails here.)
    let from = counted_from(&outlet_lines);
    let mut checked = 0;
    for (i, life) in lives[..ROUNDS].iter().enumerate() {
        if let (Some(process), [.., before, _]) = (&life.process, life.acknowledged.as_slice()) {
            let counted = from[process];
            assert!(
                counted >= *before,
                "consumer {i}: the outlet counted from {counted}, before its acknowledgment of {before}"
            );
            checked += 1;
        }
    }
    assert!(
        checked >= ROUNDS / 10,
        "only {checked} consumers acknowledged twice or more"
    );
    if let Some(segments) = segments {
        segments.before_kill(&final_consumer);
    }
    drop(final_consumer);
}

#[test]
fn a_producer_killed_fifty_times_has_every_packet_it_sent_received_or_counted_lost() {
    let _alone = one_at_a_time();
    producer_killed::<Pose>("test/accounting-producer", 3_000, None);
}

#[test]
fn a_producer_of_chunks_in_shared_memory_killed_fifty_times_loses_no_count_nor_segment() {
    let _alone = one_at_a_time();
    let mut segments = Segments::default();
    producer_killed::<Chunk>("test/accounting-producer-chunks", 100, Some(&mut segments));
    // Two for each producer life (its pool and metadata), which this process keeps
    // mapped; one more was counted in one run of the two soaks with chunks alone (not
    // explained).
    segments.check_reclaimed(2 * (ROUNDS + 1) + 1);
}

/// The producer soak with packets `P` on `key`, the last producer sending `last`; the
/// segments of the killed producers noted in `segments` when given.
fn producer_killed<P: Streamed>(key: &str, last: u64, mut segments: Option<&mut Segments>) {
    let state = tempfile::tempdir().unwrap();
    let (node, endpoint) = support::node("accounting-consumer", &[]);
    let mut consumer = System::new();
    consumer
        .add(
            node.inlet::<P>("inlet", key, coolbot::OutputKind::Data)
                .build()
                .unwrap(),
        )
        .unwrap();
    let (hand, handed) = crossbeam_channel::bounded(1);
    consumer.add(P::queue("sink", hand)).unwrap();
    consumer.connect("inlet.output", "sink.input").unwrap();
    consumer.run_all().unwrap();
    let input = handed.recv_timeout(PATIENCE).expect("the consumer's input");
    let inlet = consumer.handle("inlet").unwrap();

    let producer = |life: usize, limit: Option<u64>, lines: &Sender<(usize, String)>| {
        let mut command = Command::new(env!("CARGO_BIN_EXE_outlet-under-test"));
        command
            .args([endpoint.as_str(), key, P::ARG])
            .args(limit.map(|limit| limit.to_string()))
            .env("COOLBOT_STATE_DIR", state.path());
        spawn(&mut command, life, lines)
    };
    let (lines, printed) = crossbeam_channel::unbounded();
    let mut lives = Vec::new();
    let mut received = 0u64;
    let mut last_seq = 0u64;
    let mut damaged = 0u64;
    let mut drain = |input: &UfifoIn<P>| {
        for packet in input.drain() {
            received += 1;
            last_seq = packet.seq();
            damaged += u64::from(!packet.intact());
        }
        (received, last_seq)
    };
    let mut lifetime = lifetimes();
    for life in 0..ROUNDS {
        let mut process = producer(life, None, &lines);
        // Sending, and heard: the inlet has had this epoch (a report of an epoch it
        // never had is not counted: it cannot know it was subscribed then).
        let before = drain(&input).0;
        assert!(
            read_until(&printed, &mut lives, |lives| lives
                .get(life)
                .is_some_and(|l| l.sent > 0)
                && drain(&input).0 > before),
            "producer {life} is heard"
        );
        // Every fifth lives longer, with several tally writes and reports behind it.
        let long = Duration::from_millis(450);
        std::thread::sleep(if life % 5 == 4 { long } else { lifetime() });
        assert!(
            matches!(process.0.try_wait(), Ok(None)),
            "producer {life} ended before its kill"
        );
        if let Some(segments) = segments.as_deref_mut() {
            segments.before_kill(&process);
        }
        drop(process); // kill -9
        assert!(
            gone(&node, "coolbot/accounting-producer"),
            "producer {life} seen gone"
        );
    }
    let final_producer = producer(ROUNDS, Some(last), &lines);
    let counts = |lives: &[Life], received: u64| {
        let sent: u64 = lives.iter().map(|l| l.sent).sum();
        (sent, received, inlet.snapshot().overflows)
    };
    let accounted = read_until(&printed, &mut lives, |lives| {
        let (received, last_seq) = drain(&input);
        let (sent, received, missing) = counts(lives, received);
        last_seq == last && received + missing >= sent
    });
    let (received, _) = drain(&input);
    let (sent, received, missing) = counts(&lives, received);
    eprintln!(
        "sent {sent} (each producer's newest number), received {received}, \
         counted missing at the inlet {missing}"
    );
    assert!(
        accounted,
        "packets lost without a count: sent {sent} > received {received} + missing {missing}"
    );
    assert!(
        received + missing <= sent + ROUNDS as u64,
        "counted more than one per kill beyond what was sent: {received} + {missing} > {sent} + {ROUNDS}"
    );
    assert_eq!(
        inlet.snapshot().port_overflows,
        [("network".to_owned(), missing), ("resets".to_owned(), 0)],
        "the killed producers' reports stay within the ledger's window"
    );
    assert_eq!(damaged, 0, "packets arrived damaged");
    if let Some(segments) = segments {
        segments.before_kill(&final_producer);
    }
    drop(final_producer);
}
