{#- Written in rustfmt's layout: see coolc/src/layout.rs (`l`). -#}
//! Tests of the crate's components, each alone in its generated harness
//! (`generated::<component>::Harness`): built with in-memory ports on a virtual
//! clock, driven on the test's thread exactly as its component thread would run it,
//! so a test is deterministic and waits for no real time. Each starts from the
//! component's filled-in stubs and its default configuration; feed its inputs, advance
//! the clock and assert on what it sends, its variables and its states
//! (`docs/generated-code.md`, "Testing a component alone: the generated harness").
//!
//! `coolc compile` wrote this file once, when it created the crate, and never changes
//! it: it is yours.

use std::time::Duration;
{%- for t in tests %}

#[test]
{{ l.test_fn(&t.name) }}
{{ l.body_let("behavior", &t.behavior) }}
{{ l.body_let("mut harness", &t.harness) }}
    harness.advance(Duration::from_secs(1)).unwrap();
{{ l.body_statement(&t.check) }}
}
{%- endfor %}
