/// Converts a variable or configuration value to a runtime [`coolbot::Value`].
#[doc(hidden)]
pub fn __cool_to_value<T: ::serde::Serialize>(value: &T) -> ::coolbot::Value {
    ::coolbot::Value::from_serde(value).unwrap_or_else(::coolbot::Value::Str)
}

/// Converts a runtime [`coolbot::Value`] to a variable or configuration value.
#[doc(hidden)]
pub fn __cool_from_value<T: ::serde::de::DeserializeOwned>(
    value: &::coolbot::Value,
) -> ::core::result::Result<T, ::std::string::String> {
    value.to_serde()
}

/// The error of setting `variable` of a component that is not controllable.
#[doc(hidden)]
pub fn __cool_not_controllable(spec: &::coolbot::Spec, variable: usize) -> ::std::string::String {
    ::std::format!(
        "variable {variable} of {} is not controllable",
        spec.type_name
    )
}

/// The configuration after applying `value`: the fields it names replace the current
/// ones, the others keep their values.
#[doc(hidden)]
pub fn __cool_configure<T: ::serde::Serialize + ::serde::de::DeserializeOwned>(
    current: &T,
    value: &::coolbot::Value,
) -> ::core::result::Result<T, ::std::string::String> {
    let given = value.to_json();
    let mut merged = match ::coolbot::Value::from_serde(current)? {
        ::coolbot::Value::Json(json) => json,
        other => other.to_json(),
    };
    let merged_fields = match (merged.as_object_mut(), given.as_object()) {
        (Some(fields), Some(given)) => {
            fields.extend(given.clone());
            true
        }
        _ => false,
    };
    if merged_fields {
        ::coolbot::Value::Json(merged).to_serde()
    } else {
        value.to_serde()
    }
}
