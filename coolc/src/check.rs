//! Checks: every rule of the language, one small function per rule.
//!
//! All diagnostics are collected; no check stops the others.

use crate::ast;
use crate::diagnostics::Diagnostic;
use crate::resolve::Symbols;

/// Runs every check over every file.
pub fn check(files: &[ast::File], symbols: &Symbols, diagnostics: &mut Vec<Diagnostic>) {
    let _ = (files, symbols, diagnostics);
}
