//! Recording and replay of port traffic (`coolbot::record`): every packet a tapped
//! producer sends is in the file or counted as lost, a recording replays into a
//! consumer as the same sequence, mistakes are clear errors, and ports inside
//! compounds are reached by path.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::Duration;

use coolbot::crossbeam_channel::{self, Receiver, Sender};
use coolbot::port::{DataOut, FifoIn, PosterOut, TickIn, TickOut};
use coolbot::record::{
    self, NOT_SERIALIZABLE, Pace, Player, QUEUE_FULL, ReadError, Reader, Record, RecordError,
    RecordFormat, Recorder,
};
use coolbot::ros::RosType;
use coolbot::{Command, Component, Controllable, MonitorEvent, SectionResult, State, System};
use coolbot_runtime_tests::generated::{
    record_holder, record_poster_source, record_sink, record_source,
};
use coolbot_runtime_tests::record::{Hook, Sample, sample};

/// How long tests wait for anything (generous: the machine is shared).
const WAIT: Duration = Duration::from_secs(20);

/// The test's ends of a source's outputs (`out`, `beat`).
struct Outputs {
    out: DataOut<Sample>,
    beat: TickOut,
}

/// The test's ends of a sink's inputs (`data`, `beat`).
struct Inputs {
    data: FifoIn<Sample>,
    beat: TickIn,
}

/// A `RecordSource`'s behaviour: it hands clones of its outputs to the test when it
/// starts.
struct HandOutputs(Sender<Outputs>);

impl record_source::Behavior for HandOutputs {
    fn start(&mut self, cx: &mut record_source::Cx<'_>) -> SectionResult {
        let _ = self.0.send(Outputs {
            out: cx.outputs.out.clone(),
            beat: cx.outputs.beat.clone(),
        });
        Ok(())
    }
}

/// A `RecordSink`'s behaviour: it hands clones of its inputs to the test when it
/// starts.
struct HandInputs(Sender<Inputs>);

impl record_sink::Behavior for HandInputs {
    fn start(&mut self, cx: &mut record_sink::Cx<'_>) -> SectionResult {
        let _ = self.0.send(Inputs {
            data: cx.inputs.data.clone(),
            beat: cx.inputs.beat.clone(),
        });
        Ok(())
    }
}

/// A `RecordPosterSource`'s behaviour: it hands a clone of its poster to the test.
struct HandPoster(Sender<PosterOut<Sample>>);

impl record_poster_source::Behavior for HandPoster {
    fn start(&mut self, cx: &mut record_poster_source::Cx<'_>) -> SectionResult {
        let _ = self.0.send(cx.outputs.map.clone());
        Ok(())
    }
}

/// What a handing behaviour handed over (once its component has started).
fn handed<T>(from: &Receiver<T>) -> T {
    from.recv_timeout(WAIT)
        .expect("the component hands its ports over when it starts")
}

/// A `RecordSource` named `name`, and where it hands its outputs over.
fn source(name: &str) -> (Component, Receiver<Outputs>) {
    let (hand, outputs) = crossbeam_channel::bounded(1);
    (record_source::component(name, HandOutputs(hand)), outputs)
}

/// A `RecordSink` named `name`, and where it hands its inputs over.
fn sink(name: &str) -> (Component, Receiver<Inputs>) {
    let (hand, inputs) = crossbeam_channel::bounded(1);
    (record_sink::component(name, HandInputs(hand)), inputs)
}

/// A running system with a source `src` and a sink `sink` (not connected).
fn bench_with_ticks() -> (System, Outputs, Inputs) {
    let mut system = System::new();
    let (src, outputs) = source("src");
    let (consumer, inputs) = sink("sink");
    system.add(src).expect("add src");
    system.add(consumer).expect("add sink");
    system.run_all().expect("run");
    (system, handed(&outputs), handed(&inputs))
}

/// [`bench_with_ticks`], data ports only.
fn bench() -> (System, DataOut<Sample>, FifoIn<Sample>) {
    let (system, outputs, inputs) = bench_with_ticks();
    (system, outputs.out, inputs.data)
}

fn temp_file(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("coolbot-record-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    dir.join(name)
}

fn records(path: &std::path::Path) -> Vec<Record> {
    Reader::open(path)
        .expect("open")
        .collect::<Result<Vec<_>, _>>()
        .expect("every line is a record")
}

fn packets(records: &[Record], port: &str) -> Vec<(u64, Sample)> {
    records
        .iter()
        .filter_map(|record| match record {
            Record::Packet(packet) if packet.port == port => {
                Some((packet.seq, packet.decode::<Sample>().expect("decodes")))
            }
            _ => None,
        })
        .collect()
}

#[test]
fn a_full_tap_loses_packets_counted_and_reported_never_silently() {
    let (system, out, _data) = bench();
    let path = temp_file("full.mcap");
    let mut recorder = Recorder::new().capacity(4);
    recorder.tap::<Sample>(&system, "src.out").expect("tap");
    let recording = recorder.start(&path).expect("start");

    // The first packet holds the recorder's thread inside serde until released, so
    // the queue fills deterministically: 4 packets wait, the next 6 are lost.
    let (entered_sender, entered) = crossbeam_channel::bounded(1);
    let (release, gate) = crossbeam_channel::bounded(1);
    let mut first = sample(0);
    first.hook = Some(Arc::new(Hook {
        fail: false,
        entered: entered_sender,
        release: gate,
    }));
    out.send(first);
    entered.recv_timeout(WAIT).expect("the recorder serializes");
    for n in 1..=10 {
        out.send(sample(n));
    }
    assert_eq!(
        recording.stats()[0].lost,
        6,
        "the producer counted the losses"
    );
    release.send(()).expect("release");
    let loss = recording
        .losses()
        .recv_timeout(WAIT)
        .expect("a loss notice");
    assert_eq!(
        (loss.port.as_str(), loss.reason.as_str()),
        ("src.out", QUEUE_FULL)
    );
    let summary = recording.finish().expect("finish");

    let port = &summary.ports[0];
    assert_eq!((port.sent, port.recorded, port.lost), (11, 5, 6));
    let records = records(&path);
    let recorded = packets(&records, "src.out");
    let seqs: Vec<u64> = recorded.iter().map(|(seq, _)| *seq).collect();
    assert_eq!(seqs, [0, 1, 2, 3, 4], "the queued packets, in order");
    assert!(recorded.iter().all(|(seq, s)| *s == sample(*seq)));
    let lost: u64 = records
        .iter()
        .filter_map(|r| match r {
            Record::Lost(loss) if loss.port == "src.out" => Some(loss.lost),
            _ => None,
        })
        .sum();
    assert_eq!(lost, 6, "the file says how many were lost");
    assert_eq!(records.last(), Some(&Record::End(summary)));
    drop(system);
}

#[test]
fn under_load_every_packet_is_recorded_or_counted_lost() {
    let (system, out, _data) = bench();
    let path = temp_file("load.mcap");
    let mut recorder = Recorder::new().capacity(64);
    recorder.tap::<Sample>(&system, "src.out").expect("tap");
    let recording = recorder.start(&path).expect("start");
    const SENT: u64 = 20_000;
    let senders: Vec<_> = (0..2)
        .map(|half| {
            let out = out.clone();
            std::thread::spawn(move || {
                for n in (half * SENT / 2)..((half + 1) * SENT / 2) {
                    out.send(sample(n));
                }
            })
        })
        .collect();
    for sender in senders {
        sender.join().expect("sender");
    }
    let summary = recording.finish().expect("finish");
    let port = &summary.ports[0];
    assert_eq!(port.sent, SENT);
    assert_eq!(port.recorded + port.lost, SENT);

    let records = records(&path);
    let recorded = packets(&records, "src.out");
    assert_eq!(recorded.len() as u64, port.recorded);
    let mut seqs: Vec<u64> = recorded.iter().map(|(seq, _)| *seq).collect();
    seqs.sort_unstable();
    seqs.dedup();
    assert_eq!(seqs.len() as u64, port.recorded, "no packet twice");
    assert!(seqs.iter().all(|seq| *seq < SENT));
    let lost: u64 = records
        .iter()
        .filter_map(|r| match r {
            Record::Lost(loss) => Some(loss.lost),
            _ => None,
        })
        .sum();
    assert_eq!(lost, port.lost, "every loss is in the file");
    drop(system);
}

#[test]
fn a_packet_that_does_not_serialize_is_counted_lost() {
    let (system, out, _data) = bench();
    let path = temp_file("unserializable.mcap");
    let mut recorder = Recorder::new();
    recorder.tap::<Sample>(&system, "src.out").expect("tap");
    let recording = recorder.start(&path).expect("start");
    let (entered, _) = crossbeam_channel::bounded(1);
    let (_, release) = crossbeam_channel::bounded(1);
    out.send(sample(0));
    out.send(Sample {
        hook: Some(Arc::new(Hook {
            fail: true,
            entered,
            release,
        })),
        ..sample(1)
    });
    out.send(sample(2));
    let summary = recording.finish().expect("finish");
    let port = &summary.ports[0];
    assert_eq!((port.sent, port.recorded, port.lost), (3, 2, 1));
    let records = records(&path);
    let seqs: Vec<u64> = packets(&records, "src.out").iter().map(|p| p.0).collect();
    assert_eq!(seqs, [0, 2]);
    assert!(records.iter().any(|r| matches!(
        r,
        Record::Lost(loss) if loss.reason == NOT_SERIALIZABLE && loss.lost == 1
    )));
    drop(system);
}

#[test]
fn a_recording_replays_into_a_consumer_as_the_same_sequence() {
    let path = temp_file("replay.mcap");
    let sent: Vec<Sample> = (0..200).map(sample).collect();
    {
        let (system, out, _data) = bench();
        let mut recorder = Recorder::new();
        recorder.tap::<Sample>(&system, "src.out").expect("tap");
        let recording = recorder.start(&path).expect("start");
        for packet in &sent {
            out.send(packet.clone());
        }
        let summary = recording.finish().expect("finish");
        assert_eq!(summary.ports[0].recorded, 200);
    }

    for pace in [Pace::AsFastAsPossible, Pace::Original] {
        let (system, _out, data) = bench();
        let mut player = Player::open(&path).expect("open");
        assert_eq!(player.header().ports[0].path, "src.out");
        player
            .route::<Sample>("src.out", &system, "sink.data")
            .expect("route");
        let played = player.play(pace).expect("play");
        assert_eq!(played.sent["src.out"], 200, "{pace:?}");
        let received: Vec<Sample> = data.drain().collect();
        assert_eq!(received, sent, "{pace:?}: the same sequence");
    }

    // Offline: the typed packets of one port.
    let offline: Vec<Sample> = Reader::open(&path)
        .expect("open")
        .packets::<Sample>("src.out")
        .map(|item| item.expect("decodes").1)
        .collect();
    assert_eq!(offline, sent);
}

#[test]
fn mistakes_are_clear_errors() {
    let (system, _out, _data) = bench();
    let mut recorder = Recorder::new();
    let error = recorder
        .tap::<String>(&system, "src.out")
        .expect_err("wrong type");
    assert!(matches!(error, RecordError::TypeMismatch { .. }), "{error}");
    let message = error.to_string();
    assert!(
        message.contains("Sample") && message.contains("String") && message.contains("src.out"),
        "{message}"
    );
    let error = recorder
        .tap::<Sample>(&system, "src.nothing")
        .expect_err("unknown port");
    assert_eq!(
        error.to_string(),
        "`src.nothing`: component `src` has no output port `nothing` (it has: out, beat)"
    );
    let error = recorder
        .tap::<Sample>(&system, "ghost.out")
        .expect_err("unknown component");
    assert!(
        matches!(error, RecordError::UnknownComponent { .. }),
        "{error}"
    );
    let error = recorder.tap::<Sample>(&system, "src").expect_err("no port");
    assert!(matches!(error, RecordError::BadPath { .. }), "{error}");
    let error = recorder
        .tap::<Sample>(&system, "src.beat")
        .expect_err("a tick output");
    assert!(
        matches!(error, RecordError::UnsupportedKind { .. }),
        "{error}"
    );
    let error = recorder
        .tap_ticks(&system, "src.out")
        .expect_err("a data output");
    assert!(
        matches!(error, RecordError::UnsupportedKind { .. }),
        "{error}"
    );
    let error = recorder
        .tap::<Sample>(&system, ".out")
        .expect_err("no component");
    assert!(matches!(error, RecordError::BadPath { .. }), "{error}");
    recorder.tap::<Sample>(&system, "src.out").expect("tap");
    let error = recorder
        .tap::<Sample>(&system, "src.out")
        .expect_err("twice");
    assert!(matches!(error, RecordError::Duplicate(_)), "{error}");
    let error = recorder
        .monitor(&system, "nobody")
        .expect_err("unknown component");
    assert!(
        matches!(error, RecordError::UnknownComponent { .. }),
        "{error}"
    );

    let path = temp_file("mistakes.mcap");
    drop(recorder.start(&path).expect("start"));
    let mut player = Player::open(&path).expect("open");
    let error = player
        .route::<Sample>("elsewhere.out", &system, "sink.data")
        .expect_err("not recorded");
    assert_eq!(
        error.to_string(),
        "the recording has no port `elsewhere.out` (it has: src.out)"
    );
    let error = player
        .route::<String>("src.out", &system, "sink.data")
        .expect_err("wrong type");
    assert!(matches!(error, RecordError::TypeMismatch { .. }), "{error}");

    // A file that is not MCAP at all.
    let not_mcap = temp_file("not-mcap.mcap");
    std::fs::write(&not_mcap, "{\"kind\":\"end\"}\n").expect("write");
    let error = Reader::open(&not_mcap).expect_err("not MCAP");
    assert!(matches!(error, ReadError::Mcap { .. }), "{error}");
    // An MCAP file that is not a recording: a channel before any header.
    let not_a_recording = temp_file("not-a-recording.mcap");
    {
        let file = std::fs::File::create(&not_a_recording).expect("create");
        let mut writer = mcap::Writer::new(std::io::BufWriter::new(file)).expect("writer");
        writer
            .add_channel(0, "elsewhere", "json", &Default::default())
            .expect("channel");
        writer.finish().expect("finish");
    }
    assert!(matches!(
        Reader::open(&not_a_recording),
        Err(ReadError::NoHeader { .. })
    ));
    // A recording of a later format version.
    let future = temp_file("future.mcap");
    {
        let file = std::fs::File::create(&future).expect("create");
        let mut writer = mcap::Writer::new(std::io::BufWriter::new(file)).expect("writer");
        writer
            .write_metadata(&mcap::records::Metadata {
                name: "coolbot.header".to_owned(),
                metadata: [(
                    "header".to_owned(),
                    "{\"version\":99,\"shape\":\"new\"}".to_owned(),
                )]
                .into(),
            })
            .expect("metadata");
        writer.finish().expect("finish");
    }
    let error = Reader::open(&future).expect_err("a future version");
    assert!(
        matches!(error, ReadError::Version { found: 99, .. }),
        "{error}"
    );
    assert_eq!(record::FORMAT_VERSION, 2);
}

/// `RecordHolder`'s supervisor has no sections.
struct Holds;

impl record_holder::Supervisor for Holds {}

/// `RecordHolder`'s parts: its source hands its outputs over.
struct Holding(Option<HandOutputs>);

impl record_holder::Parts for Holding {
    fn supervisor(&mut self) -> impl record_holder::Supervisor {
        Holds
    }

    fn src(&mut self) -> impl record_source::Behavior {
        self.0.take().expect("one source")
    }
}

#[test]
fn ports_and_monitors_inside_a_compound_are_reached_by_path() {
    let (hand, outputs) = crossbeam_channel::bounded(1);
    let compound =
        record_holder::component("base", Holding(Some(HandOutputs(hand)))).expect("build");
    let mut system = System::new();
    system.add(compound).expect("add");
    system.start().expect("start");

    let path = temp_file("compound.mcap");
    let mut recorder = Recorder::new();
    recorder
        .tap::<Sample>(&system, "base.src.out")
        .expect("inner tap");
    recorder
        .tap::<Sample>(&system, "base.out")
        .expect("exported tap");
    recorder
        .monitor(&system, "base.src")
        .expect("inner monitor");
    let recording = recorder.start(&path).expect("start");
    system.run_all().expect("run");
    let inner = system
        .handle("base")
        .and_then(|h| h.instance("src"))
        .expect("src");
    inner.wait_state(State::Running, WAIT).expect("running");
    let Outputs { out, .. } = handed(&outputs);
    for n in 0..50 {
        out.send(sample(n));
    }
    let summary = recording.finish().expect("finish");
    for port in &summary.ports {
        assert_eq!((port.sent, port.recorded), (50, 50), "{}", port.port);
    }
    let records = records(&path);
    let expected: Vec<(u64, Sample)> = (0..50).map(|n| (n, sample(n))).collect();
    assert_eq!(packets(&records, "base.src.out"), expected);
    assert_eq!(packets(&records, "base.out"), expected);
    let states: Vec<State> = records
        .iter()
        .filter_map(|r| match r {
            Record::Event(event) if event.component == "base.src" => match event.event {
                MonitorEvent::State { to, .. } => Some(to),
                _ => None,
            },
            _ => None,
        })
        .collect();
    assert!(
        states.contains(&State::Running),
        "the instance's way to running is recorded: {states:?}"
    );
    assert_eq!(summary.monitors[0].events, {
        records
            .iter()
            .filter(|r| matches!(r, Record::Event(_)))
            .count() as u64
    });
    drop(system);
}

#[test]
fn tick_events_are_recorded_and_replayed() {
    let path = temp_file("ticks.mcap");
    {
        let (system, outputs, _inputs) = bench_with_ticks();
        let mut recorder = Recorder::new();
        recorder.tap_ticks(&system, "src.beat").expect("tap ticks");
        recorder
            .tap::<Sample>(&system, "src.out")
            .expect("tap data");
        let recording = recorder.start(&path).expect("start");
        for n in 0..5 {
            outputs.beat.emit();
            outputs.out.send(sample(n));
        }
        let summary = recording.finish().expect("finish");
        let counts: Vec<(u64, u64)> = summary.ports.iter().map(|p| (p.sent, p.recorded)).collect();
        assert_eq!(counts, [(5, 5), (5, 5)]);
    }
    let reader = Reader::open(&path).expect("open");
    let kinds: Vec<&str> = reader
        .header()
        .ports
        .iter()
        .map(|p| p.kind.as_str())
        .collect();
    assert_eq!(kinds, ["tick", "data"]);
    let events: Vec<u64> = reader
        .packets::<()>("src.beat")
        .map(|item| item.expect("an event").0.seq)
        .collect();
    assert_eq!(events, [0, 1, 2, 3, 4]);

    let (system, _outputs, inputs) = bench_with_ticks();
    let mut player = Player::open(&path).expect("open");
    player
        .route_ticks("src.beat", &system, "sink.beat")
        .expect("route ticks");
    let error = player
        .route_ticks("src.out", &system, "sink.data")
        .expect_err("a data input");
    assert!(
        matches!(error, RecordError::UnsupportedKind { .. }),
        "{error}"
    );
    let played = player.play(Pace::AsFastAsPossible).expect("play");
    assert_eq!(played.sent["src.beat"], 5);
    assert_eq!(played.skipped, 5, "the data port has no route");
    assert_eq!(inputs.beat.take(), 5);
    assert!(inputs.data.is_empty());
}

#[test]
fn a_recording_dropped_after_its_system_still_ends_its_file() {
    let path = temp_file("dropped.mcap");
    let (system, out, _data) = bench();
    let mut recorder = Recorder::new();
    recorder.tap::<Sample>(&system, "src.out").expect("tap");
    recorder.monitor(&system, "src").expect("monitor");
    let recording = recorder.start(&path).expect("start");
    for n in 0..10 {
        out.send(sample(n));
    }
    assert!(system.shutdown().clean());
    // The producer's handle outlives its system: what it sends now is still seen.
    out.send(sample(10));
    drop(recording);
    let records = records(&path);
    let Some(Record::End(summary)) = records.last() else {
        panic!("no end record: {:?}", records.last());
    };
    assert_eq!((summary.ports[0].sent, summary.ports[0].recorded), (11, 11));
    assert!(
        records.iter().any(|r| matches!(
            r,
            Record::Event(event) if matches!(event.event, MonitorEvent::State { to: State::Dead, .. })
        )),
        "the shutdown is in the recording"
    );
}

#[test]
fn every_post_of_a_tapped_poster_output_is_recorded_or_counted() {
    let (hand, poster) = crossbeam_channel::bounded(1);
    let mut system = System::new();
    system
        .add(record_poster_source::component("src", HandPoster(hand)))
        .expect("add src");
    system.run_all().expect("run");
    let map = handed(&poster);
    let path = temp_file("poster.mcap");
    let mut recorder = Recorder::new().capacity(4);
    recorder
        .tap::<Sample>(&system, "src.map")
        .expect("tap a poster");
    let recording = recorder.start(&path).expect("start");
    const POSTS: u64 = 2_000;
    for n in 0..POSTS {
        map.post(sample(n));
    }
    let summary = recording.finish().expect("finish");
    let port = &summary.ports[0];
    assert_eq!(port.port, "src.map");
    assert_eq!(port.sent, POSTS);
    assert_eq!(port.recorded + port.lost, POSTS, "{port:?}");
    let values: Vec<u64> = Reader::open(&path)
        .expect("open")
        .packets::<Sample>("src.map")
        .map(|item| item.expect("a post").1.n)
        .collect();
    assert_eq!(values.len() as u64, port.recorded);
    assert!(
        values.windows(2).all(|pair| pair[0] < pair[1]),
        "posts are recorded in order"
    );
    let reader = Reader::open(&path).expect("open");
    assert_eq!(reader.header().ports[0].kind, "poster");
    assert_eq!(
        map.posted(),
        Some(sample(POSTS - 1)),
        "the post itself is kept"
    );
    assert!(system.shutdown().clean());
}

#[test]
fn monitoring_events_the_recorder_cannot_keep_up_with_are_counted_and_reported_lost() {
    let (system, out, _data) = bench();
    let handle = system.handle("src").expect("src");
    let path = temp_file("monitor-lost.mcap");
    let mut recorder = Recorder::new();
    recorder.tap::<Sample>(&system, "src.out").expect("tap");
    recorder.monitor(&system, "src").expect("monitor");
    let recording = recorder.start(&path).expect("start");

    // A packet holds the recorder's thread inside serde until released (a slow disk):
    // meanwhile the component publishes more events than the recorder's subscription
    // holds (one `Period` event per command), and the rest are dropped for it.
    let (entered_sender, entered) = crossbeam_channel::bounded(1);
    let (release, gate) = crossbeam_channel::bounded(1);
    let mut held = sample(0);
    held.hook = Some(Arc::new(Hook {
        fail: false,
        entered: entered_sender,
        release: gate,
    }));
    out.send(held);
    entered.recv_timeout(WAIT).expect("the recorder serializes");
    const COMMANDS: u64 = coolbot::OBSERVER_CAPACITY as u64 + 600;
    for n in 0..COMMANDS {
        let period = Duration::from_millis(if n % 2 == 0 { 11 } else { 12 });
        handle.command(Command::SetPeriod(period)).expect("period");
    }
    release.send(()).expect("release");
    let summary = recording.finish().expect("finish");
    let monitor = &summary.monitors[0];
    assert!(monitor.sent >= COMMANDS, "{monitor:?}");
    assert_eq!(monitor.sent, monitor.events + monitor.lost, "{monitor:?}");
    assert!(monitor.lost >= 600, "{monitor:?}");

    let records = records(&path);
    let events = records
        .iter()
        .filter(|r| matches!(r, Record::Event(e) if e.component == "src"))
        .count() as u64;
    assert_eq!(
        events, monitor.events,
        "the summary counts the event records"
    );
    let losses: Vec<_> = records
        .iter()
        .filter_map(|r| match r {
            Record::Lost(loss) if loss.port == "src" => Some(loss),
            _ => None,
        })
        .collect();
    assert!(losses.iter().all(|loss| loss.reason == QUEUE_FULL));
    assert_eq!(
        losses.iter().map(|loss| loss.lost).sum::<u64>(),
        monitor.lost,
        "every lost event is in a `lost` record"
    );
    assert_eq!(losses.last().map(|loss| loss.total), Some(monitor.lost));
    let Some(Record::End(end)) = records.last() else {
        panic!("no end record");
    };
    assert_eq!(end.monitors, summary.monitors);

    // A replay tells event losses from packet losses.
    let played = Player::open(&path)
        .expect("open")
        .play(Pace::AsFastAsPossible)
        .expect("play");
    assert_eq!((played.lost, played.lost_events), (0, monitor.lost));
    drop(system);
}

/// The JSON of an MCAP message.
fn json_of(data: &[u8]) -> serde_json::Value {
    serde_json::from_slice(data).expect("a JSON message")
}

#[test]
fn an_mcap_reader_of_its_own_finds_the_schemas_channels_and_counts() {
    // Read back with the `mcap` crate's own readers (its summary section and its
    // message stream), not with `coolbot::record::Reader`.
    let path = temp_file("independent.mcap");
    let (system, outputs, _inputs) = bench_with_ticks();
    let mut recorder = Recorder::new();
    recorder.tap::<Sample>(&system, "src.out").expect("tap");
    recorder.tap_ticks(&system, "src.beat").expect("tap ticks");
    recorder.monitor(&system, "src").expect("monitor");
    let recording = recorder.start(&path).expect("start");
    for n in 0..20 {
        if n == 7 {
            // One packet that does not serialize: a loss, written on the losses channel.
            let (entered, _) = crossbeam_channel::bounded(1);
            let (_, release) = crossbeam_channel::bounded(1);
            outputs.out.send(Sample {
                hook: Some(Arc::new(Hook {
                    fail: true,
                    entered,
                    release,
                })),
                ..sample(n)
            });
        } else {
            outputs.out.send(sample(n));
        }
    }
    for _ in 0..3 {
        outputs.beat.emit();
    }
    // Monitoring events: the source is stopped and started again.
    let src = system.handle("src").expect("src");
    src.command(Command::SetState(Controllable::Ready))
        .expect("ready");
    src.command(Command::SetState(Controllable::Running))
        .expect("running");
    // The ticks are seen by the recorder's thread when it wakes: wait for them.
    let deadline = std::time::Instant::now() + WAIT;
    while recording.stats()[1].recorded < 3 && std::time::Instant::now() < deadline {
        std::thread::yield_now();
    }
    let summary = recording.finish().expect("finish");
    assert_eq!(
        summary
            .ports
            .iter()
            .map(|p| (p.sent, p.recorded, p.lost))
            .collect::<Vec<_>>(),
        [(20, 19, 1), (3, 3, 0)]
    );
    let events = summary.monitors[0].events;
    assert!(events >= 4, "two state changes, each from and to: {events}");

    let bytes = std::fs::read(&path).expect("read");
    let found = mcap::Summary::read(&bytes)
        .expect("an MCAP summary")
        .expect("a summary section");
    let mut topics: Vec<(&str, &str, &str, &str)> = found
        .channels
        .values()
        .map(|channel| {
            let schema = channel.schema.as_ref().expect("every channel has a schema");
            (
                channel.topic.as_str(),
                channel.message_encoding.as_str(),
                schema.encoding.as_str(),
                schema.name.as_str(),
            )
        })
        .collect();
    topics.sort();
    assert_eq!(
        topics,
        [
            (
                "coolbot/losses",
                "json",
                "jsonschema",
                "coolbot::record::LossRecord"
            ),
            ("src.beat", "json", "jsonschema", "event"),
            (
                "src.out",
                "json",
                "jsonschema",
                std::any::type_name::<Sample>()
            ),
            ("src/events", "json", "jsonschema", "coolbot::MonitorEvent"),
        ]
    );
    let channel = |topic: &str| {
        found
            .channels
            .values()
            .find(|c| c.topic == topic)
            .expect("the channel")
            .clone()
    };
    // The packet type's schema, traced from its `Deserialize`.
    let out = channel("src.out");
    let schema = json_of(&out.schema.as_ref().expect("schema").data);
    assert_eq!(schema["type"], "object");
    assert_eq!(schema["title"], "Sample");
    assert_eq!(schema["properties"]["n"]["type"], "integer");
    assert_eq!(schema["properties"]["n"]["minimum"], 0);
    assert_eq!(schema["properties"]["label"]["type"], "string");
    assert_eq!(schema["required"], serde_json::json!(["n", "label"]));
    assert_eq!(out.metadata["coolbot.kind"], "data");
    assert_eq!(out.metadata["coolbot.schema"], "traced");
    assert_eq!(out.metadata["coolbot.wrapped"], "");
    // A tick is not an object: wrapped as `{"value": null}`.
    let beat = channel("src.beat");
    let schema = json_of(&beat.schema.as_ref().expect("schema").data);
    // A tick's value is `null`, which the viewers' part of JSON Schema has no type
    // for: the wrapped schema names no property (`coolbot::schema::for_viewers`).
    assert_eq!(schema["properties"], serde_json::json!({}), "{schema}");
    // A schema given (the tick's is the runtime's) is kept whole beside it.
    let given: serde_json::Value =
        serde_json::from_str(&beat.metadata["coolbot.schema.given"]).expect("JSON");
    assert_eq!(given["type"], "null", "{given}");
    assert!(!out.metadata.contains_key("coolbot.schema.given"));
    assert_eq!(beat.metadata["coolbot.wrapped"], "value");
    let losses = channel("coolbot/losses");
    let schema = json_of(&losses.schema.as_ref().expect("schema").data);
    assert_eq!(schema["properties"]["lost"]["type"], "integer");

    // The counts: the statistics and the messages themselves.
    let stats = found.stats.as_ref().expect("statistics");
    let count = |topic: &str| stats.channel_message_counts[&channel(topic).id];
    assert_eq!(count("src.out"), 19);
    assert_eq!(count("src.beat"), 3);
    assert_eq!(count("coolbot/losses"), 1);
    assert_eq!(count("src/events"), events);
    let mut sequences = Vec::new();
    let mut lost = Vec::new();
    let mut times = Vec::new();
    for message in mcap::MessageStream::new(&bytes).expect("a message stream") {
        let message = message.expect("a message");
        times.push(message.log_time);
        let value = json_of(&message.data);
        match message.channel.topic.as_str() {
            "src.out" => {
                let n = value["n"].as_u64().expect("n");
                assert_eq!(u64::from(message.sequence), n);
                assert_eq!(value["label"], format!("sample {n}"));
                sequences.push(message.sequence);
            }
            "src.beat" => assert_eq!(value, serde_json::json!({ "value": null })),
            "coolbot/losses" => lost.push((value["port"].clone(), value["lost"].clone())),
            "src/events" => assert!(value.is_object() || value.is_string(), "{value}"),
            other => panic!("a message on {other}"),
        }
    }
    let expected: Vec<u32> = (0..20).filter(|n| *n != 7).collect();
    assert_eq!(sequences, expected, "the gap is the lost packet");
    assert_eq!(lost, [(serde_json::json!("src.out"), serde_json::json!(1))]);

    // The header and the end, as metadata; times are Unix nanoseconds from the start.
    let mut metadata = BTreeMap::new();
    for index in &found.metadata_indexes {
        let record = mcap::read::metadata(&bytes, index).expect("a metadata record");
        metadata.insert(record.name.clone(), record.metadata);
    }
    let header = json_of(metadata["coolbot.header"]["header"].as_bytes());
    let start = header["start_unix_ns"].as_u64().expect("start");
    assert!(
        times.iter().all(|t| *t >= start),
        "log times count from the start"
    );
    assert_eq!(header["ports"][0]["path"], "src.out");
    let end = json_of(metadata["coolbot.end"]["summary"].as_bytes());
    assert_eq!(end["ports"][0]["recorded"], 19);
    assert_eq!(end["ports"][0]["lost"], 1);
    drop(system);
}

#[test]
fn a_recording_on_a_virtual_clock_is_stamped_with_its_times() {
    let path = temp_file("virtual.mcap");
    let (system, out, _data) = bench();
    let clock = coolbot::VirtualClock::new();
    let mut recorder = Recorder::new().clock(coolbot::Clock::virtual_clock(&clock));
    recorder.tap::<Sample>(&system, "src.out").expect("tap");
    let recording = recorder.start(&path).expect("start");
    out.send(sample(0));
    clock
        .advance(Duration::from_millis(10))
        .expect("no component on it");
    out.send(sample(1));
    clock
        .advance(Duration::from_micros(1))
        .expect("no component on it");
    out.send(sample(2));
    recording.finish().expect("finish");
    let times: Vec<u64> = Reader::open(&path)
        .expect("open")
        .packets::<Sample>("src.out")
        .map(|item| item.expect("a packet").0.t)
        .collect();
    assert_eq!(times, [0, 10_000_000, 10_001_000]);
    drop(system);
}

/// A fresh path for a bag directory (the recorder creates it).
fn bag_path(name: &str) -> std::path::PathBuf {
    let path = temp_file(name);
    let _ = std::fs::remove_dir_all(&path);
    path
}

/// A poster output recorded in a bag keeps its kind: the channel's `coolbot.kind`,
/// and the port's kind as the reader gives it back.
#[test]
fn a_poster_in_a_ros2_recording_is_a_poster() {
    let (hand, poster) = crossbeam_channel::bounded(1);
    let mut system = System::new();
    system
        .add(record_poster_source::component("src", HandPoster(hand)))
        .expect("add src");
    system.run_all().expect("run");
    let map = handed(&poster);
    let bag = bag_path("poster_bag");
    let mut recorder = Recorder::new().format(RecordFormat::Ros2);
    recorder.tap_ros::<Sample>(&system, "src.map").expect("tap");
    let recording = recorder.start(&bag).expect("start");
    map.post(sample(1));
    let summary = recording.finish().expect("finish");
    assert_eq!(summary.ports[0].sent, 1);
    let bytes = std::fs::read(bag.join("poster_bag_0.mcap")).expect("the bag's MCAP file");
    let found = mcap::Summary::read(&bytes)
        .expect("an MCAP summary")
        .expect("a summary section");
    let channel = found.channels.values().next().expect("a channel");
    assert_eq!(channel.metadata["coolbot.kind"], "poster");
    let reader = Reader::open(&bag).expect("open");
    assert_eq!(reader.header().ports[0].kind, "poster");
}

#[test]
fn a_ros2_recording_is_a_rosbag2_bag_of_cdr_messages() {
    let (system, out, _data) = bench();
    let bag = bag_path("samples_bag");
    let mut recorder = Recorder::new().format(RecordFormat::Ros2);
    recorder
        .tap_ros_on::<Sample>(&system, "src.out", "/samples")
        .expect("tap");
    let recording = recorder.start(&bag).expect("start");
    for n in 0..3 {
        out.send(sample(n));
    }
    let summary = recording.finish().expect("finish");
    assert_eq!((summary.ports[0].sent, summary.ports[0].recorded), (3, 3));

    // The MCAP file, read with the `mcap` crate: profile `ros2`, the type's schema,
    // the topic's channel as rosbag2 writes them, CDR messages.
    let file = bag.join("samples_bag_0.mcap");
    let bytes = std::fs::read(&file).expect("the bag's MCAP file");
    let mut stream = mcap::read::LinearReader::new(&bytes).expect("MCAP");
    let Some(Ok(mcap::records::Record::Header(header))) = stream.next() else {
        panic!("an MCAP header first");
    };
    assert_eq!(header.profile, "ros2");
    let found = mcap::Summary::read(&bytes)
        .expect("an MCAP summary")
        .expect("a summary section");
    assert_eq!(found.channels.len(), 1, "one channel: the topic");
    let channel = found.channels.values().next().expect("a channel");
    assert_eq!(
        (channel.topic.as_str(), channel.message_encoding.as_str()),
        ("/samples", "cdr")
    );
    assert_eq!(
        channel.metadata["offered_qos_profiles"],
        record::OFFERED_QOS_PROFILES
    );
    assert_eq!(
        channel.metadata["topic_type_hash"],
        <Sample as RosType>::TYPE_HASH
    );
    let schema = channel.schema.as_ref().expect("a schema");
    assert_eq!(
        (schema.name.as_str(), schema.encoding.as_str()),
        ("coolbot_test/msg/Sample", "ros2msg")
    );
    assert_eq!(&schema.data[..], b"uint64 n\nstring label\n");
    let mut times = Vec::new();
    for (n, message) in mcap::MessageStream::new(&bytes)
        .expect("messages")
        .enumerate()
    {
        let message = message.expect("a message");
        let n = u64::try_from(n).unwrap();
        assert_eq!(
            message.data.as_ref(),
            coolbot::cdr::to_vec(&sample(n)).unwrap(),
            "message {n} is the sample's CDR"
        );
        assert_eq!(message.log_time, message.publish_time);
        times.push(message.log_time);
    }
    assert_eq!(times.len(), 3);
    assert!(times.windows(2).all(|w| w[0] <= w[1]), "{times:?}");

    // `metadata.yaml`, and the same metadata in the file, as rosbag2 writes them.
    let yaml = std::fs::read_to_string(bag.join("metadata.yaml")).expect("metadata.yaml");
    let duration = times[2] - times[0];
    let expected = format!(
        "rosbag2_bagfile_information:
  version: 9
  storage_identifier: mcap
  duration:
    nanoseconds: {duration}
  starting_time:
    nanoseconds_since_epoch: {start}
  message_count: 3
  topics_with_message_count:
    - topic_metadata:
        name: /samples
        type: coolbot_test/msg/Sample
        serialization_format: cdr
        offered_qos_profiles:
          - history: keep_last
            depth: 10
            reliability: reliable
            durability: volatile
            deadline:
              sec: 9223372036
              nsec: 854775807
            lifespan:
              sec: 9223372036
              nsec: 854775807
            liveliness: automatic
            liveliness_lease_duration:
              sec: 9223372036
              nsec: 854775807
            avoid_ros_namespace_conventions: false
        type_description_hash: {hash}
      message_count: 3
  compression_format: \"\"
  compression_mode: \"\"
  relative_file_paths:
    - \"samples_bag_0.mcap\"
  files:
    - path: \"samples_bag_0.mcap\"
      starting_time:
        nanoseconds_since_epoch: {start}
      duration:
        nanoseconds: {duration}
      message_count: 3
  custom_data: ~
  ros_distro: coolbot
",
        start = times[0],
        hash = <Sample as RosType>::TYPE_HASH,
    );
    assert_eq!(yaml, expected);
    let mut rosbag2 = None;
    for record in mcap::read::LinearReader::new(&bytes).expect("MCAP") {
        if let mcap::records::Record::Metadata(metadata) = record.expect("a record")
            && metadata.name == "rosbag2"
        {
            rosbag2 = Some(metadata.metadata["serialized_metadata"].clone());
        }
    }
    let inner: String = yaml
        .lines()
        .skip(1)
        .map(|line| line.strip_prefix("  ").unwrap_or(line))
        .collect::<Vec<_>>()
        .join("\n");
    assert_eq!(rosbag2.as_deref(), Some(inner.as_str()));

    // And our own reader reads it back, by port path.
    let reader = Reader::open(&bag).expect("open the bag directory");
    assert_eq!(reader.header().ports[0].path, "src.out");
    let read: Vec<(u64, Sample)> = reader
        .packets::<Sample>("src.out")
        .map(|item| {
            let (packet, value) = item.expect("decodes");
            (packet.seq, value)
        })
        .collect();
    assert_eq!(read, (0..3).map(|n| (n, sample(n))).collect::<Vec<_>>());
    drop(system);
}

#[test]
fn a_ros2_recording_refuses_what_is_not_a_ros_type_naming_it() {
    let (system, _outputs, _inputs) = bench_with_ticks();
    let ros2 = || Recorder::new().format(RecordFormat::Ros2);
    let mut recorder = ros2();
    recorder.tap::<Sample>(&system, "src.out").expect("tap");
    let error = recorder.start(bag_path("refused_a")).unwrap_err();
    assert!(
        matches!(&error, RecordError::NotRosType { path, .. } if path == "src.out"),
        "{error}"
    );
    assert!(error.to_string().contains("tap_ros"), "{error}");
    let mut recorder = ros2();
    recorder.tap_ticks(&system, "src.beat").expect("tap ticks");
    let error = recorder.start(bag_path("refused_b")).unwrap_err();
    assert!(
        matches!(&error, RecordError::NotRosType { path, carries } if path == "src.beat" && carries == "tick events"),
        "{error}"
    );
    let mut recorder = ros2();
    recorder.monitor(&system, "src").expect("monitor");
    let error = recorder.start(bag_path("refused_c")).unwrap_err();
    assert!(
        matches!(&error, RecordError::MonitorNotRos { component } if component == "src"),
        "{error}"
    );
    // Nothing was created for a refused recording.
    assert!(!bag_path("refused_a").exists());

    let mut recorder = ros2();
    let error = recorder
        .tap_ros_on::<Sample>(&system, "src.out", "samples")
        .unwrap_err();
    assert!(matches!(error, RecordError::BadTopic { .. }), "{error}");
    // The default topic is the path's.
    recorder.tap_ros::<Sample>(&system, "src.out").expect("tap");
    let error = recorder
        .tap_ros_on::<Sample>(&system, "sink.data", "/src/out")
        .unwrap_err();
    assert!(matches!(error, RecordError::SameTopic { .. }), "{error}");
    // A bag directory is never written over.
    let taken = bag_path("taken");
    std::fs::create_dir_all(&taken).unwrap();
    let error = recorder.start(&taken).unwrap_err();
    assert!(matches!(error, RecordError::Io { .. }), "{error}");
    drop(system);
}

#[test]
fn a_port_tapped_as_ros_in_the_coolbot_format_is_recorded_as_json() {
    let (system, out, _data) = bench();
    let path = temp_file("ros_as_json.mcap");
    let mut recorder = Recorder::new();
    recorder.tap_ros::<Sample>(&system, "src.out").expect("tap");
    let recording = recorder.start(&path).expect("start");
    out.send(sample(4));
    recording.finish().expect("finish");
    let records = records(&path);
    assert_eq!(packets(&records, "src.out"), [(0, sample(4))]);
    assert!(records.iter().all(|record| match record {
        Record::Packet(packet) => packet.cdr.is_none(),
        _ => true,
    }));
    drop(system);
}

#[test]
fn a_ros2_recording_writes_its_losses_as_metadata_records() {
    let (system, out, _data) = bench();
    let bag = bag_path("lossy_bag");
    let mut recorder = Recorder::new().format(RecordFormat::Ros2).capacity(4);
    recorder.tap_ros::<Sample>(&system, "src.out").expect("tap");
    let recording = recorder.start(&bag).expect("start");
    // As in the coolbot format: the first packet holds the recorder's thread, 4 wait,
    // the next 6 are lost.
    let (entered_sender, entered) = crossbeam_channel::bounded(1);
    let (release, gate) = crossbeam_channel::bounded(1);
    let mut first = sample(0);
    first.hook = Some(Arc::new(Hook {
        fail: false,
        entered: entered_sender,
        release: gate,
    }));
    out.send(first);
    entered.recv_timeout(WAIT).expect("the recorder serializes");
    for n in 1..=10 {
        out.send(sample(n));
    }
    release.send(()).expect("release");
    let summary = recording.finish().expect("finish");
    let port = &summary.ports[0];
    assert_eq!((port.sent, port.recorded, port.lost), (11, 5, 6));
    let records = records(&bag);
    assert_eq!(
        packets(&records, "src.out")
            .iter()
            .map(|(seq, _)| *seq)
            .collect::<Vec<_>>(),
        [0, 1, 2, 3, 4]
    );
    let lost: u64 = records
        .iter()
        .filter_map(|r| match r {
            Record::Lost(loss) if loss.port == "src.out" && loss.reason == QUEUE_FULL => {
                Some(loss.lost)
            }
            _ => None,
        })
        .sum();
    assert_eq!(lost, 6, "the bag says how many were lost");
    assert_eq!(records.last(), Some(&Record::End(summary)));
    // Only the topic's channel: the losses are metadata records.
    let bytes = std::fs::read(bag.join("lossy_bag_0.mcap")).unwrap();
    let found = mcap::Summary::read(&bytes).unwrap().unwrap();
    assert_eq!(found.channels.len(), 1);
    drop(system);
}

/// A rosbag2 bag as another program writes it: profile `ros2`, no CoolBOT header,
/// every sequence 0.
fn foreign_bag(dir: &std::path::Path, samples: &[Sample]) {
    std::fs::create_dir_all(dir).unwrap();
    let file = std::fs::File::create(dir.join("foreign_0.mcap")).unwrap();
    let mut mcap = mcap::WriteOptions::new()
        .profile("ros2")
        .create(std::io::BufWriter::new(file))
        .unwrap();
    let schema = mcap
        .add_schema(
            "coolbot_test/msg/Sample",
            "ros2msg",
            b"uint64 n\nstring label\n",
        )
        .unwrap();
    let channel = mcap
        .add_channel(schema, "/samples", "cdr", &BTreeMap::new())
        .unwrap();
    for (n, value) in samples.iter().enumerate() {
        let time = 1_700_000_000_000_000_000 + u64::try_from(n).unwrap() * 1_000_000;
        mcap.write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id: channel,
                sequence: 0,
                log_time: time,
                publish_time: time,
            },
            &coolbot::cdr::to_vec(value).unwrap(),
        )
        .unwrap();
    }
    mcap.finish().unwrap();
}

#[test]
fn a_bag_another_program_wrote_replays_by_topic() {
    let bag = bag_path("foreign");
    let sent: Vec<Sample> = (0..5).map(sample).collect();
    foreign_bag(&bag, &sent);
    let reader = Reader::open(&bag).expect("open");
    assert_eq!(reader.header().ports.len(), 1);
    assert_eq!(
        (
            reader.header().ports[0].path.as_str(),
            reader.header().ports[0].type_name.as_str()
        ),
        ("/samples", "coolbot_test/msg/Sample")
    );
    let read: Vec<(u64, u64, Sample)> = reader
        .packets::<Sample>("/samples")
        .map(|item| {
            let (packet, value) = item.expect("decodes");
            (packet.t, packet.seq, value)
        })
        .collect();
    assert_eq!(
        read,
        sent.iter()
            .enumerate()
            .map(|(n, s)| {
                let n = u64::try_from(n).unwrap();
                (n * 1_000_000, n, s.clone())
            })
            .collect::<Vec<_>>(),
        "times from the first message, sequences counted"
    );
    let (system, _out, data) = bench();
    let mut player = Player::open(&bag).expect("open");
    player
        .route::<Sample>("/samples", &system, "sink.data")
        .expect("route");
    let played = player.play(Pace::AsFastAsPossible).expect("play");
    assert_eq!(played.sent["/samples"], 5);
    assert_eq!(data.drain().collect::<Vec<_>>(), sent);
    // Read as a stream (no summary), the bag has no header to say what it holds.
    let stream = std::fs::File::open(bag.join("foreign_0.mcap")).unwrap();
    let error = Reader::new(bag.clone(), Box::new(stream)).unwrap_err();
    assert!(matches!(error, ReadError::NoHeader { .. }), "{error}");
    drop(system);
}
