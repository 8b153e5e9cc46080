//! JSON Schemas of packet types, for recordings that other tools read
//! ([`crate::record`] writes one per recorded port into its MCAP file).
//!
//! A schema is derived from the type's `serde::Deserialize` alone, with no value of it:
//! the type is deserialized from a tracing deserializer (`serde-reflection`), which
//! records every struct, field, enum variant and primitive the type asks for, and the
//! trace is written out as the JSON Schema of the type's `serde_json` form (structs as
//! objects, externally tagged enums, `Option` as "or null", maps as objects, integers
//! and numbers, tuples as fixed arrays). Named types are written inline (a type that
//! contains itself is cut at the second occurrence with an empty schema), so readers
//! that do not resolve `$ref` see every field.
//!
//! What cannot be traced this way (a type whose `Deserialize` is hand-written to accept
//! anything, `#[serde(untagged)]` or internally tagged enums, `#[serde(flatten)]`) gets
//! the permissive schema `{}` and the reason in [`Schema::derived`]; a caller that
//! knows better gives the schema itself (`Recorder::tap_with_schema`). Recordings and
//! `coolctl foxglove` write every schema, traced or given, in the part of JSON Schema
//! the Foxglove viewers read ([`for_viewers`]). An enum's
//! variants are traced one pass each; one still untraced after [`MAX_PASSES`] passes
//! gets `{}` for its own schema, the rest of the type keeps its exact schema.

use std::collections::BTreeMap;

use serde::de::DeserializeOwned;
use serde_json::{Map, Value, json};
use serde_reflection::{
    ContainerFormat, Format, Named, Registry, Samples, Tracer, TracerConfig, VariantFormat,
};

/// How many tracing passes at most one type gets (each pass explores one more variant
/// of every enum not yet complete).
pub const MAX_PASSES: usize = 64;

/// The JSON Schema dialect the schemas are written in.
pub const DIALECT: &str = "https://json-schema.org/draft/2020-12/schema";

/// A JSON Schema and how it was obtained.
#[derive(Debug, Clone, PartialEq)]
pub struct Schema {
    /// The schema (a JSON object).
    pub schema: Value,
    /// `traced` (derived from the type), `given` (by the caller), or `unknown: <why>`
    /// (the permissive schema `{}`).
    pub derived: String,
}

impl Schema {
    /// A schema given by the caller.
    pub fn given(schema: Value) -> Schema {
        Schema {
            schema,
            derived: "given".to_owned(),
        }
    }

    /// Whether values of the schema are JSON objects (otherwise a recording wraps
    /// them as `{"value": ...}`, which plotting tools expect).
    pub fn is_object(&self) -> bool {
        self.schema.get("type").and_then(Value::as_str) == Some("object")
    }

    /// The schema of the JSON a recording or a Foxglove channel carries for a value
    /// of this schema (the value itself when it is an object, else wrapped, see
    /// [`Schema::wrapped`]), in the part of JSON Schema the viewers read
    /// ([`for_viewers`]).
    pub fn for_viewers(&self) -> Value {
        if self.is_object() {
            for_viewers(&self.schema)
        } else {
            for_viewers(&self.wrapped())
        }
    }

    /// The schema of `{"value": <a value of this schema>}`.
    pub fn wrapped(&self) -> Value {
        let mut inner = self.schema.clone();
        if let Some(object) = inner.as_object_mut() {
            object.remove("$schema");
        }
        json!({
            "$schema": DIALECT,
            "type": "object",
            "properties": { "value": inner },
            "required": ["value"],
        })
    }
}

/// The JSON Schema of `T`'s `serde_json` form, traced from its `Deserialize`.
pub fn of<T: DeserializeOwned>() -> Schema {
    match trace::<T>() {
        Ok((format, registry, incomplete)) => {
            let mut writer = SchemaWriter {
                registry: &registry,
                incomplete: &incomplete,
                open: Vec::new(),
            };
            let mut schema = writer.format(&format);
            if let Some(object) = schema.as_object_mut() {
                object.insert("$schema".to_owned(), Value::from(DIALECT));
                object
                    .entry("title")
                    .or_insert_with(|| Value::from(short_name(std::any::type_name::<T>())));
            }
            Schema {
                schema,
                derived: "traced".to_owned(),
            }
        }
        Err(why) => Schema {
            schema: json!({
                "$schema": DIALECT,
                "title": short_name(std::any::type_name::<T>()),
                "description": format!("no schema: {why}"),
            }),
            derived: format!("unknown: {why}"),
        },
    }
}

/// `schema` (an object's, as [`of`] writes it or [`Schema::wrapped`] wraps it) in the
/// part of JSON Schema that the Foxglove and Lichtblick viewers read (their
/// `parseJsonSchema`, which refuses a whole channel or recording channel for one
/// property outside it): an object whose properties each have one `type`, `boolean`,
/// `string`, `number`, `integer`, `object` (with `properties`) or `array` (of one of
/// the others but `array`), or are a `oneOf` of numeric `const`s.
///
/// What the viewers cannot read is written in that part where the values still fit:
/// a value that may be `null` (an `Option`, a float, which `serde_json` writes as
/// `null` when it is not finite) has its one type and `"nullable": true` (OpenAPI's
/// keyword, which Ajv reads and the viewers pass over) instead of a list of types or
/// an `anyOf`; an enum of unit variants is a string with its `enum`; a map is an
/// object with no properties. A property whose values no such schema describes (a
/// tuple, an array of arrays or of enums with data, an enum with data, a unit, a type
/// that could not be traced, a `$ref`) is left out of `properties`: its values stay in
/// every message, and a viewer shows them without a type.
pub fn for_viewers(schema: &Value) -> Value {
    let mut object = viewer_object(schema);
    for key in ["$schema", "description"] {
        if let Some(value) = schema.get(key) {
            object[key] = value.clone();
        }
    }
    object
}

/// An object schema with each property in the viewers' form (see [`for_viewers`]),
/// those without one left out.
fn viewer_object(schema: &Value) -> Value {
    let mut properties = Map::new();
    for (name, property) in schema
        .get("properties")
        .and_then(Value::as_object)
        .into_iter()
        .flatten()
    {
        if let Some(property) = viewer_property(property) {
            properties.insert(name.clone(), property);
        }
    }
    let required: Vec<&Value> = schema
        .get("required")
        .and_then(Value::as_array)
        .into_iter()
        .flatten()
        .filter(|name| {
            name.as_str()
                .is_some_and(|name| properties.contains_key(name))
        })
        .collect();
    let mut object = json!({ "type": "object", "properties": properties });
    if !required.is_empty() {
        object["required"] = json!(required);
    }
    if let Some(title) = schema.get("title") {
        object["title"] = title.clone();
    }
    object
}

/// A property's schema in the viewers' form (see [`for_viewers`]); None when no
/// schema they read describes its values.
fn viewer_property(schema: &Value) -> Option<Value> {
    let is_null = |case: &Value| case.get("type").and_then(Value::as_str) == Some("null");
    if let Some(cases) = schema.get("anyOf").and_then(Value::as_array) {
        let mut others = cases.iter().filter(|case| !is_null(case));
        let (Some(only), None) = (others.next(), others.next()) else {
            return None;
        };
        // A `oneOf` of numeric constants has no `type` to be `nullable` with.
        return (cases.len() == 2)
            .then(|| viewer_property(only))
            .flatten()
            .filter(|inner| inner.get("type").is_some())
            .map(nullable);
    }
    if let Some(cases) = schema.get("oneOf").and_then(Value::as_array) {
        let consts: Option<Vec<&Value>> = cases.iter().map(|case| case.get("const")).collect();
        let consts = consts.filter(|consts| !consts.is_empty())?;
        if consts.iter().all(|value| value.is_number()) {
            return Some(schema.clone());
        }
        if !consts.iter().all(|value| value.is_string()) {
            return None;
        }
        let mut names = json!({ "type": "string", "enum": consts });
        if let Some(title) = schema.get("title") {
            names["title"] = title.clone();
        }
        return Some(names);
    }
    let (ty, may_be_null) = match schema.get("type")? {
        Value::String(ty) => (ty.as_str(), false),
        Value::Array(types) => {
            let mut others = types.iter().filter(|ty| ty.as_str() != Some("null"));
            let (Some(Value::String(only)), None) = (others.next(), others.next()) else {
                return None;
            };
            (only.as_str(), types.len() == 2)
        }
        _ => return None,
    };
    let mut lowered = match ty {
        "boolean" | "string" | "number" | "integer" => {
            let mut scalar = schema.clone();
            scalar["type"] = Value::from(ty);
            // The viewers decode base64 only; other encoded strings stay strings.
            if scalar.get("contentEncoding").and_then(Value::as_str) != Some("base64")
                && let Some(object) = scalar.as_object_mut()
            {
                object.remove("contentEncoding");
            }
            scalar
        }
        "object" => viewer_object(schema),
        "array" if schema.get("prefixItems").is_none() => {
            let items = viewer_property(schema.get("items")?)?;
            let readable = ["boolean", "string", "number", "integer", "object"];
            if !items
                .get("type")
                .and_then(Value::as_str)
                .is_some_and(|ty| readable.contains(&ty))
            {
                return None;
            }
            let mut items = items;
            if let Some(object) = items.as_object_mut() {
                // Not even base64 in an array's items.
                object.remove("contentEncoding");
            }
            let mut array = schema.clone();
            array["type"] = Value::from("array");
            array["items"] = items;
            array
        }
        _ => return None,
    };
    if may_be_null {
        lowered = nullable(lowered);
    }
    Some(lowered)
}

/// `schema` that also accepts `null` (`nullable`, and `null` among an `enum`'s values,
/// as Ajv requires).
fn nullable(mut schema: Value) -> Value {
    schema["nullable"] = Value::Bool(true);
    if let Some(values) = schema.get_mut("enum").and_then(Value::as_array_mut)
        && !values.contains(&Value::Null)
    {
        values.push(Value::Null);
    }
    schema
}

/// The type's last path segment (`RangeScan` for `robot::types::RangeScan`), generics
/// kept.
fn short_name(type_name: &str) -> &str {
    let head = type_name.split('<').next().unwrap_or(type_name);
    let start = head.rfind("::").map_or(0, |at| at + 2);
    &type_name[start..]
}

/// Trace `T`: its top-level format, the named types it uses, and the enums whose
/// variants are not all traced.
///
/// Each pass explores one more variant of the enums it is told to watch; the enums
/// nested in `T` are learnt from the tracer's `MissingVariants` answer, and the
/// tracing starts over with them watched, until no enum is missing variants.
fn trace<T: DeserializeOwned>() -> Result<(Format, Registry, Vec<String>), String> {
    let mut watched: Vec<String> = Vec::new();
    loop {
        let (format, tracer) = passes::<T>(&watched)?;
        match tracer.registry() {
            Ok(registry) => return Ok((format, registry, Vec::new())),
            Err(serde_reflection::Error::MissingVariants(missing)) => {
                let new: Vec<String> = missing
                    .into_iter()
                    .filter(|name| !watched.contains(name))
                    .collect();
                if new.is_empty() {
                    // No progress: keep what was traced, with the incomplete enums
                    // left open.
                    let (format, tracer) = passes::<T>(&watched)?;
                    let mut registry = tracer.registry_unchecked();
                    registry.retain(|name, _| !watched.contains(name));
                    return Ok((format, registry, watched));
                }
                watched.extend(new);
            }
            Err(error) => return Err(error.to_string()),
        }
    }
}

/// Trace `T` until none of the `watched` enums is missing a variant (at most
/// [`MAX_PASSES`] passes).
fn passes<T: DeserializeOwned>(watched: &[String]) -> Result<(Format, Tracer), String> {
    let samples = Samples::new();
    let mut tracer = Tracer::new(TracerConfig::default().is_human_readable(true));
    let mut format = Format::Unit;
    for _ in 0..MAX_PASSES {
        format = tracer
            .trace_type_once::<T>(&samples)
            .map_err(|error| error.to_string())?
            .0;
        let mut more = false;
        for name in watched {
            more |= tracer.check_incomplete_enum(name).is_some();
        }
        if !more {
            break;
        }
    }
    Ok((format, tracer))
}

/// Writes traced formats as JSON Schema, inlining named types.
struct SchemaWriter<'a> {
    registry: &'a BTreeMap<String, ContainerFormat>,
    incomplete: &'a [String],
    /// The named types being written (a type met again inside itself is cut).
    open: Vec<String>,
}

impl SchemaWriter<'_> {
    fn format(&mut self, format: &Format) -> Value {
        match format {
            Format::Variable(_) => json!({}),
            Format::TypeName(name) => self.named(name),
            Format::Unit => json!({ "type": "null" }),
            Format::Bool => json!({ "type": "boolean" }),
            Format::I8 => integer(i64::from(i8::MIN), i8::MAX.into()),
            Format::I16 => integer(i64::from(i16::MIN), i16::MAX.into()),
            Format::I32 => integer(i64::from(i32::MIN), i32::MAX.into()),
            Format::U8 => integer(0, u8::MAX.into()),
            Format::U16 => integer(0, u16::MAX.into()),
            Format::U32 => integer(0, u32::MAX.into()),
            Format::I64 | Format::I128 => json!({ "type": "integer" }),
            Format::U64 | Format::U128 => json!({ "type": "integer", "minimum": 0 }),
            // serde_json writes a non-finite float as `null`.
            Format::F32 | Format::F64 => json!({ "type": ["number", "null"] }),
            Format::Char => json!({ "type": "string", "minLength": 1, "maxLength": 1 }),
            Format::Str => json!({ "type": "string" }),
            Format::Bytes => json!({
                "type": "array",
                "items": { "type": "integer", "minimum": 0, "maximum": 255 },
            }),
            Format::Option(inner) => {
                json!({ "anyOf": [self.format(inner), { "type": "null" }] })
            }
            Format::Seq(inner) => json!({ "type": "array", "items": self.format(inner) }),
            Format::Map { value, .. } => {
                // JSON object keys are strings, whatever the map's key type.
                json!({ "type": "object", "additionalProperties": self.format(value) })
            }
            Format::Tuple(items) => self.tuple(items),
            Format::TupleArray { content, size } => json!({
                "type": "array",
                "items": self.format(content),
                "minItems": size,
                "maxItems": size,
            }),
        }
    }

    fn tuple(&mut self, items: &[Format]) -> Value {
        let prefix: Vec<Value> = items.iter().map(|item| self.format(item)).collect();
        json!({
            "type": "array",
            "prefixItems": prefix,
            "items": false,
            "minItems": items.len(),
            "maxItems": items.len(),
        })
    }

    fn fields(&mut self, fields: &[Named<Format>]) -> Value {
        let mut properties = Map::new();
        for field in fields {
            properties.insert(field.name.clone(), self.format(&field.value));
        }
        let required: Vec<&str> = fields.iter().map(|field| field.name.as_str()).collect();
        json!({ "type": "object", "properties": properties, "required": required })
    }

    fn named(&mut self, name: &str) -> Value {
        if self.incomplete.iter().any(|n| n == name) {
            return json!({ "title": name, "description": "variants not all traced" });
        }
        let Some(container) = self.registry.get(name) else {
            return json!({ "title": name });
        };
        if self.open.iter().any(|open| open == name) {
            // Recursive: cut here.
            return json!({ "title": name });
        }
        self.open.push(name.to_owned());
        let mut schema = match container {
            ContainerFormat::UnitStruct => json!({ "type": "null" }),
            ContainerFormat::NewTypeStruct(inner) => self.format(inner),
            ContainerFormat::TupleStruct(items) => self.tuple(items),
            ContainerFormat::Struct(fields) => self.fields(fields),
            ContainerFormat::Enum(variants) => {
                let cases: Vec<Value> = variants
                    .values()
                    .map(|variant| self.variant(variant))
                    .collect();
                json!({ "oneOf": cases })
            }
        };
        self.open.pop();
        if let Some(object) = schema.as_object_mut() {
            object
                .entry("title")
                .or_insert_with(|| Value::from(name.to_owned()));
        }
        schema
    }

    /// A variant as `serde_json` writes it: a unit variant as its name, the others as
    /// `{ "Name": content }`.
    fn variant(&mut self, variant: &Named<VariantFormat>) -> Value {
        let content = match &variant.value {
            VariantFormat::Unit => return json!({ "const": variant.name }),
            VariantFormat::Variable(_) => json!({}),
            VariantFormat::NewType(inner) => self.format(inner),
            VariantFormat::Tuple(items) => self.tuple(items),
            VariantFormat::Struct(fields) => self.fields(fields),
        };
        let mut properties = Map::new();
        properties.insert(variant.name.clone(), content);
        json!({
            "type": "object",
            "properties": properties,
            "required": [variant.name],
            "additionalProperties": false,
        })
    }
}

fn integer(minimum: i64, maximum: i64) -> Value {
    json!({ "type": "integer", "minimum": minimum, "maximum": maximum })
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use serde::Deserialize;
    use serde_json::json;

    use super::of;

    #[derive(Deserialize)]
    #[allow(dead_code, reason = "only traced")]
    enum Mode {
        Idle,
        Moving { speed: f64 },
        Turning(i8),
    }

    #[derive(Deserialize)]
    #[allow(dead_code, reason = "only traced")]
    struct Pose {
        x: f32,
        label: Option<String>,
        mode: Mode,
        path: Vec<(u8, bool)>,
        tags: BTreeMap<String, u16>,
        corners: [u32; 2],
    }

    #[test]
    fn a_struct_with_a_nested_enum_is_traced_whole() {
        let schema = of::<Pose>();
        assert_eq!(schema.derived, "traced");
        assert!(schema.is_object());
        let p = &schema.schema["properties"];
        assert_eq!(schema.schema["title"], "Pose");
        assert_eq!(p["x"]["type"], json!(["number", "null"]));
        assert_eq!(p["label"]["anyOf"][1], json!({ "type": "null" }));
        assert_eq!(p["label"]["anyOf"][0], json!({ "type": "string" }));
        let modes = p["mode"]["oneOf"].as_array().expect("variants");
        assert_eq!(
            modes.len(),
            3,
            "every variant of the nested enum: {modes:?}"
        );
        assert_eq!(modes[0], json!({ "const": "Idle" }));
        assert_eq!(
            modes[1]["properties"]["Moving"]["properties"]["speed"]["type"],
            json!(["number", "null"])
        );
        assert_eq!(modes[2]["properties"]["Turning"]["minimum"], -128);
        assert_eq!(p["path"]["items"]["prefixItems"][1]["type"], "boolean");
        assert_eq!(p["tags"]["additionalProperties"]["maximum"], 65535);
        assert_eq!(p["corners"]["maxItems"], 2);
    }

    #[derive(Deserialize)]
    #[allow(dead_code, reason = "only traced")]
    enum Gear {
        Low,
        High,
    }

    #[derive(Deserialize)]
    #[allow(dead_code, reason = "only traced")]
    struct Reading {
        pose: Pose,
        gear: Gear,
        spare: Option<Gear>,
        range: Option<f64>,
        ranges: Vec<f32>,
        grid: [[f32; 2]; 2],
        unit: (),
    }

    /// Every property of `object` in the part of JSON Schema the Foxglove and
    /// Lichtblick viewers read (their `parseJsonSchema`'s rules).
    fn viewers_read(object: &serde_json::Value, at: &str) {
        assert_eq!(object["type"], "object", "{at}");
        for (name, property) in object["properties"].as_object().expect("properties") {
            let at = format!("{at}.{name}");
            if let Some(cases) = property["oneOf"].as_array() {
                assert!(cases.iter().all(|case| case["const"].is_number()), "{at}");
                continue;
            }
            match property["type"].as_str().expect(&at) {
                "string" => {
                    let encoding = property.get("contentEncoding");
                    assert!(encoding.is_none_or(|e| e == "base64"), "{at}");
                }
                "boolean" | "number" | "integer" => {}
                "object" => viewers_read(property, &at),
                "array" => match property["items"]["type"].as_str().expect(&at) {
                    "boolean" | "string" | "number" | "integer" => {
                        assert!(property["items"].get("contentEncoding").is_none(), "{at}");
                    }
                    "object" => viewers_read(&property["items"], &at),
                    other => panic!("{at}: an array of {other}"),
                },
                other => panic!("{at}: {other}"),
            }
        }
    }

    #[test]
    fn the_viewers_form_keeps_what_they_read_and_leaves_out_what_they_cannot() {
        let viewers = super::for_viewers(&of::<Reading>().schema);
        viewers_read(&viewers, "Reading");
        let p = &viewers["properties"];
        assert_eq!(viewers["title"], "Reading");
        assert_eq!(p["range"], json!({ "type": "number", "nullable": true }));
        assert_eq!(
            p["ranges"]["items"],
            json!({ "type": "number", "nullable": true })
        );
        assert_eq!(p["gear"]["enum"], json!(["Low", "High"]));
        assert_eq!(p["spare"]["enum"], json!(["Low", "High", null]));
        let pose = &p["pose"]["properties"];
        assert_eq!(pose["label"], json!({ "type": "string", "nullable": true }));
        assert_eq!(pose["tags"], json!({ "type": "object", "properties": {} }));
        // What is left out is not required either.
        assert_eq!(
            p["pose"]["required"],
            json!(["x", "label", "tags", "corners"])
        );
        assert_eq!(pose["corners"]["items"]["type"], "integer");
        // A tuple list, an enum with data, an array of arrays and a unit: left out.
        for (object, name) in [(pose, "path"), (pose, "mode"), (p, "grid"), (p, "unit")] {
            assert!(object.get(name).is_none(), "{name}: {object}");
        }
        // Given shapes `of` does not write: a list of types on an array, an optional
        // `oneOf` of numbers (no `type` to be nullable with), an empty `oneOf`.
        let given = super::for_viewers(&json!({ "type": "object", "properties": {
            "a": { "type": ["array", "null"], "items": { "type": "number" } },
            "b": { "anyOf": [{ "oneOf": [{ "const": 1, "title": "one" }] }, { "type": "null" }] },
            "c": { "oneOf": [] },
            "d": { "type": "string", "contentEncoding": "gzip" },
            "e": { "type": "array", "items": { "type": "string", "contentEncoding": "base64" } },
            "f": { "type": ["string", "null"], "enum": ["x", null] },
        } }));
        viewers_read(&given, "given");
        assert_eq!(
            given["properties"]["a"],
            json!({ "type": "array", "items": { "type": "number" }, "nullable": true })
        );
        assert!(given["properties"].get("b").is_none(), "{given}");
        assert!(given["properties"].get("c").is_none(), "{given}");
        assert_eq!(given["properties"]["d"], json!({ "type": "string" }));
        assert_eq!(
            given["properties"]["e"]["items"],
            json!({ "type": "string" })
        );
        assert_eq!(given["properties"]["f"]["enum"], json!(["x", null]));
        // A value that is not an object, wrapped: its `value` is read.
        let number = super::for_viewers(&of::<f64>().wrapped());
        viewers_read(&number, "f64");
        assert_eq!(number["properties"]["value"]["nullable"], true);
    }

    #[test]
    fn a_number_is_not_an_object_and_is_wrapped() {
        let schema = of::<f64>();
        assert!(!schema.is_object());
        assert_eq!(
            schema.wrapped()["properties"]["value"]["type"],
            json!(["number", "null"])
        );
    }

    #[test]
    fn a_type_that_cannot_be_traced_gets_the_permissive_schema_and_why() {
        #[derive(Deserialize)]
        #[serde(untagged)]
        #[allow(dead_code, reason = "only traced")]
        enum Loose {
            A(u8),
            B(String),
        }
        let schema = of::<Loose>();
        assert!(
            schema.derived.starts_with("unknown: "),
            "{}",
            schema.derived
        );
        assert!(schema.schema.get("type").is_none());
        assert!(
            schema.schema["description"]
                .as_str()
                .is_some_and(|d| d.starts_with("no schema: ")),
        );
    }

    #[test]
    fn a_type_that_contains_itself_is_cut_at_the_repetition() {
        #[derive(Deserialize)]
        #[allow(dead_code, reason = "only traced")]
        struct Tree {
            value: u8,
            children: Vec<Tree>,
        }
        let schema = of::<Tree>();
        assert_eq!(schema.derived, "traced");
        assert_eq!(
            schema.schema["properties"]["children"]["items"],
            json!({ "title": "Tree" })
        );
    }
}
