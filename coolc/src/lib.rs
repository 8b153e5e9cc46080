//! `coolc`: the compiler for CoolBOT `.cool` component descriptions.
//!
//! The pipeline is `syntax` -> `resolve` -> `check` -> `lower` -> `emit`; see
//! `ARCHITECTURE.md` at the repository root.
#![deny(missing_docs)]

pub mod ast;
