//! `adaptation { ... }` tunings (from the checked model) to the Rust expressions that
//! hand them to the runtime: a `coolbot::AdaptConfig` for `Component::with_adaptation`
//! and `CompoundBuilder::adaptation`, and a selector for
//! `CompoundBuilder::adaptation_selector`.

use crate::checked::model::{SelectorKind, Tuning};
use crate::ir::Code;

/// The `coolbot::AdaptConfig` a tuning says, or `None` when it says nothing (the
/// runtime's default then applies).
pub(super) fn config(tuning: &Tuning) -> Option<Code> {
    (*tuning != Tuning::default()).then(|| config_always(tuning))
}

/// The `coolbot::AdaptConfig` a tuning says, even when it is the default (an
/// instance's block replaces its component's `off`).
pub(super) fn config_always(tuning: &Tuning) -> Code {
    Code::StructRest(
        "::coolbot::AdaptConfig".to_owned(),
        fields(tuning),
        Box::new(Code::call("::coolbot::AdaptConfig::default", Vec::new())),
    )
}

/// The fields of the `coolbot::AdaptConfig` a tuning says, or `None` when it says
/// nothing (for the atomic template, which lays the struct out itself).
pub(super) fn written_fields(tuning: &Tuning) -> Option<Vec<(String, Code)>> {
    (*tuning != Tuning::default()).then(|| fields(tuning))
}

/// `(field, value)` for every key the tuning writes.
fn fields(tuning: &Tuning) -> Vec<(String, Code)> {
    let mut fields = Vec::new();
    if tuning.off {
        fields.push(("enabled".to_owned(), Code::core_some(Code::atom("false"))));
    }
    let counts = [
        ("window", tuning.window),
        ("violations", tuning.violations),
        ("hold_periods", tuning.hold),
        ("spare_periods", tuning.settle),
        ("width", tuning.homogeneity),
    ];
    for (field, value) in counts {
        if let Some(value) = value {
            fields.push((field.to_owned(), Code::atom(value.to_string())));
        }
    }
    fields
}

/// The `coolbot::adapt::Selector` a tuning names, if it names one.
pub(super) fn selector(tuning: &Tuning) -> Option<Code> {
    tuning.selector.map(|selector| {
        Code::atom(match selector {
            SelectorKind::ProtectPriority => "::coolbot::adapt::ProtectPriority",
            SelectorKind::FastestCorrection => "::coolbot::adapt::FastestCorrection",
        })
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_written_keys_are_set_and_off_turns_adaptation_off() {
        assert_eq!(config(&Tuning::default()), None);
        let tuning = Tuning {
            window: Some(8),
            hold: Some(3),
            homogeneity: Some(2),
            ..Tuning::default()
        };
        assert_eq!(
            config(&tuning).map(|code| code.to_string()).as_deref(),
            Some(
                "::coolbot::AdaptConfig { window: 8, hold_periods: 3, width: 2, ..::coolbot::AdaptConfig::default() }"
            )
        );
        let off = Tuning {
            off: true,
            ..Tuning::default()
        };
        assert!(
            config_always(&off)
                .to_string()
                .contains("enabled: ::core::option::Option::Some(false)")
        );
        assert_eq!(selector(&tuning), None);
    }
}
