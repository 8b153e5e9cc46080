//! `adaptation { ... }` blocks: known keys, each once, counts (not durations) within
//! the runtime's limits, `off` alone, compound-only keys on compounds, and tuning
//! only where the timing adapts.

use super::Checker;
use super::model::{SelectorKind, TimingEntry};
use super::values::describe;
use crate::ast::{self, Span};
use crate::diagnostics::{Code, Diagnostic};

/// The keys an `adaptation` block knows, each with the largest value the runtime
/// takes (`coolbot::adapt::MAX_*`); `off` and `selector` take no count.
const COUNTS: &[(&str, u64)] = &[
    ("window", 1000),
    ("violations", 1000),
    ("hold", 100_000),
    ("settle", 100_000),
    ("homogeneity", 1000),
];

/// Every key, for "did you mean".
const KEYS: &[&str] = &[
    "off",
    "window",
    "violations",
    "hold",
    "settle",
    "homogeneity",
    "selector",
];

/// The runtime's default `window` (`coolbot::AdaptConfig::default`).
const DEFAULT_WINDOW: u64 = 4;

/// Where a block stands.
#[derive(Clone, Copy)]
pub(super) struct Target {
    /// The block tunes a compound's supervisor (else an atomic component).
    pub compound: bool,
    /// The timing that applies can adapt (a period interval, or no period with
    /// `max_response` and quality levels); always true for a compound.
    pub adapts: bool,
    /// The `window` the block's `violations` is compared with when the block does not
    /// write one (an instance's: its component's).
    pub window: Option<u64>,
}

/// Checks one block.
pub(super) fn block(checker: &mut Checker<'_, '_>, block: &ast::Adaptation, target: Target) {
    let mut seen: Vec<(&str, Span)> = Vec::new();
    for entry in &block.entries {
        let key = entry.key.name.as_str();
        if !KEYS.contains(&key) {
            checker.unknown(
                Code::UnknownAdaptationKey,
                &entry.key,
                "adaptation key",
                "",
                KEYS.iter().copied(),
            );
            continue;
        }
        if let Some((_, first)) = seen.iter().find(|(name, _)| *name == key) {
            let diagnostic = checker
                .error(
                    Code::RepeatedAdaptationKey,
                    entry.span,
                    format!("`{key}` is written twice in this `adaptation` block"),
                )
                .with_label("second one")
                .with_secondary(*first, "first one")
                .with_help("keep one");
            checker.push(diagnostic);
            continue;
        }
        seen.push((key, entry.span));
        if matches!(key, "homogeneity" | "selector") && !target.compound {
            let diagnostic = checker
                .error(
                    Code::MisplacedMember,
                    entry.span,
                    format!("`{key}` tunes a compound's supervisor, not an atomic component"),
                )
                .with_label("in the adaptation of an atomic component")
                .with_help("move it to the `adaptation` block of the compound");
            checker.push(diagnostic);
            continue;
        }
        if matches!(key, "violations" | "settle") && target.compound {
            let diagnostic = checker
                .error(
                    Code::MisplacedMember,
                    entry.span,
                    format!("`{key}` tunes an atomic component's detector, not a compound's supervisor"),
                )
                .with_label("in the adaptation of a compound")
                .with_help(
                    "a compound's supervisor settles for `hold + window + 1` periods; tune its instances' detectors in their own blocks",
                );
            checker.push(diagnostic);
            continue;
        }
        match key {
            "off" => {
                if let Some(value) = &entry.value {
                    let diagnostic = checker
                        .error(Code::TypeMismatch, value.span, "`off` takes no value")
                        .with_label("remove this")
                        .with_help("write `off;`");
                    checker.push(diagnostic);
                }
            }
            "selector" => selector(checker, entry),
            _ => count(checker, entry),
        }
    }
    if let Some((_, off)) = seen.iter().find(|(key, _)| *key == "off")
        && let Some((key, tuned)) = seen.iter().find(|(key, _)| *key != "off")
    {
        let diagnostic = checker
            .error(
                Code::AdaptationOffTuned,
                *tuned,
                format!("`{key}` tunes an adaptation this block turns `off`"),
            )
            .with_label("tuning")
            .with_secondary(*off, "adaptation turned off here")
            .with_help("remove `off`, or the tuning");
        checker.push(diagnostic);
    }
    violations_within_window(checker, block, target);
    if !target.adapts
        && let Some((key, span)) = seen.iter().find(|(key, _)| *key != "off")
    {
        let diagnostic = checker
            .error(
                Code::TuningWithoutAdaptation,
                *span,
                format!("`{key}` tunes an adaptation that never runs: the timing does not adapt"),
            )
            .with_label("tuning without adaptation")
            .with_help(
                "adaptation runs with a period interval (`period 10ms..40ms;`), or without a period with `max_response` and `quality` levels",
            );
        checker.push(diagnostic);
    }
}

/// The count a well-formed entry writes.
fn value(entry: &ast::AdaptEntry) -> Option<u64> {
    match entry.value.as_ref().map(|value| &value.kind) {
        Some(ast::ExprKind::Int(n)) => Some(*n),
        _ => None,
    }
}

fn violations_within_window(
    checker: &mut Checker<'_, '_>,
    block: &ast::Adaptation,
    target: Target,
) {
    let find = |key: &str| block.entries.iter().find(|entry| entry.key.name == key);
    let Some(violations) = find("violations") else {
        return;
    };
    let (Some(count), window) = (
        value(violations),
        find("window")
            .and_then(value)
            .or(target.window)
            .unwrap_or(DEFAULT_WINDOW),
    ) else {
        return;
    };
    if count > window {
        let diagnostic = checker
            .error(
                Code::AdaptationRange,
                violations.span,
                format!("{count} violations can never be counted in a window of {window} periods"),
            )
            .with_label("more than the window")
            .with_help(format!(
                "write at most `violations {window};`, or widen `window`"
            ));
        checker.push(diagnostic);
    }
}

fn count(checker: &mut Checker<'_, '_>, entry: &ast::AdaptEntry) {
    let key = entry.key.name.as_str();
    let unit = if key == "homogeneity" {
        "a number of levels"
    } else {
        "a count of periods"
    };
    let max = COUNTS
        .iter()
        .find(|(name, _)| *name == key)
        .map_or(u64::MAX, |(_, max)| *max);
    let Some(value) = &entry.value else {
        let diagnostic = checker
            .error(
                Code::TypeMismatch,
                entry.span,
                format!("`{key}` needs {unit}"),
            )
            .with_label("no value")
            .with_help(format!("e.g. `{key} 4;`"));
        checker.push(diagnostic);
        return;
    };
    let diagnostic: Option<Diagnostic> = match value.kind {
        ast::ExprKind::Int(0) => Some(
            checker
                .error(
                    Code::ZeroSize,
                    value.span,
                    format!("`{key}` must not be zero"),
                )
                .with_label("zero here"),
        ),
        ast::ExprKind::Int(n) if n > max => Some(
            checker
                .error(
                    Code::AdaptationRange,
                    value.span,
                    format!("`{key}` is at most {max}"),
                )
                .with_label("too large"),
        ),
        ast::ExprKind::Int(_) => None,
        ast::ExprKind::Duration(_) | ast::ExprKind::Frequency(_) => Some(
            checker
                .error(
                    Code::TypeMismatch,
                    value.span,
                    format!("`{key}` is {unit}, found {}", describe(value)),
                )
                .with_label("wrong unit")
                .with_help(format!("write a plain number: `{key} 4;`")),
        ),
        _ => Some(
            checker
                .error(
                    Code::TypeMismatch,
                    value.span,
                    format!("`{key}` needs {unit}, found {}", describe(value)),
                )
                .with_label("expected a positive integer"),
        ),
    };
    if let Some(diagnostic) = diagnostic {
        checker.push(diagnostic);
    }
}

fn selector(checker: &mut Checker<'_, '_>, entry: &ast::AdaptEntry) {
    let names = SelectorKind::ALL.iter().map(|(name, _)| *name);
    match entry.value.as_ref().map(|value| (&value.kind, value.span)) {
        Some((ast::ExprKind::Path(path), _)) if path.len() == 1 => {
            let name = &path[0];
            if !SelectorKind::ALL
                .iter()
                .any(|(known, _)| *known == name.name)
            {
                checker.unknown(Code::UnknownSelector, name, "selector", "", names);
            }
        }
        found => {
            let span = found.map_or(entry.span, |(_, span)| span);
            let what = entry.value.as_ref().map_or("nothing", describe);
            let diagnostic = checker
                .error(
                    Code::TypeMismatch,
                    span,
                    format!("`selector` needs a selector's name, found {what}"),
                )
                .with_label("expected `protect_priority` or `fastest_correction`");
            checker.push(diagnostic);
        }
    }
}

/// Whether a timing (a component's entries, then an instance's, which replace them)
/// adapts: a period interval, or no period with `max_response` and quality levels.
pub(super) fn adapts<'t>(entries: impl IntoIterator<Item = &'t TimingEntry>) -> bool {
    let (mut period, mut response, mut quality) = (None, false, false);
    for entry in entries {
        match entry {
            TimingEntry::Period(_, hi) => period = Some(hi.is_some()),
            TimingEntry::MaxResponse(_) => response = true,
            TimingEntry::Quality(levels) => quality = levels.len() > 1,
            TimingEntry::Priority(_) => {}
        }
    }
    match period {
        Some(interval) => interval,
        None => response && quality,
    }
}
