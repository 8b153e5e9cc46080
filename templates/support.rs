/// Converts a variable or configuration value to a runtime [`coolbot::Value`].
#[doc(hidden)]
pub fn __cool_to_value<T: ::serde::Serialize>(value: &T) -> ::coolbot::Value {
    ::coolbot::Value::from_serde(value)
        .unwrap_or_else(|error| ::coolbot::Value::Str(::coolbot::Chain(&error).to_string()))
}

/// Converts a variable of a primitive type to a runtime [`coolbot::Value`] (`From`).
#[doc(hidden)]
pub fn __cool_value_of<T: ::core::clone::Clone + ::core::convert::Into<::coolbot::Value>>(
    value: &T,
) -> ::coolbot::Value {
    value.clone().into()
}

/// Converts a variable through its serde_with adapter `A` (a type holding an array
/// longer than 32 elements) to a runtime [`coolbot::Value`].
#[doc(hidden)]
pub fn __cool_to_value_as<T, A: ::coolbot::serde_with::SerializeAs<T>>(
    value: &T,
) -> ::coolbot::Value {
    __cool_to_value(&::coolbot::serde_with::ser::SerializeAsWrap::<T, A>::new(
        value,
    ))
}

/// Converts a runtime [`coolbot::Value`] to a variable or configuration value.
#[doc(hidden)]
pub fn __cool_from_value<T: ::serde::de::DeserializeOwned>(
    value: &::coolbot::Value,
) -> ::core::result::Result<T, ::coolbot::ConvertError> {
    value.to_serde()
}

/// The configuration after applying `value`: the fields it names replace the current
/// ones, the others keep their values.
#[doc(hidden)]
pub fn __cool_configure<T: ::serde::Serialize + ::serde::de::DeserializeOwned>(
    current: &T,
    value: &::coolbot::Value,
) -> ::core::result::Result<T, ::coolbot::ConvertError> {
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
