//! A compound's exported ports behave as an atomic component's
//! (`support/exports.rs`), for the pulled tick ports, on hand-made components: the
//! language does not let a tick output be `pull` (`coolc::check::connect_kind`), so
//! no generated component has one (and none can feed a pulled tick input), though the
//! runtime answers a pull of a tick output with an event. Every other kind is in
//! `tests/runtime/tests/all/exports.rs`, on generated components.

mod support;

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use coolbot::port::{DataOut, FifoIn, LastIn, PosterIn, PosterOut, TickIn, TickOut, UfifoIn};
use coolbot::{Component, CompoundBuilder, Fault, InputKind, OutputKind, OverflowPolicy, System};
use support::exports::{
    In, Input, Out, Output, Port, PortHandle, Rig, Standby, Topology, connect_and_run, consumer_of,
    exported_behaves_as_atomic, follows_the_stand_in, producer_of, stand_by,
};
use support::shell::{Idle, ShellBuilder, input, output};

/// The hand-made components' ports, made and declared by the test.
impl Input {
    fn new(kind: In) -> Input {
        match kind {
            In::Fifo => Input::Fifo(FifoIn::new(8, OverflowPolicy::Reject)),
            In::Ufifo => Input::Ufifo(UfifoIn::new(2, None)),
            In::Last => Input::Last(LastIn::new()),
            In::Poster => Input::Poster(PosterIn::new()),
            In::Tick => Input::Tick(TickIn::new()),
        }
    }

    fn kind(&self) -> InputKind {
        match self {
            Input::Fifo(_) => InputKind::Fifo {
                capacity: 8,
                policy: OverflowPolicy::Reject,
            },
            Input::Ufifo(_) => InputKind::Ufifo {
                initial: 2,
                max: None,
            },
            Input::Last(_) => InputKind::Last,
            Input::Poster(_) => InputKind::Poster,
            Input::Tick(_) => InputKind::Tick,
        }
    }

    fn register(&self, shell: ShellBuilder, name: &'static str, pull: bool) -> ShellBuilder {
        let spec = input(name, self.kind(), pull);
        match self {
            Input::Fifo(port) => shell.input(spec, port),
            Input::Ufifo(port) => shell.input(spec, port),
            Input::Last(port) => shell.input(spec, port),
            Input::Poster(port) => shell.input(spec, port),
            Input::Tick(port) => shell.input(spec, port),
        }
    }
}

impl Output {
    fn new(kind: Out) -> Output {
        match kind {
            Out::Data => Output::Data(DataOut::new()),
            Out::Poster => Output::Poster(PosterOut::new()),
            Out::Tick => Output::Tick(TickOut::new()),
        }
    }

    fn kind(&self) -> OutputKind {
        match self {
            Output::Data(_) => OutputKind::Data,
            Output::Poster(_) => OutputKind::Poster,
            Output::Tick(_) => OutputKind::Tick,
        }
    }

    fn register(&self, shell: ShellBuilder, name: &'static str, pull: bool) -> ShellBuilder {
        let spec = output(name, self.kind(), pull);
        match self {
            Output::Data(port) => shell.output(spec, port),
            Output::Poster(port) => shell.output(spec, port),
            Output::Tick(port) => shell.output(spec, port),
        }
    }
}

/// What `w` and its stand-in look like: the port under test (`port`), a pull output
/// `trip` whose answer fails the component (to inject a fault), and the counter its
/// pull answers count with.
struct Member {
    component: Component,
    port: PortHandle,
}

/// Build a component named `name` with the port under test (pulled or not).
fn member(name: &str, port: Port, pull: bool, answers: Arc<AtomicU64>) -> Member {
    let trip = DataOut::<u64>::new();
    let handle = match port {
        Port::In(kind) => PortHandle::In(Input::new(kind)),
        Port::Out(kind) => PortHandle::Out(Output::new(kind)),
    };
    let shell = ShellBuilder::new(name);
    let shell = match &handle {
        PortHandle::In(input) => input.register(shell, "port", pull),
        PortHandle::Out(output) => output.register(shell, "port", pull),
    };
    let answer_with = handle.clone();
    // `trip` comes after the port under test if that is an output.
    let trip_index = match port {
        Port::In(_) => 0,
        Port::Out(_) => 1,
    };
    let shell = shell
        .output(output("trip", OutputKind::Data, true), &trip)
        .answer(move |index| {
            if index == trip_index {
                return Err(Fault::message("tripped"));
            }
            let n = answers.fetch_add(1, Ordering::SeqCst) + 1;
            match &answer_with {
                PortHandle::Out(output) => output.produce(n),
                PortHandle::In(_) => return Err(Fault::message("an input does not answer")),
            }
            Ok(())
        });
    Member {
        component: shell.build(),
        port: handle,
    }
}

fn rig(port: Port, pull: bool, topology: Topology, standby_by: Standby) -> Rig {
    let answers = Arc::new(AtomicU64::new(0));
    let w = member("w", port, pull, Arc::clone(&answers));
    let inner = w.port.clone();
    let outer_answers = Arc::new(AtomicU64::new(0));
    let outer = match port {
        Port::In(kind) => PortHandle::Out(Output::new(producer_of(kind))),
        Port::Out(kind) => PortHandle::In(Input::new(consumer_of(kind))),
    };
    let o = ShellBuilder::new("o");
    let o = match &outer {
        PortHandle::Out(output) => {
            let answer_with = output.clone();
            let counter = Arc::clone(&outer_answers);
            output.register(o, "end", pull).answer(move |_| {
                answer_with.produce(counter.fetch_add(1, Ordering::SeqCst) + 1);
                Ok(())
            })
        }
        PortHandle::In(input) => input.register(o, "end", pull),
    };
    let trip = LastIn::<u64>::new();
    let o = o.input(input("trip", InputKind::Last, true), &trip);
    let mut system = System::new();
    system.add(o.build()).expect("add o");
    let mut standby = None;
    match topology {
        Topology::Atomic => system.add(w.component).expect("add w"),
        Topology::Exported => {
            let mut builder = CompoundBuilder::new("k", Idle).instance(w.component);
            if standby_by != Standby::None {
                let s = member("s", port, pull, Arc::clone(&answers));
                standby = Some(s.port.clone());
                builder = stand_by(builder, standby_by, s.component);
            }
            builder = match port {
                Port::In(In::Tick) => builder.export_tick_input("x", "w.port"),
                Port::In(_) => builder.export_input::<u64>("x", "w.port"),
                Port::Out(Out::Tick) => builder.export_tick_output("x", "w.port"),
                Port::Out(_) => builder.export_output::<u64>("x", "w.port"),
            };
            let k = builder
                .export_output::<u64>("trip", "w.trip")
                .build()
                .expect("build k");
            system.add(k).expect("add k")
        }
    };
    connect_and_run(&mut system, port, topology);
    Rig {
        system,
        inner,
        standby,
        outer,
        outer_answers,
        answers,
        trip,
    }
}

/// The pulled tick ports (a pulled tick output, and a pulled tick input fed by one).
const CASES: &[(Port, bool)] = &[(Port::In(In::Tick), true), (Port::Out(Out::Tick), true)];

support::exports::exported_port_tests!(CASES, rig);
