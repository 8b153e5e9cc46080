//! `adaptation { ... }` tunings (from the checked model) to the Rust expressions that
//! hand them to the runtime: a `coolbot::AdaptConfig` for `Component::with_adaptation`
//! and `CompoundBuilder::adaptation`, and a selector for
//! `CompoundBuilder::adaptation_selector`.

use crate::checked::model::{SelectorKind, Tuning};

/// The `coolbot::AdaptConfig` a tuning says, or `None` when it says nothing (the
/// runtime's default then applies).
pub(super) fn config(tuning: &Tuning) -> Option<String> {
    (*tuning != Tuning::default()).then(|| config_always(tuning))
}

/// The `coolbot::AdaptConfig` a tuning says, even when it is the default (an
/// instance's block replaces its component's `off`).
pub(super) fn config_always(tuning: &Tuning) -> String {
    let mut fields = fields(tuning);
    fields.push("..::coolbot::AdaptConfig::default()".to_owned());
    format!("::coolbot::AdaptConfig {{ {} }}", fields.join(", "))
}

/// The fields of the `coolbot::AdaptConfig` a tuning says, or `None` when it says
/// nothing (for the atomic template, which lays the struct out itself).
pub(super) fn written_fields(tuning: &Tuning) -> Option<Vec<String>> {
    (*tuning != Tuning::default()).then(|| fields(tuning))
}

/// `field: value` for every key the tuning writes.
fn fields(tuning: &Tuning) -> Vec<String> {
    let mut fields = Vec::new();
    if tuning.off {
        fields.push("enabled: ::core::option::Option::Some(false)".to_owned());
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
            fields.push(format!("{field}: {value}"));
        }
    }
    fields
}

/// The `coolbot::adapt::Selector` a tuning names, if it names one.
pub(super) fn selector(tuning: &Tuning) -> Option<&'static str> {
    tuning.selector.map(|selector| match selector {
        SelectorKind::ProtectPriority => "::coolbot::adapt::ProtectPriority",
        SelectorKind::FastestCorrection => "::coolbot::adapt::FastestCorrection",
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
            config(&tuning).as_deref(),
            Some(
                "::coolbot::AdaptConfig { window: 8, hold_periods: 3, width: 2, ..::coolbot::AdaptConfig::default() }"
            )
        );
        let off = Tuning {
            off: true,
            ..Tuning::default()
        };
        assert!(config_always(&off).contains("enabled: ::core::option::Option::Some(false)"));
        assert_eq!(selector(&tuning), None);
    }
}
