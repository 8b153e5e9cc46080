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

/// A TCP port free on loopback now.
pub(crate) fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
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
