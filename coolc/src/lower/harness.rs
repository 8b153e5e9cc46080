//! The typed test harness of an atomic component (`templates/harness.rs`), derived
//! from its lowered [`ir::Atomic`]: one method per port with the port's packet type,
//! one typed setter per controllable variable. The harness wraps the runtime's
//! `coolbot::harness::Harness`, which drives the component's generated glue exactly
//! as a component thread would.

use crate::ir;

/// What the harness template prints for one atomic component.
#[derive(Clone, Debug, PartialEq)]
pub struct Harness {
    /// One method (sometimes two) per input.
    pub inputs: Vec<Method>,
    /// One method (sometimes two) per output.
    pub outputs: Vec<Method>,
    /// One typed setter per controllable variable.
    pub setters: Vec<Method>,
}

/// One method of the typed harness: its doc line, signature and one-line body.
#[derive(Clone, Debug, PartialEq)]
pub struct Method {
    /// Its doc line.
    pub doc: ir::Doc,
    /// `pub fn name(&mut self, ...) -> ...`, without the body.
    pub signature: String,
    /// The body's lines: statements, then the returned expression.
    pub body: Vec<String>,
}

/// The port's kind as its handle type says (`::coolbot::port::FifoIn<T>` is a fifo).
fn handle_kind(handle: &str) -> &str {
    let before = &handle[..handle.find('<').unwrap_or(handle.len())];
    let name = before.rsplit("::").next().unwrap_or(before);
    match name {
        "TickIn" | "TickOut" => "tick",
        "FifoIn" => "fifo",
        "UfifoIn" => "ufifo",
        "LastIn" => "last",
        "PosterIn" | "PosterOut" => "poster",
        "DataOut" => "data",
        _ => "",
    }
}

/// The packet type inside a handle type (`FifoIn<T>` gives `T`), `None` for ticks.
fn packet_of(handle: &str) -> Option<&str> {
    let open = handle.find('<')?;
    let close = handle.rfind('>')?;
    (close > open).then(|| &handle[open + 1..close])
}

/// A method name from a prefix and a field (without `r#`: `push_type` is no keyword).
fn method(prefix: &str, field: &str) -> String {
    format!("{prefix}_{}", field.trim_start_matches("r#"))
}

fn string(text: &str) -> String {
    crate::ident::string_literal(text)
}

/// The harness of `c`.
pub fn harness(c: &ir::Atomic) -> Harness {
    let mut inputs = Vec::new();
    for port in &c.inputs {
        let name = string(&port.cool_name);
        let kind = handle_kind(&port.handle);
        match packet_of(&port.handle) {
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
                    body: vec![format!("self.inner.tick({name})")],
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
                        body: vec![format!("self.inner.answer_tick({name})")],
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
                    body: vec![format!("self.inner.push({name}, packet)")],
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
                        body: vec![format!("self.inner.answer({name}, packet)")],
                    });
                }
            }
        }
    }
    let mut outputs = Vec::new();
    for port in &c.outputs {
        let name = string(&port.cool_name);
        match packet_of(&port.handle) {
            None => outputs.push(Method {
                doc: vec![format!(
                    "The events tick output `{}` emitted since the last call.",
                    port.cool_name
                )],
                signature: format!(
                    "pub fn {}(&mut self) -> HarnessResult<u64>",
                    method("ticks", &port.field)
                ),
                body: vec![format!("self.inner.take_ticks({name})")],
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
                    body: vec![format!("self.inner.take_sent({name})")],
                });
                if handle_kind(&port.handle) == "poster" {
                    outputs.push(Method {
                        doc: vec![format!(
                            "The value poster output `{}` holds now.",
                            port.cool_name
                        )],
                        signature: format!(
                            "pub fn {}(&self) -> HarnessResult<::core::option::Option<{packet}>>",
                            method("posted", &port.field)
                        ),
                        body: vec![format!("self.inner.posted({name})")],
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
                body: vec![format!("self.inner.pull({name})")],
            });
        }
    }
    let setters = c
        .vars
        .iter()
        .filter(|var| var.controllable())
        .filter_map(|var| {
            let field = format!("self.vars.{}", var.field.name);
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
                body: vec![
                    format!("let value = {};", var.to_value.replace(&field, "value")),
                    format!("self.inner.set({}, value)", string(&var.field.cool_name)),
                ],
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
    use super::{handle_kind, packet_of};

    #[test]
    fn kinds_and_packets_come_from_the_handle_types() {
        let fifo = "::coolbot::port::FifoIn<::std::vec::Vec<super::types::Range>>";
        assert_eq!(handle_kind(fifo), "fifo");
        assert_eq!(
            packet_of(fifo),
            Some("::std::vec::Vec<super::types::Range>")
        );
        assert_eq!(handle_kind("::coolbot::port::TickIn"), "tick");
        assert_eq!(packet_of("::coolbot::port::TickIn"), None);
        assert_eq!(
            handle_kind("::coolbot::port::PosterOut<[f32; 72]>"),
            "poster"
        );
        assert_eq!(
            packet_of("::coolbot::port::PosterOut<[f32; 72]>"),
            Some("[f32; 72]")
        );
    }
}
