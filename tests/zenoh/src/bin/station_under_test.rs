//! The station process of `tests/all/placement.rs`: node NAME, connected to the endpoint
//! given, runs an agent that builds, on request, the relay of every connection kind
//! (`EveryKindRelay`, `cool/placement.cool`), whose behaviour forwards each input to
//! the output of its kind, and the pull doubler (`PullDoubler`). It prints `ready`
//! once the agent answers, and runs until it is killed or its input closes.

use std::sync::Arc;
use std::time::Duration;

use coolbot::SectionResult;
use coolbot_zenoh::Node;
use coolbot_zenoh::agent::{Agent, Registry};
use coolbot_zenoh_tests::generated::{every_kind_relay, pull_doubler};

/// Forwards, on a thread of its own, each input of the relay to the output of its
/// kind: ticks to `to`; the `last`, `fifo` and `ufifo` packets to `out`, as
/// `value * 10 + 1`, `+ 2` and `+ 3` (so that the consumer tells them apart); the
/// poster to `po`.
struct Forward;

impl every_kind_relay::Behavior for Forward {
    fn start(&mut self, cx: &mut every_kind_relay::Cx<'_>) -> SectionResult {
        let (i, o) = (&cx.inputs, &cx.outputs);
        let (ti, li, fi, ui, pi) = (
            i.ti.clone(),
            i.li.clone(),
            i.fi.clone(),
            i.ui.clone(),
            i.pi.clone(),
        );
        let (to, out, po) = (o.to.clone(), o.out.clone(), o.po.clone());
        std::thread::spawn(move || {
            loop {
                for _ in 0..ti.take() {
                    to.emit();
                }
                if let Some(value) = li.take_new() {
                    out.send(value * 10 + 1);
                }
                for value in fi.drain() {
                    out.send(value * 10 + 2);
                }
                for value in ui.drain() {
                    out.send(value * 10 + 3);
                }
                if let Some(value) = pi.take_new() {
                    po.post(value);
                }
                std::thread::sleep(Duration::from_millis(1));
            }
        });
        Ok(())
    }
}

/// `PullDoubler`'s behaviour: a pull of `y` pulls `x` and answers twice the value.
struct Twice;

impl pull_doubler::Behavior for Twice {
    fn answer_y(&mut self, cx: &mut pull_doubler::Cx<'_>) -> Result<u64, coolbot::Fault> {
        let value = cx
            .inputs
            .x
            .pull(Duration::from_secs(5))
            .map_err(|error| coolbot::Fault::message(format!("no answer at `x`: {error}")))?;
        Ok(value * 2)
    }
}

fn main() {
    let mut args = std::env::args().skip(1);
    let (Some(name), Some(endpoint)) = (args.next(), args.next()) else {
        eprintln!("usage: station-under-test NAME ENDPOINT");
        std::process::exit(2);
    };
    let config = coolbot_zenoh::peer_config(&[], &[endpoint], false).expect("a configuration");
    let node = Arc::new(Node::open(&name, config).expect("the node opens"));
    let mut registry = Registry::new();
    every_kind_relay::register(&mut registry, |name| {
        every_kind_relay::component(name, Forward)
    });
    pull_doubler::register(&mut registry, |name| pull_doubler::component(name, Twice));
    let _agent = Agent::start(Arc::clone(&node), registry).expect("the agent starts");
    println!("ready");
    // Until the test closes stdin (or kills this process).
    let _ = std::io::Read::read_to_end(&mut std::io::stdin(), &mut Vec::new());
}
