//! The typed test harness of an atomic component (`templates/harness.rs`), derived
//! from its lowered [`ir::Atomic`]: one method per port with the port's packet type,
//! one typed setter per controllable variable. The harness wraps the runtime's
//! `coolbot::harness::Harness`, which drives the component's generated glue exactly
//! as a component thread would.

use crate::ir::{self, Code};

/// What the harness template prints for one atomic component.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Harness {
    /// One method (sometimes two) per input.
    pub(crate) inputs: Vec<Method>,
    /// One method (sometimes two) per output.
    pub(crate) outputs: Vec<Method>,
    /// One typed setter per controllable variable.
    pub(crate) setters: Vec<Method>,
}

/// One method of the typed harness: its doc line, signature and one-line body.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Method {
    /// Its doc line.
    pub(crate) doc: ir::Doc,
    /// `pub fn name(&mut self, ...) -> ...`, without the body.
    pub(crate) signature: String,
    /// The body's lines: statements, then the returned expression.
    pub(crate) body: Vec<ir::StubLine>,
}

/// The Rust type of a port's packets, `None` for a tick port.
fn packet_of(port: &ir::Port) -> Option<&str> {
    (port.kind_name != "tick").then_some(port.rust_packet.as_str())
}

/// A method name from a prefix and a field (without `r#`: `push_type` is no keyword).
fn method(prefix: &str, field: &str) -> String {
    format!("{prefix}_{}", field.trim_start_matches("r#"))
}

/// `self.inner.method(args)`: a call of the untyped harness, the method's value.
fn inner(method: &str, args: Vec<Code>) -> Vec<ir::StubLine> {
    let call = Code::atom("self").field("inner").method(method, args);
    vec![ir::StubLine::Value(call)]
}

/// The harness of `c`.
pub(crate) fn harness(c: &ir::Atomic) -> Harness {
    let mut inputs = Vec::new();
    for port in &c.inputs {
        let name = Code::string(&port.cool_name);
        let kind = port.kind_name;
        match packet_of(port) {
            None => {
                inputs.push(Method {
                    doc: vec![format!(
                        "An event arrives at tick input `{}`.",
                        port.cool_name
                    )],
                    signature: format!(
                        "pub fn {}(&mut self) -> HarnessResult<()>",
                        method("tick", &port.field)
                    ),
                    body: inner("tick", vec![name.clone()]),
                });
                if port.pull {
                    inputs.push(Method {
                        doc: vec![format!(
                            "Answers the next pull request on `{}` with an event.",
                            port.cool_name
                        )],
                        signature: format!(
                            "pub fn {}(&mut self) -> HarnessResult<()>",
                            method("answer", &port.field)
                        ),
                        body: inner("answer_tick", vec![name.clone()]),
                    });
                }
            }
            Some(packet) => {
                let (verb, what) = if kind == "poster" {
                    ("post", "is posted for")
                } else {
                    ("push", "arrives at")
                };
                inputs.push(Method {
                    doc: vec![format!(
                        "`packet` {what} {kind} input `{}`.",
                        port.cool_name
                    )],
                    signature: format!(
                        "pub fn {}(&mut self, packet: {packet}) -> HarnessResult<()>",
                        method(verb, &port.field)
                    ),
                    body: inner("push", vec![name.clone(), Code::atom("packet")]),
                });
                if port.pull {
                    inputs.push(Method {
                        doc: vec![format!(
                            "Answers the next pull request on `{}` with `packet`.",
                            port.cool_name
                        )],
                        signature: format!(
                            "pub fn {}(&mut self, packet: {packet}) -> HarnessResult<()>",
                            method("answer", &port.field)
                        ),
                        body: inner("answer", vec![name.clone(), Code::atom("packet")]),
                    });
                }
            }
        }
    }
    let mut outputs = Vec::new();
    for port in &c.outputs {
        let name = Code::string(&port.cool_name);
        match packet_of(port) {
            None => outputs.push(Method {
                doc: vec![format!(
                    "The events tick output `{}` emitted since the last call.",
                    port.cool_name
                )],
                signature: format!(
                    "pub fn {}(&mut self) -> HarnessResult<u64>",
                    method("ticks", &port.field)
                ),
                body: inner("take_ticks", vec![name.clone()]),
            }),
            Some(packet) => {
                outputs.push(Method {
                    doc: vec![format!(
                        "The packets output `{}` sent since the last call, in order.",
                        port.cool_name
                    )],
                    signature: format!(
                        "pub fn {}(&mut self) -> HarnessResult<::std::vec::Vec<{packet}>>",
                        method("sent", &port.field)
                    ),
                    body: inner("take_sent", vec![name.clone()]),
                });
                if port.kind_name == "poster" {
                    outputs.push(Method {
                        doc: vec![format!(
                            "The value poster output `{}` holds now.",
                            port.cool_name
                        )],
                        signature: format!(
                            "pub fn {}(&self) -> HarnessResult<::core::option::Option<{packet}>>",
                            method("posted", &port.field)
                        ),
                        body: inner("posted", vec![name.clone()]),
                    });
                }
            }
        }
        if port.pull {
            outputs.push(Method {
                doc: vec![format!(
                    "Asks pull output `{}` for an answer, as a consumer would.",
                    port.cool_name
                )],
                signature: format!(
                    "pub fn {}(&mut self) -> HarnessResult<()>",
                    method("pull", &port.field)
                ),
                body: inner("pull", vec![name.clone()]),
            });
        }
    }
    let setters = c
        .vars
        .iter()
        .filter(|var| var.controllable())
        .filter_map(|var| {
            let field = super::atomic::glue_vars().field(var.field.name.as_str());
            // The glue's conversion of the field, applied to the argument.
            var.to_value.contains(&field).then(|| Method {
                doc: vec![format!(
                    "Sets controllable variable `{}` through the control port.",
                    var.field.cool_name
                )],
                signature: format!(
                    "pub fn {}(&mut self, value: {}) -> HarnessResult<()>",
                    method("set", &var.field.name),
                    var.field.ty
                ),
                body: [ir::StubLine::Let(
                    "value".to_owned(),
                    var.to_value.replace(&field, &Code::atom("value")),
                )]
                .into_iter()
                .chain(inner(
                    "set",
                    vec![Code::string(&var.field.cool_name), Code::atom("value")],
                ))
                .collect(),
            })
        })
        .collect();
    Harness {
        inputs,
        outputs,
        setters,
    }
}

#[cfg(test)]
mod tests {

    #[test]
    fn a_setter_converts_its_argument_as_the_glue_converts_the_field() {
        let checked = crate::analyze_text(
            "t.cool",
            "atomic A { controllable speed: f64 = 1.0; controllable big: [u8; 40]; }",
        )
        .checked()
        .unwrap_or_else(|a| panic!("{}", a.render(crate::RenderOptions::plain())));
        let krate = crate::lower::lower(&checked, &crate::lower::Options::default());
        let bodies: Vec<Vec<String>> = super::harness(&krate.atomics[0])
            .setters
            .iter()
            .map(|m| m.body.iter().map(ToString::to_string).collect())
            .collect();
        assert_eq!(
            bodies,
            [
                vec![
                    "let value = ::coolbot::Value::from(value);".to_owned(),
                    r#"self.inner.set("speed", value)"#.to_owned(),
                ],
                vec![
                    "let value = super::__cool_to_value(&::coolbot::serde_with::ser::SerializeAsWrap::<[u8; 40], [::coolbot::serde_with::Same; 40]>::new(&value));".to_owned(),
                    r#"self.inner.set("big", value)"#.to_owned(),
                ],
            ]
        );
    }
    #[test]
    fn methods_follow_each_port_kind_and_packet() {
        let checked = crate::analyze_text(
            "t.cool",
            "atomic A { input t: tick; input q: fifo<[f32; 72]>(2); input s: poster<u8>; \
             output o: tick; output p: poster<f32>; }",
        )
        .checked()
        .unwrap_or_else(|a| panic!("{}", a.render(crate::RenderOptions::plain())));
        let krate = crate::lower::lower(&checked, &crate::lower::Options::default());
        let harness = super::harness(&krate.atomics[0]);
        let signatures: Vec<&str> = harness
            .inputs
            .iter()
            .chain(&harness.outputs)
            .map(|m| m.signature.as_str())
            .collect();
        assert_eq!(
            signatures,
            [
                "pub fn tick_t(&mut self) -> HarnessResult<()>",
                "pub fn push_q(&mut self, packet: [f32; 72]) -> HarnessResult<()>",
                "pub fn post_s(&mut self, packet: u8) -> HarnessResult<()>",
                "pub fn ticks_o(&mut self) -> HarnessResult<u64>",
                "pub fn sent_p(&mut self) -> HarnessResult<::std::vec::Vec<f32>>",
                "pub fn posted_p(&self) -> HarnessResult<::core::option::Option<f32>>",
            ]
        );
    }
}
