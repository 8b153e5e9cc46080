//! A packet travels by value, and a section that builds one and sends it holds many
//! copies of it on its thread's stack at once: a component's thread has the stack
//! for packets well beyond what coolc lets a description declare inline (32 KiB).

use coolbot::harness::Harness;
use coolbot::port::{DataOut, FifoIn};
use coolbot::{
    Automaton, Component, Context, InputKind, InputSpec, OutputKind, OutputSpec, OverflowPolicy,
    PortSet, Section, SectionResult, Spec, StateSpec, System,
};
use coolbot_runtime_tests::generated::largest_sender;
use coolbot_runtime_tests::generated::types::Largest;
use coolbot_runtime_tests::support::eventually;

/// 96 KiB inline. On a thread of Rust's default 2 MiB, a debug build's section that
/// builds one and sends it overflows the stack, which aborts the process.
#[derive(Clone)]
struct Big([u64; 12288]);

static SOURCE: Spec = Spec::new("BigSource", "sends one large packet as it enters its state")
    .with_states(&[StateSpec::new("send").with_entry()])
    .with_outputs(&[OutputSpec::new("out", OutputKind::Data, "Big")]);

/// Holds the input the test reads; no user automaton.
static SINK: Spec = Spec::new("BigSink", "an input the test reads").with_inputs(&[InputSpec::new(
    "input",
    InputKind::Fifo {
        capacity: 4,
        policy: OverflowPolicy::Reject,
    },
    "Big",
)]);

struct Sink;

impl Automaton for Sink {
    fn spec(&self) -> &'static Spec {
        &SINK
    }
}

struct Source(DataOut<Big>);

impl Automaton for Source {
    fn spec(&self) -> &'static Spec {
        &SOURCE
    }

    fn section(&mut self, _state: usize, _section: Section, _cx: &mut Context) -> SectionResult {
        let mut packet = Big([0; 12288]);
        for (index, word) in packet.0.iter_mut().enumerate() {
            *word = index as u64;
        }
        self.0.send(std::hint::black_box(packet));
        Ok(())
    }
}

#[test]
fn a_component_builds_and_sends_a_packet_of_96_kib_on_its_thread() {
    let received = FifoIn::<Big>::new(4, OverflowPolicy::Reject);
    let out = DataOut::<Big>::new();
    let mut system = System::new();
    system
        .add(Component::new(
            "sink",
            Box::new(Sink),
            PortSet::new().input(&received),
        ))
        .expect("add the sink");
    system
        .add(Component::new(
            "source",
            Box::new(Source(out.clone())),
            PortSet::new().output(&out),
        ))
        .expect("add the source");
    system.connect("source.out", "sink.input").expect("connect");
    system.run_all().expect("run");
    eventually(|| !received.is_empty(), "the packet arrives");
    let packet = received.recv().expect("the packet");
    assert!(packet.0.iter().enumerate().all(|(i, w)| *w == i as u64));
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}

/// Builds the packet the way a behaviour does: from its default, then field by field.
struct Fill;

impl largest_sender::Behavior for Fill {
    fn send_entry(&mut self, cx: &mut largest_sender::Cx<'_>) -> SectionResult {
        let mut packet = Largest::default();
        for (index, word) in packet.words.iter_mut().enumerate() {
            *word = index as u64;
        }
        cx.outputs.out.send(packet);
        Ok(())
    }
}

/// The bound coolc keeps a packet within is safe where the stack is smallest: a
/// harness runs its component on the test's own thread (2 MiB), and a debug build's
/// generated section holds many copies of the packet there.
#[test]
fn a_harness_builds_and_sends_a_packet_of_32_kib_on_the_test_thread() {
    let mut h = Harness::new(largest_sender::component("s", Fill)).expect("the harness");
    h.run().expect("run");
    h.settle().expect("settle");
    let sent: Vec<Largest> = h.take_sent("out").expect("the packets sent");
    assert_eq!(sent.len(), 1);
    assert!(
        sent[0]
            .words
            .iter()
            .enumerate()
            .all(|(i, w)| *w == i as u64)
    );
}
