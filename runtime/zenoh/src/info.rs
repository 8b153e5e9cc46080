//! What a node answers on a component's info key (`coolbot/<node>/<path>/s`): the
//! component's static shape from its `Spec` (type, variables with their kinds and
//! types, ports, quality levels) and the outputs the node echoes
//! ([`crate::Node::echo`]). `coolctl get` reads it to show types beside values;
//! `coolctl echo` to tell a port that is not echoed from one that does not exist;
//! `coolctl foxglove` to advertise an echoed port with its packets' JSON Schema.

use std::collections::BTreeMap;

use coolbot::{Spec, VarKind};
use serde::{Deserialize, Serialize};

/// A component's static shape, as the network sees it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ComponentInfo {
    /// The component type (`MotionController`).
    pub type_name: String,
    /// Its user variables, in declaration order (a compound's mapped ones too).
    pub variables: Vec<VariableInfo>,
    /// Its input ports.
    pub inputs: Vec<PortInfo>,
    /// Its output ports.
    pub outputs: Vec<PortInfo>,
    /// Its quality levels by name (its timing block's `quality`), best first.
    pub qualities: Vec<String>,
    /// The outputs the node echoes on the network (`coolctl echo`).
    pub echoed: Vec<String>,
    /// The JSON Schema of each echoed output's packets, by port (the schema a
    /// recording writes for the port, [`coolbot::schema::of`]; `coolctl foxglove`
    /// advertises it). Empty from a node that sends none.
    #[serde(default)]
    pub schemas: BTreeMap<String, serde_json::Value>,
}

/// One variable.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct VariableInfo {
    /// Its name.
    pub name: String,
    /// `observable` or `controllable`.
    pub kind: String,
    /// Its type as the description writes it (`f64`, `Pose2D`).
    pub ty: String,
}

/// One port.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct PortInfo {
    /// Its name.
    pub name: String,
    /// Its connection kind (`fifo(16, drop_oldest)`, `data`, `poster`, ...).
    pub kind: String,
    /// Its packet type as the description writes it.
    pub packet: String,
}

impl ComponentInfo {
    /// The shape of `spec`, with the outputs echoed and their packets' schemas.
    pub fn of(spec: &Spec, echoed: BTreeMap<String, serde_json::Value>) -> ComponentInfo {
        ComponentInfo {
            type_name: spec.type_name.to_owned(),
            variables: spec
                .variables
                .iter()
                .map(|v| VariableInfo {
                    name: v.name.to_owned(),
                    kind: match v.kind {
                        VarKind::Observable => "observable",
                        VarKind::Controllable => "controllable",
                    }
                    .to_owned(),
                    ty: v.ty.to_owned(),
                })
                .collect(),
            inputs: spec
                .inputs
                .iter()
                .map(|p| PortInfo {
                    name: p.name.to_owned(),
                    kind: format!("{:?}", p.kind).to_lowercase(),
                    packet: p.packet.to_owned(),
                })
                .collect(),
            outputs: spec
                .outputs
                .iter()
                .map(|p| PortInfo {
                    name: p.name.to_owned(),
                    kind: format!("{:?}", p.kind).to_lowercase(),
                    packet: p.packet.to_owned(),
                })
                .collect(),
            qualities: spec
                .timing
                .qualities
                .iter()
                .map(|q| (*q).to_owned())
                .collect(),
            echoed: echoed.keys().cloned().collect(),
            schemas: echoed,
        }
    }
}
