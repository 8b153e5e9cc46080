//! The generator of random valid descriptions, shared by the property test
//! (`tests/all/valid_descriptions.rs`) and the larger run
//! (`examples/random_descriptions.rs`): each includes this file as a module.
//!
//! [`describe`] draws one description from a seed: packets with arrays of any
//! length, lists, optionals and nested packets, enums, converters, atomics with every
//! kind of member, compounds with converters and nesting, and an imported file
//! (`main.cool` imports `types.cool`).

use std::fmt::Write as _;

/// SplitMix64: a small, fixed pseudo-random sequence per seed.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }

    fn chance(&mut self, percent: u64) -> bool {
        self.next() % 100 < percent
    }

    fn pick<'a, T>(&mut self, items: &'a [T]) -> &'a T {
        &items[self.below(items.len())]
    }
}

/// A `.cool` type the generator can write.
#[derive(Clone, Debug)]
enum Ty {
    Prim(&'static str),
    Packet(usize),
    Enum(usize),
    Array(Box<Ty>, u64),
    List(Box<Ty>),
    Optional(Box<Ty>),
}

const PRIMS: &[&str] = &[
    "bool", "i8", "i32", "i64", "u8", "u16", "u32", "u64", "f32", "f64", "String", "Duration",
    "Time",
];
/// Array lengths around the 32 where serde and `Default` stop.
const LENGTHS: &[u64] = &[1, 3, 32, 33, 40, 72];
/// The most bytes a packet, a configuration block or a component's variables hold
/// inline (`docs/language.md`, "Types"); an array beyond it is a list here too, which
/// keeps every array within its own bound (2^16 elements) as well.
const MAX_INLINE_BYTES: u64 = 32 << 10;

impl Ty {
    /// About how many bytes a value of the type takes inline, as coolc counts them,
    /// `sizes` those of the packets.
    fn bytes(&self, sizes: &[u64]) -> u64 {
        match self {
            Ty::Packet(i) => sizes[*i],
            Ty::Array(inner, n) => n.saturating_mul(inner.bytes(sizes)),
            Ty::Optional(inner) => inner.bytes(sizes).saturating_add(8),
            Ty::Enum(_) => 8,
            Ty::List(_) => 24,
            Ty::Prim("bool" | "i8" | "u8") => 1,
            Ty::Prim("u16") => 2,
            Ty::Prim("i32" | "u32" | "f32") => 4,
            Ty::Prim("i64" | "u64" | "f64") => 8,
            Ty::Prim("Duration" | "Time") => 16,
            Ty::Prim(_) => 24,
        }
    }

    /// The type, or a list of it when it would take `bytes` beyond `max` (a list
    /// lives on the heap). A list still takes its three words, so the type stays
    /// inline only if the lists of every member after it (five at most) still fit.
    fn within(self, sizes: &[u64], bytes: &mut u64, max: u64) -> Ty {
        const LISTS_AFTER: u64 = 5 * 24;
        let own = self.bytes(sizes);
        if bytes.saturating_add(own).saturating_add(LISTS_AFTER) > max {
            *bytes += 24;
            Ty::List(Box::new(self))
        } else {
            *bytes += own;
            self
        }
    }

    fn text(&self) -> String {
        match self {
            Ty::Prim(p) => (*p).to_owned(),
            Ty::Packet(i) => format!("P{i}"),
            Ty::Enum(i) => format!("E{i}"),
            Ty::Array(inner, n) => format!("[{}; {n}]", inner.text()),
            Ty::List(inner) => format!("[{}]", inner.text()),
            Ty::Optional(inner) => format!("{}?", inner.text()),
        }
    }

    /// A default literal for the type, when it has one.
    fn literal(&self, rng: &mut Rng) -> Option<String> {
        Some(match self {
            Ty::Prim("bool") => rng.pick(&["true", "false"]).to_string(),
            Ty::Prim("i8" | "i32" | "i64") => rng.pick(&["-3", "0", "7"]).to_string(),
            Ty::Prim("u8" | "u16" | "u32" | "u64") => rng.pick(&["0", "9", "0x1F"]).to_string(),
            Ty::Prim("f32" | "f64") => rng.pick(&["0.5", "-1.25", "2"]).to_string(),
            Ty::Prim("String") => rng.pick(&["\"\"", "\"beam\"", "\"a\\tb\""]).to_string(),
            Ty::Prim("Duration") => rng.pick(&["15ms", "2s", "1us"]).to_string(),
            Ty::Prim(_) | Ty::Packet(_) => return None,
            Ty::Enum(i) => format!("E{i}::V0"),
            Ty::Array(inner, n) => {
                let item = inner.literal(rng)?;
                if *n <= 3 && rng.chance(50) {
                    format!("[{}]", vec![item; *n as usize].join(", "))
                } else {
                    format!("[{item}; {n}]")
                }
            }
            Ty::List(inner) => {
                let item = inner.literal(rng)?;
                if rng.chance(50) {
                    format!("[{item}, {item}]")
                } else {
                    "[]".to_owned()
                }
            }
            Ty::Optional(inner) => match inner.literal(rng) {
                Some(item) if rng.chance(50) => item,
                _ => "none".to_owned(),
            },
        })
    }
}

/// A random type over the packets of `sizes` (the bytes each takes) and enums
/// `0..enums` (`depth` bounds the nesting); an array that would take more than
/// `MAX_INLINE_BYTES` is a list.
fn ty(rng: &mut Rng, sizes: &[u64], enums: usize, depth: usize) -> Ty {
    let packets = sizes.len();
    let choice = rng.below(if depth == 0 { 3 } else { 7 });
    match choice {
        1 if packets > 0 => Ty::Packet(rng.below(packets)),
        2 if enums > 0 => Ty::Enum(rng.below(enums)),
        3 | 4 => {
            let inner = ty(rng, sizes, enums, depth - 1);
            let n = *rng.pick(LENGTHS);
            if n.saturating_mul(inner.bytes(sizes)) > MAX_INLINE_BYTES {
                Ty::List(Box::new(inner))
            } else {
                Ty::Array(Box::new(inner), n)
            }
        }
        5 => Ty::List(Box::new(ty(rng, sizes, enums, depth - 1))),
        6 => {
            let inner = ty(rng, sizes, enums, depth - 1);
            if matches!(inner, Ty::Optional(_)) {
                inner
            } else {
                Ty::Optional(Box::new(inner))
            }
        }
        _ => Ty::Prim(PRIMS[rng.below(PRIMS.len())]),
    }
}

/// One atomic's interface, as the compounds see it.
struct Atomic {
    /// `(name, packet)` of its `data` outputs.
    data_outputs: Vec<(String, usize)>,
    /// `(name, packet, is a fifo)` of its packet inputs.
    inputs: Vec<(String, usize, bool)>,
    /// Its observable variables.
    observables: Vec<String>,
}

/// The description drawn from `seed`: `(file name, text)`, `main.cool` first; it
/// imports `types.cool`.
pub fn describe(seed: u64) -> Vec<(String, String)> {
    let mut rng = Rng(seed);
    let mut types = String::from("// Types, imported by main.cool.\n\n");
    let enums = 1 + rng.below(3);
    for e in 0..enums {
        let variants: Vec<String> = (0..1 + rng.below(4)).map(|v| format!("V{v}")).collect();
        writeln!(
            types,
            "/// Enum {e}.\nenum E{e} {{ {} }}\n",
            variants.join(", ")
        )
        .unwrap();
    }
    let packets = 2 + rng.below(4);
    // The bytes each packet takes inline.
    let mut sizes: Vec<u64> = Vec::new();
    for p in 0..packets {
        let mut fields = Vec::new();
        let mut bytes = 0;
        for f in 0..1 + rng.below(5) {
            let field_ty =
                ty(&mut rng, &sizes, enums, 2).within(&sizes, &mut bytes, MAX_INLINE_BYTES);
            let default = if rng.chance(50) {
                field_ty.literal(&mut rng)
            } else {
                None
            };
            let default = default.map(|d| format!(" = {d}")).unwrap_or_default();
            fields.push(format!(
                "    /// Field {f}.\n    f{f}: {}{default},",
                field_ty.text()
            ));
        }
        writeln!(
            types,
            "/// Packet {p}.\npacket P{p} {{\n{}\n}}\n",
            fields.join("\n")
        )
        .unwrap();
        // Rust pads a packet up to its alignment, at most a word (coolc counts it so).
        sizes.push(bytes.max(1).next_multiple_of(8));
    }
    let converters = 1 + rng.below(2);
    let mut converter_ends = Vec::new();
    for c in 0..converters {
        let from = rng.below(packets);
        // Usually between two different packets.
        let to = (from + 1 + rng.below(packets - 1)) % packets;
        converter_ends.push((from, to));
        writeln!(
            types,
            "/// Converter {c}.\nconverter K{c}: P{from} -> P{to};\n"
        )
        .unwrap();
    }

    let mut main = String::from("import \"types.cool\";\n\n");
    let mut atomics = Vec::new();
    for a in 0..2 + rng.below(3) {
        let mut members = Vec::new();
        let mut config = Vec::new();
        let mut bytes = 0;
        for c in 0..rng.below(3) {
            let field_ty =
                ty(&mut rng, &sizes, enums, 2).within(&sizes, &mut bytes, MAX_INLINE_BYTES);
            let default = field_ty
                .literal(&mut rng)
                .map(|d| format!(" = {d}"))
                .unwrap_or_default();
            config.push(format!("        c{c}: {}{default};", field_ty.text()));
        }
        if !config.is_empty() {
            members.push(format!(
                "    configuration {{\n{}\n    }}",
                config.join("\n")
            ));
        }
        let mut observables = Vec::new();
        let mut var_bytes = 0;
        for v in 0..rng.below(4) {
            let kind = *rng.pick(&["observable", "controllable", "local"]);
            let var_ty =
                ty(&mut rng, &sizes, enums, 2).within(&sizes, &mut var_bytes, MAX_INLINE_BYTES);
            let default = if rng.chance(50) {
                var_ty.literal(&mut rng)
            } else {
                None
            };
            let default = default.map(|d| format!(" = {d}")).unwrap_or_default();
            members.push(format!("    {kind} v{v}: {}{default};", var_ty.text()));
            if kind == "observable" {
                observables.push(format!("v{v}"));
            }
        }
        let mut inputs = Vec::new();
        let mut input_names = Vec::new();
        for i in 0..1 + rng.below(3) {
            let packet = rng.below(packets);
            let (text, fifo) = match rng.below(5) {
                0 => (format!("fifo<P{packet}>({})", 1 + rng.below(8)), true),
                1 => (format!("ufifo<P{packet}>(2, max 8)"), true),
                2 => (format!("last<P{packet}>"), false),
                3 => (format!("poster<P{packet}>"), false),
                _ => ("tick".to_owned(), false),
            };
            members.push(format!("    /// Input {i}.\n    input i{i}: {text};"));
            input_names.push(format!("i{i}"));
            if !text.starts_with("tick") && !text.starts_with("poster") {
                inputs.push((format!("i{i}"), packet, fifo));
            }
        }
        let mut data_outputs = Vec::new();
        for o in 0..1 + rng.below(3) {
            let packet = rng.below(packets);
            let text = match rng.below(4) {
                0 | 1 => {
                    data_outputs.push((format!("o{o}"), packet));
                    format!("data<P{packet}>")
                }
                2 => format!("poster<P{packet}>"),
                _ => "tick".to_owned(),
            };
            members.push(format!("    output o{o}: {text};"));
        }
        members.push("    timing { period 10ms; max_response 50ms; }".to_owned());
        // Every third atomic has no automaton (the language allows none): decided by
        // its index, not drawn, so that the other draws stay as they were.
        let automaton = a % 3 != 2;
        let plan = if automaton {
            "retry 2 every 5ms; goto s1;"
        } else {
            "retry 2 every 5ms;"
        };
        members.push(format!(
            "    /// A fault.\n    exception x0 \"the sensor failed\" {{ {plan} }}"
        ));
        let on = rng.pick(&input_names).clone();
        if automaton {
            members.push(format!(
                "    automaton {{\n        initial s0;\n        state s0 {{ entry; periodic; on {on} -> s1; may -> s1; }}\n        state s1 {{ exit; after 100ms -> s0; }}\n    }}"
            ));
        }
        writeln!(
            main,
            "/// Atomic {a}.\natomic A{a} {{\n{}\n}}\n",
            members.join("\n")
        )
        .unwrap();
        atomics.push(Atomic {
            data_outputs,
            inputs,
            observables,
        });
    }

    let compounds = 1 + rng.below(3);
    for c in 0..compounds {
        let mut members = Vec::new();
        // `(instance, atomic)`.
        let mut instances = Vec::new();
        for i in 0..2 + rng.below(3) {
            let atomic = rng.below(atomics.len());
            members.push(format!("    instance x{i}: A{atomic};"));
            instances.push((format!("x{i}"), atomic));
        }
        // Nesting: an earlier compound (which may use converters itself).
        if c > 0 && rng.chance(70) {
            members.push(format!("    instance n0: C{};", rng.below(c)));
        }
        let mut fed = Vec::new();
        let mut feeding = Vec::new();
        for (from, a) in &instances {
            for (output, packet) in &atomics[*a].data_outputs {
                for (to, b) in &instances {
                    for (input, input_packet, fifo) in &atomics[*b].inputs {
                        let key = format!("{to}.{input}");
                        let source = format!("{from}.{output}");
                        if fed.contains(&key) || (*fifo && feeding.contains(&source)) {
                            continue;
                        }
                        let via = converter_ends
                            .iter()
                            .position(|(f, t)| f == packet && t == input_packet);
                        let line = if packet == input_packet && !rng.chance(30) {
                            format!("    connect {source} -> {key};")
                        } else if let Some(k) = via {
                            format!("    connect {source} -> {key} via K{k};")
                        } else {
                            continue;
                        };
                        members.push(line);
                        fed.push(key);
                        if *fifo {
                            feeding.push(source.clone());
                        }
                    }
                }
            }
        }
        for (instance, a) in &instances {
            if let Some(variable) = atomics[*a].observables.first() {
                members.push(format!(
                    "    observable {instance}_{variable} = {instance}.{variable};"
                ));
            }
        }
        members.push("    observable faults: u32 = 0;".to_owned());
        members.push("    on error x0: restart;".to_owned());
        members.push("    timing { period 20ms; }".to_owned());
        members.push(
            "    supervisor {\n        initial w;\n        state w { entry; when x0.state == running_error || faults > 3 -> w2; }\n        state w2 { periodic; when x0.state == running -> w; }\n    }"
                .to_owned(),
        );
        writeln!(
            main,
            "/// Compound {c}.\ncompound C{c} {{\n{}\n}}\n",
            members.join("\n")
        )
        .unwrap();
    }
    vec![
        ("main.cool".to_owned(), main),
        ("types.cool".to_owned(), types),
    ]
}
