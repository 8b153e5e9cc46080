//! The one semantic model: every component, type and converter resolved from the
//! syntax trees once, which the checks consult and `crate::Checked` hands to `lower`
//! and `diagram` when there is no error.
//!
//! `types` is its vocabulary (resolved types, port kinds with their settings,
//! ranges, tuning, typed rule expressions); `component` the resolved components,
//! types and converters; `build` the [`Model`] that resolves them, each component
//! once, when first asked for.

mod build;
mod component;
mod types;

pub(crate) use build::Model;
pub use component::*;
pub use types::*;
