/// Converts a variable or configuration value to a runtime [`coolbot::Value`].
#[doc(hidden)]
pub fn __cool_to_value<T: ::serde::Serialize>(value: &T) -> ::coolbot::Value {
    ::coolbot::Value::from_serde(value)
}

/// Converts a runtime [`coolbot::Value`] to a variable or configuration value.
#[doc(hidden)]
pub fn __cool_from_value<T: ::serde::de::DeserializeOwned>(
    value: &::coolbot::Value,
) -> ::core::result::Result<T, ::std::string::String> {
    value.to_serde()
}
