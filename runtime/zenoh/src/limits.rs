//! The limits on what comes from the network (`docs/distribution.md`, "Limits"):
//! the lengths of names and keys, the size of a request or a command, the sizes of
//! the queues a request asks for, and the counts in a request. Each is checked before
//! anything is decoded, allocated or declared for it, and a refusal names the limit
//! and its value ([`Exceeded`]).
//!
//! The periods, `max_response` bounds and priorities a request or a command may give
//! are the control port's ranges, `coolbot::ranges`.

/// One limit: its name (as the refusals and `docs/distribution.md` print it), its
/// value and its unit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Limit {
    /// The limit's name.
    pub name: &'static str,
    /// The largest value allowed.
    pub max: usize,
    /// What the value counts (`bytes`, `packets`, ...).
    pub unit: &'static str,
}

impl Limit {
    /// `Ok` if `value` (of `what`, for the refusal) is within the limit.
    pub fn check(self, what: impl FnOnce() -> String, value: usize) -> Result<(), Exceeded> {
        if value <= self.max {
            Ok(())
        } else {
            Err(Exceeded {
                limit: self,
                what: what(),
                value,
            })
        }
    }
}

/// A value over a [`Limit`].
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "{what}: {value} {unit}, over the limit {name} = {max} {unit}",
    unit = .limit.unit,
    name = .limit.name,
    max = .limit.max
)]
pub struct Exceeded {
    /// The limit.
    pub limit: Limit,
    /// What was over it (`the instance name`, `the fifo capacity of wire 2`).
    pub what: String,
    /// Its value.
    pub value: usize,
}

/// The longest name an instantiation request gives (a type, an instance, a port, a
/// variable, the owner node), in bytes.
pub const NAME: Limit = Limit {
    name: "NAME",
    max: 128,
    unit: "bytes",
};

/// The longest node name or component path (`robot.base.motion`) a node declares
/// keys for, in bytes (`keys::check_name`).
pub const PATH: Limit = Limit {
    name: "PATH",
    max: 512,
    unit: "bytes",
};

/// The longest bridge key, in bytes (`keys::check_bridge_key`).
pub const KEY: Limit = Limit {
    name: "KEY",
    max: 512,
    unit: "bytes",
};

/// The largest instantiation request (its JSON) an agent decodes, in bytes.
pub const REQUEST: Limit = Limit {
    name: "REQUEST",
    max: 1 << 20,
    unit: "bytes",
};

/// The largest command (its JSON) a control key decodes, in bytes.
pub const COMMAND: Limit = Limit {
    name: "COMMAND",
    max: 1 << 20,
    unit: "bytes",
};

/// The largest answer (its JSON) a node decodes from another node's agent, or a proxy
/// from its remote instance's control port, in bytes.
pub const REPLY: Limit = Limit {
    name: "REPLY",
    max: 64 << 10,
    unit: "bytes",
};

/// The largest monitoring event (its JSON) a proxy decodes from its remote instance,
/// in bytes: a longer one is counted lost at the proxy's `@network`, undecoded.
pub const EVENT: Limit = Limit {
    name: "EVENT",
    max: 4 << 20,
    unit: "bytes",
};

/// The largest snapshot of a monitoring port (its JSON) a proxy decodes from its
/// remote instance's node, in bytes: a longer one is refused, undecoded.
pub const SNAPSHOT: Limit = Limit {
    name: "SNAPSHOT",
    max: 16 << 20,
    unit: "bytes",
};

/// The largest shape of a component (its JSON, with the JSON Schemas of its echoed
/// outputs) `coolctl` decodes from a node, in bytes: a longer one is refused,
/// undecoded.
pub const INFO: Limit = Limit {
    name: "INFO",
    max: 4 << 20,
    unit: "bytes",
};

/// The largest batch of echoed packets (its JSON) `coolctl echo` and `coolctl
/// foxglove` decode from a node, in bytes: a longer one is refused (`echo`) or
/// dropped and counted (`foxglove`), undecoded.
pub const ECHO_BATCH: Limit = Limit {
    name: "ECHO_BATCH",
    max: 64 << 20,
    unit: "bytes",
};

/// The most wires (bridged ports) in one instantiation request.
pub const WIRES: Limit = Limit {
    name: "WIRES",
    max: 128,
    unit: "wires",
};

/// The most controllable variables one instantiation request sets.
pub const VARIABLES: Limit = Limit {
    name: "VARIABLES",
    max: 128,
    unit: "variables",
};

/// The largest queue a request asks an outlet for: a fifo's capacity, a ufifo's
/// initial size and its cap, in packets.
pub const QUEUE: Limit = Limit {
    name: "QUEUE",
    max: 65_536,
    unit: "packets",
};

/// The most memory a queue a request asks for holds from the start: a fifo's
/// capacity, or a ufifo's initial size, times the packet type's size in memory.
pub const QUEUE_BYTES: Limit = Limit {
    name: "QUEUE_BYTES",
    max: 64 << 20,
    unit: "bytes",
};

/// The most memory the queues one request asks for hold from the start, together
/// (each within [`QUEUE_BYTES`]): what one request may have an agent allocate.
pub const REQUEST_QUEUE_BYTES: Limit = Limit {
    name: "REQUEST_QUEUE_BYTES",
    max: 128 << 20,
    unit: "bytes",
};

/// The most memory the queues of every instance an agent runs (and of those it still
/// releases) hold from the start, together: what all requests may have one agent
/// allocate. A request that would take it over is refused.
pub const HOSTED_QUEUE_BYTES: Limit = Limit {
    name: "HOSTED_QUEUE_BYTES",
    max: 512 << 20,
    unit: "bytes",
};

/// The most instances an agent runs at once for other nodes (those not yet `dead`):
/// each is a component on a thread of its own, with its bridges' ends.
pub const INSTANCES: Limit = Limit {
    name: "INSTANCES",
    max: 1024,
    unit: "instances",
};

/// The most quality levels a request's timing gives.
pub const LEVELS: Limit = Limit {
    name: "LEVELS",
    max: 64,
    unit: "levels",
};

/// The longest quality level name, in bytes.
pub const LEVEL_NAME: Limit = Limit {
    name: "LEVEL_NAME",
    max: 64,
    unit: "bytes",
};

/// The most distinct lists of quality levels an agent keeps (each is kept for the
/// process's life: the runtime holds levels as `&'static str`).
pub const LEVEL_LISTS: Limit = Limit {
    name: "LEVEL_LISTS",
    max: 256,
    unit: "lists",
};

/// The longest ROS 2 node name, namespace or fully qualified topic name a participant
/// declares keys for, in bytes (`docs/ros2.md`).
pub const ROS_NAME: Limit = Limit {
    name: "ROS_NAME",
    max: 255,
    unit: "bytes",
};

/// The longest message a ROS 2 subscription decodes unless it says otherwise, in
/// bytes: a longer one is counted lost, undecoded (`docs/ros2.md`).
pub const ROS_PAYLOAD: Limit = Limit {
    name: "ROS_PAYLOAD",
    max: 64 << 20,
    unit: "bytes",
};

/// Every limit, in the order `docs/distribution.md` lists them.
pub const ALL: [Limit; 22] = [
    NAME,
    PATH,
    KEY,
    REQUEST,
    COMMAND,
    REPLY,
    EVENT,
    SNAPSHOT,
    INFO,
    ECHO_BATCH,
    WIRES,
    VARIABLES,
    QUEUE,
    QUEUE_BYTES,
    REQUEST_QUEUE_BYTES,
    HOSTED_QUEUE_BYTES,
    INSTANCES,
    LEVELS,
    LEVEL_NAME,
    LEVEL_LISTS,
    ROS_NAME,
    ROS_PAYLOAD,
];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_refusal_names_the_limit_and_its_value() {
        assert_eq!(
            QUEUE.check(|| "the fifo capacity".to_owned(), 65_536),
            Ok(())
        );
        let error = QUEUE
            .check(|| "the fifo capacity".to_owned(), 1 << 33)
            .unwrap_err();
        assert_eq!(
            error.to_string(),
            "the fifo capacity: 8589934592 packets, over the limit QUEUE = 65536 packets"
        );
    }
}
