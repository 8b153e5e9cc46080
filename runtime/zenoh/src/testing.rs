//! What the crate's unit tests share: a component that does nothing, free ports and
//! nodes on loopback.

use std::sync::Arc;

use coolbot::{Component, PortSet};

use crate::Node;
use crate::agent::Registry;

/// A component that does nothing: one state, the ports of its spec.
pub(crate) struct Idle(pub(crate) &'static coolbot::Spec);

impl coolbot::Automaton for Idle {
    fn spec(&self) -> &'static coolbot::Spec {
        self.0
    }

    fn section(
        &mut self,
        _state: usize,
        _section: coolbot::Section,
        _cx: &mut coolbot::Context,
    ) -> Result<(), coolbot::Fault> {
        Ok(())
    }
}

/// The spec of [`Idle`] with no ports, type `Idle`.
pub(crate) fn idle_spec() -> &'static coolbot::Spec {
    crate::bridge::leak_spec("Idle", "Does nothing.", Vec::new(), None, false)
}

/// An [`Idle`] named `name` with no ports.
pub(crate) fn idle(name: &str, spec: &'static coolbot::Spec) -> Component {
    Component::new(name, Box::new(Idle(spec)), PortSet::new())
}

/// A registry of one type, `Idle`, with no ports.
pub(crate) fn idle_registry(spec: &'static coolbot::Spec) -> Registry {
    let mut registry = Registry::new();
    registry.register("Idle", move |name| idle(name, spec));
    registry
}

/// A port free on loopback now, outside the range outgoing connections take theirs
/// from.
pub(crate) fn free_port() -> u16 {
    crate::free_loopback_port()
}

/// Node `name` on loopback, listening on `listen` and connecting to `connect` (TCP
/// ports), keeping no tallies.
pub(crate) fn node(name: &str, listen: Option<u16>, connect: Option<u16>) -> Arc<Node> {
    let endpoint = |port: Option<u16>| {
        port.map(|port| format!("tcp/127.0.0.1:{port}"))
            .into_iter()
            .collect::<Vec<_>>()
    };
    let config = crate::peer_config(&endpoint(listen), &endpoint(connect), false).unwrap();
    Arc::new(Node::open(name, config).unwrap().with_state_directory(None))
}

/// Send `state` to component `path` of node `on` over the network, from `node`, and
/// check that its control port accepted it.
pub(crate) fn set_state(node: &Node, on: &str, path: &str, state: coolbot::Controllable) {
    use zenoh::Wait;
    let replies = node
        .session()
        .get(crate::keys::control(on, path))
        .payload(serde_json::to_vec(&coolbot::Command::SetState(state)).unwrap())
        .timeout(std::time::Duration::from_secs(10))
        .wait()
        .unwrap();
    let reply = replies.recv().unwrap().into_result().unwrap();
    assert_eq!(
        serde_json::from_slice::<crate::ControlReply>(&reply.payload().to_bytes()).unwrap(),
        crate::ControlReply::Accepted,
        "`{state:?}` sent to `{path}` on `{on}`"
    );
}

/// Whether `done` holds before a generous deadline, asked every 10 ms.
pub(crate) fn eventually(mut done: impl FnMut() -> bool) -> bool {
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
    while std::time::Instant::now() < deadline {
        if done() {
            return true;
        }
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    done()
}

/// Ask the agent of node `on`, from `node`, for `request` until it is built (a name
/// or memory that an instance being released holds is free once it is), before a
/// generous deadline; panics with the last answer if it is not.
pub(crate) fn built(node: &Node, on: &str, request: &crate::agent::Instantiate) {
    let mut last = None;
    let done = eventually(|| {
        let asked =
            crate::agent::instantiate(node, on, request, std::time::Duration::from_secs(10));
        let done = asked.is_ok();
        last = asked.err();
        done
    });
    assert!(done, "`{}` not built on `{on}`: {last:?}", request.name);
}

/// Send `request` to the agent of node `on` as node `requester` (a forgery on
/// plaintext when it is not `node`), without waiting for the answer: the replies.
pub(crate) fn asking(
    node: &Node,
    on: &str,
    requester: &str,
    request: &crate::agent::Instantiate,
) -> zenoh::handlers::FifoChannelHandler<zenoh::query::Reply> {
    use zenoh::Wait;
    node.session()
        .get(crate::keys::agent(on, &request.type_name, requester))
        .payload(serde_json::to_vec(request).unwrap())
        .timeout(std::time::Duration::from_secs(60))
        .wait()
        .unwrap()
}
